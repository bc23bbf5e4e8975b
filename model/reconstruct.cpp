#include "model/reconstruct.h"

#include <fstream>
#include <sstream>

#include "model/autocast.h"
#include "model/checkpoint.h"
#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {

torch::Tensor imageTensor(const Image8& img, int size) {
  auto t = torch::from_blob(const_cast<uint8_t*>(img.data.data()), {img.height, img.width, 3},
                            torch::kUInt8)
               .permute({2, 0, 1})
               .unsqueeze(0)
               .to(torch::kFloat32) /
           255.0;
  if (img.width != size || img.height != size)
    t = torch::nn::functional::interpolate(t, torch::nn::functional::InterpolateFuncOptions()
                                                  .size(std::vector<int64_t>{size, size})
                                                  .mode(torch::kBilinear)
                                                  .align_corners(false));
  return imagenetNormalize(t);
}

namespace {

Image8 toImage(const torch::Tensor& normed) {  // [1, 3, S, S] normalised -> 8-bit
  auto t = (imagenetDenormalize(normed).clamp(0, 1) * 255)
               .round()
               .to(torch::kUInt8)[0]
               .permute({1, 2, 0})
               .contiguous();
  Image8 img(static_cast<int>(t.size(1)), static_cast<int>(t.size(0)), 3);
  std::memcpy(img.data.data(), t.data_ptr(), img.data.size());
  return img;
}

torch::Tensor readMask(const std::string& path, int n) {
  std::ifstream in(path);
  if (!in) throw Error(path, "cannot read the mask file");
  std::vector<uint8_t> values;
  std::string tok;
  while (in >> tok) {
    if (tok != "0" && tok != "1")
      throw Error(path, "mask values must be 0 or 1, found '" + tok + "'");
    values.push_back(tok == "1");
  }
  if (static_cast<int>(values.size()) != n)
    throw Error(path, "mask has " + std::to_string(values.size()) + " values, the model has " +
                          std::to_string(n) + " patches");
  return torch::tensor(std::vector<int64_t>(values.begin(), values.end()))
      .to(torch::kBool)
      .view({1, n});
}

}  // namespace

CroCoNet modelFromCheckpoint(const std::string& path, const std::optional<CroCoConfig>& fallback,
                             std::string* task) {
  const Checkpoint ck = loadCheckpoint(path);
  if (task) *task = trainedTask(ck);
  CroCoConfig cfg;
  if (ck.hasArgs && ck.args.contains("enc_embed_dim") && !fallback) {
    cfg = configFromJson(ck.args, path);
  } else if (fallback) {
    cfg = *fallback;
    checkConfigAgainstState(cfg, ck.model, path);
  } else {
    throw Error(
        path, "checkpoint has no paircast hyper-parameters: give --preset or --enc-dim ... flags");
  }
  checkModelFitsState(cfg, ck.model, path);
  CroCoNet net(cfg);
  loadStateDictStrict(net, ck.model, path);
  net->eval();
  return net;
}

Reconstruction reconstructWith(CroCoNet& model, const torch::Tensor& img1,
                               const torch::Tensor& img2, const torch::Tensor& mask) {
  torch::NoGradGuard noGrad;
  const CroCoConfig& c = model->config();
  CroCoOutput out = model->forward(img1, img2, mask);
  out.prediction = out.prediction.to(torch::kFloat32);  // bf16 under autocast
  // Un-normalise the norm_pix prediction with the target patches' statistics, as the paper shows.
  auto target = out.target;
  auto mean = target.mean(-1, true), std = torch::sqrt(target.var(-1, true, true) + 1e-6);
  auto predPix = out.prediction * std + mean;
  auto m = mask.unsqueeze(-1);
  auto recon = unpatchify(torch::where(m, predPix, target), c.patch_size);
  const auto greyImage = imagenetNormalize(torch::full_like(img1, 0.5));
  auto grey = patchify(greyImage, c.patch_size);
  auto maskedInput = unpatchify(torch::where(m, grey, target), c.patch_size);
  Reconstruction r;
  r.prediction = out.prediction[0].contiguous();
  r.loss = maskedMse(out.prediction, out.mask, out.target).item<double>();
  const auto reference = img2.defined() ? img2 : greyImage;
  const Image8 tiles[4] = {toImage(reference), toImage(maskedInput), toImage(recon), toImage(img1)};
  const int S = c.img_size, gap = 4;
  r.grid = Image8(4 * S + 3 * gap, S, 3, 255);
  for (int k = 0; k < 4; ++k)
    for (int y = 0; y < S; ++y)
      std::memcpy(r.grid.pixel(k * (S + gap), y), tiles[k].pixel(0, y), 3 * S);
  return r;
}

Reconstruction reconstruct(const ReconstructOptions& o) {
  std::string task;
  CroCoNet model = modelFromCheckpoint(o.checkpoint, o.config, &task);
  const CroCoConfig& c = model->config();
  auto img1 = imageTensor(readImage8(o.image1), c.img_size);
  auto img2 = imageTensor(readImage8(o.image2), c.img_size);
  torch::Tensor mask;
  if (!o.maskFile.empty()) {
    mask = readMask(o.maskFile, c.numPatches());
  } else {
    torch::manual_seed(o.seed);
    mask = model->randomMask(1, torch::kCPU);
  }
  const AutocastGuard autocast(resolvePrecision(o.amp, at::kCPU, "reconstruct"));
  return reconstructWith(model, img1, taskReference(task, img2), mask);
}

void writeNpy(const std::string& path, const torch::Tensor& t) {
  auto f = t.to(torch::kFloat32).contiguous();
  std::ostringstream shape;
  shape << "(";
  for (int64_t i = 0; i < f.dim(); ++i)
    shape << f.size(i) << (f.dim() == 1 || i + 1 < f.dim() ? "," : "");
  shape << ")";
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': " + shape.str() + ", }";
  // Magic, version 1.0, header length; the header is padded with spaces to a multiple of 64.
  const size_t total = 10 + header.size() + 1;
  header += std::string((64 - total % 64) % 64, ' ') + "\n";
  std::string out = std::string("\x93NUMPY\x01\x00", 8);
  out += static_cast<char>(header.size() & 0xff);
  out += static_cast<char>(header.size() >> 8);
  out += header;
  out.append(static_cast<const char*>(f.data_ptr()), f.numel() * 4);
  writeFileAtomic(path, out);
}

}  // namespace paircast
