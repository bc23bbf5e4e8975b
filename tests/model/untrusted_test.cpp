// Checkpoints from untrusted sources: loadCheckpoint builds tensors and plain values only. A
// pickle naming code (os.system, posix.system, builtins.eval) is refused with the global and the
// opcode named; sizes, views, memo indices and nesting are bounded, so a small file cannot
// exhaust memory or the stack. (docs/reliability.md, "Untrusted files", lists the threats.)
#include <caffe2/serialize/inline_container.h>
#include <gtest/gtest.h>

#include <chrono>

#include "model/checkpoint.h"
#include "model/downstream.h"
#include "model/pickle_pieces.h"
#include "model/reconstruct.h"
#include "test_errors.h"
#include "test_paths.h"
#include "util/error.h"

namespace paircast {
namespace {

using testing::i64;
using testing::str;
using testing::tensor;

// A zip checkpoint as torch.save lays it out, with our own data.pkl and storage records.
std::string writeCheckpoint(const std::string& dir, const std::string& name, const std::string& pkl,
                            const std::map<std::string, std::string>& storages = {}) {
  const std::string path = dir + "/" + name + ".pth";
  caffe2::serialize::PyTorchStreamWriter writer(path);
  writer.writeRecord("data.pkl", pkl.data(), pkl.size());
  for (const auto& [key, bytes] : storages)
    writer.writeRecord("data/" + key, bytes.data(), bytes.size());
  writer.writeEndOfFile();
  return path;
}

// Pickle pieces (protocol 2 unless noted).
const std::string kProto = "\x80\x02";
// {key: value}
std::string dictOf(const std::string& key, const std::string& value) {
  return "}" + str(key) + value + "s";
}

std::string refusal(const std::string& path) {
  return testing::refusalOf(path, [&] { loadCheckpoint(path); });
}

TEST(UntrustedCheckpoint, PicklesThatNameCodeAreRefused) {
  const std::string dir = testing::scratchDir("code");
  // pickle.dumps of a __reduce__ returning (os.system, ("echo pwned",)).
  std::string why = refusal(writeCheckpoint(
      dir, "os_system", kProto + "cos\nsystem\nq\x01" + str("echo pwned") + "\x85q\x02Rq\x03."));
  EXPECT_NE(why.find("refusing global 'os.system' (GLOBAL opcode)"), std::string::npos) << why;
  // Protocol 4 spells it with STACK_GLOBAL; posix is os on Linux.
  why = refusal(writeCheckpoint(dir, "posix_system",
                                "\x80\x04\x8c\x05posix\x8c\x06system\x93\x8c\x02id\x85R."));
  EXPECT_NE(why.find("refusing global 'posix.system' (STACK_GLOBAL opcode)"), std::string::npos)
      << why;
  // Hidden inside an otherwise valid state_dict.
  why = refusal(writeCheckpoint(dir, "eval",
                                kProto + "}" + str("model") + "}(" + str("w") +
                                    tensor("0", 1, 0, {1}, {1}) + str("x") +
                                    "c__builtin__\neval\n(" + str("1") + "tRu" + "s.",
                                {{"0", std::string(4, '\0')}}));
  EXPECT_NE(why.find("'__builtin__.eval'"), std::string::npos) << why;
}

TEST(UntrustedCheckpoint, SizesAndViewsCannotAskForUnboundedMemory) {
  const std::string dir = testing::scratchDir("sizes");
  const auto start = std::chrono::steady_clock::now();
  const std::map<std::string, std::string> four = {{"0", std::string(16, '\0')}};  // 4 floats
  // 2^62 float elements are 2^64 bytes: a product that wraps to 0 must not match a 0-byte record.
  std::string why = refusal(writeCheckpoint(
      dir, "numel", kProto + dictOf("w", tensor("0", int64_t(1) << 62, 0, {1}, {1})) + ".",
      {{"0", ""}}));
  EXPECT_NE(why.find("storage '0' has 0 bytes, not 4611686018427387904 elements"),
            std::string::npos)
      << why;
  // A view reaching far outside its storage, through overflowing arithmetic.
  why = refusal(writeCheckpoint(
      dir, "reach",
      kProto + dictOf("w", tensor("0", 4, 0, {int64_t(1) << 62, 4}, {int64_t(1) << 62, 1})) + ".",
      four));
  EXPECT_NE(why.find("outside its storage"), std::string::npos) << why;
  why = refusal(writeCheckpoint(dir, "offset",
                                kProto + dictOf("w", tensor("0", 4, -2, {2}, {1})) + ".", four));
  EXPECT_NE(why.find("negative storage offset"), std::string::npos) << why;
  // Stride 0 repeats one element: 2^40 of them would be 4 TB once copied.
  why = refusal(writeCheckpoint(
      dir, "broadcast", kProto + dictOf("w", tensor("0", 4, 0, {int64_t(1) << 40}, {0})) + ".",
      four));
  EXPECT_NE(why.find("tensor view has 1099511627776 elements"), std::string::npos) << why;
  // Many views of one storage: together bounded by the file's size.
  std::string many = kProto + "}(";
  for (int i = 0; i < 200; ++i)
    many += str("w" + std::to_string(i)) + tensor("0", 4, 0, {int64_t(1) << 22}, {0});
  why = refusal(writeCheckpoint(dir, "many", many + "u.", four));
  EXPECT_NE(why.find("tensors take more than"), std::string::npos) << why;
  // A 4-byte memo index must not size an array of 4G entries.
  why = refusal(writeCheckpoint(dir, "memo", kProto + "]r\xff\xff\xff\xff."));
  EXPECT_NE(why.find("no state_dict"), std::string::npos) << why;
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(10));
}

TEST(UntrustedCheckpoint, CyclesAndDeepNestingAreRefusedWithoutOverflowingTheStack) {
  const std::string dir = testing::scratchDir("nest");
  // {'model': {...}, 'x': l} where l = []; l.append(l).
  const std::string model = str("model") + "}" + str("w") + tensor("0", 1, 0, {1}, {1}) + "s";
  const std::map<std::string, std::string> one = {{"0", std::string(4, '\0')}};
  std::string why = refusal(
      writeCheckpoint(dir, "cycle", kProto + "}(" + model + str("x") + "]q\x07h\x07" + "au.", one));
  EXPECT_NE(why.find("entry 'x' nests deeper than 100 levels (or holds a cycle)"),
            std::string::npos)
      << why;
  // 200000 nested lists: freeing them must not recurse 200000 deep either.
  const int depth = 200000;
  why = refusal(writeCheckpoint(dir, "deep",
                                kProto + "}(" + model + str("deep") + std::string(depth, '(') +
                                    std::string(depth, 'l') + "u.",
                                one));
  EXPECT_NE(why.find("entry 'deep' nests deeper"), std::string::npos) << why;
}

TEST(UntrustedCheckpoint, TheValuesItKnowsStillLoad) {
  const std::string dir = testing::scratchDir("ok");
  // What official CroCo files hold besides tensors: an argparse.Namespace and an OrderedDict.
  const std::string pkl = kProto + "}(" + str("model") + "ccollections\nOrderedDict\n)R" +
                          str("w") + tensor("0", 4, 1, {3}, {1}) + "s" + str("args") +
                          "cargparse\nNamespace\n)\x81}" + str("lr") +
                          "G?\x1a\x36\xe2\xeb\x1c\x43\x2d" + "sb" + str("epoch") + "K\x05u.";
  const float values[4] = {1, 2, 3, 4};
  const Checkpoint ck = loadCheckpoint(writeCheckpoint(
      dir, "ok", pkl, {{"0", std::string(reinterpret_cast<const char*>(values), 16)}}));
  ASSERT_EQ(ck.model.count("w"), 1u);
  EXPECT_TRUE(torch::equal(ck.model.at("w"), torch::tensor({2.0f, 3.0f, 4.0f})));
  EXPECT_EQ(ck.epoch, 5);
  ASSERT_TRUE(ck.hasArgs);
  EXPECT_DOUBLE_EQ(ck.args["lr"].get<double>(), 1e-4);
}

// A checkpoint's configuration sizes the model built before its weights are read: each value
// must be an integer in range, and the model must fit what the file holds.
TEST(UntrustedCheckpoint, ConfigurationsAreBoundedBeforeAModelIsBuilt) {
  using nlohmann::json;
  EXPECT_ERROR_CONTAINS(configFromJson(json{{"enc_embed_dim", 1e9}}, "f.pth"), "f.pth",
                        "'enc_embed_dim' is not an integer in range");
  EXPECT_ERROR_CONTAINS(configFromJson(json{{"enc_depth", 1e20}}, "f.pth"), "f.pth", "enc_depth");
  EXPECT_ERROR_CONTAINS(configFromJson(json{{"dec_depth", int64_t(1) << 40}}, "f.pth"), "f.pth",
                        "not an integer in range");
  EXPECT_ERROR_CONTAINS(
      configFromJson(json{{"enc_embed_dim", 1 << 20}, {"enc_num_heads", 1}}, "f.pth"),
      "embedding widths are at most 8192");
  EXPECT_ERROR_CONTAINS(configFromJson(json{{"img_size", 8192}, {"patch_size", 2}}, "f.pth"),
                        "at most 65536 patches");
  EXPECT_ERROR_CONTAINS(configFromJson(json{{"pos_embed", "RoPEnan"}}, "f.pth"), "RoPE frequency");
  // The base model's configuration over four values: refused before the 110M parameters are
  // made, by reconstruct's loader.
  const std::string dir = testing::scratchDir("fits");
  const std::string path = dir + "/small.pth";
  saveCheckpoint(path, {{"w", torch::zeros({4})}}, 1, json{{"args", configToJson(CroCoConfig())}});
  EXPECT_ERROR_CONTAINS(modelFromCheckpoint(path, std::nullopt), path,
                        "parameters, but it holds 4 values");
}

// A fine-tuning checkpoint's head and head_kwargs: wrong types and a billion channels are
// refused naming the file.
TEST(UntrustedCheckpoint, HeadKwargsAreBounded) {
  using nlohmann::json;
  Checkpoint ck;
  ck.extra = json{
      {"task", "flow"},
      {"croco_kwargs", configToJson(presetConfig("tiny"))},
      {"head", "dpt"},
      {"head_kwargs", {{"hooks_idx", {1, 2, 3, 4}}, {"layer_dims", {96, 192, 384, 1000000000}}}}};
  EXPECT_ERROR_CONTAINS(downstreamConfigOf(ck, "ft.pth"), "ft.pth",
                        "layer_dims are 1 to 4096, not 1000000000");
  ck.extra["head_kwargs"]["layer_dims"] = json{96, 192, 384, 1e12};
  EXPECT_ERROR_CONTAINS(downstreamConfigOf(ck, "ft.pth"), "ft.pth");
  ck.extra["head"] = 5;
  EXPECT_ERROR_CONTAINS(downstreamConfigOf(ck, "ft.pth"), "ft.pth", "bad head");
}

// The heads' parameters are counted from the configuration alone (checkModelFitsState takes
// them), so the count must be what the built head holds, for each head; and a DPT head of
// 4 x 4,096 layer_dims (2 GB) over a file of a few values is refused before it is built.
TEST(UntrustedCheckpoint, HeadParametersAreCountedBeforeTheHeadIsBuilt) {
  DownstreamConfig c;
  c.croco.img_size = 32;
  c.croco.patch_size = 16;
  c.croco.enc_embed_dim = 16, c.croco.enc_depth = 2, c.croco.enc_num_heads = 2;
  c.croco.dec_embed_dim = 8, c.croco.dec_depth = 2, c.croco.dec_num_heads = 2;
  c.layerDims = {8, 16, 24, 32};
  for (const auto& [task, head] :
       std::vector<std::pair<std::string, std::string>>{{"flow", "linear"},
                                                        {"depth", "linear"},
                                                        {"pose", "pose"},
                                                        {"flow", "dpt"},
                                                        {"depth", "dpt"}}) {
    c.task = task, c.head = head;
    SCOPED_TRACE(task + " " + head);
    DownstreamNet net(c);
    int64_t built = 0;
    for (const auto& [name, p] : net->uniqueParameters())
      if (name.rfind("head.", 0) == 0 || name.rfind("prediction_head.", 0) == 0) built += p.numel();
    EXPECT_EQ(c.headParameters(), built);
  }
  c.task = "flow", c.head = "dpt", c.layerDims = {4096, 4096, 4096, 4096};
  const std::map<std::string, torch::Tensor> state{{"patch_embed.proj.weight", torch::zeros({4})}};
  EXPECT_ERROR_CONTAINS(checkModelFitsState(c.croco, state, "ft.pth", c.headParameters()), "ft.pth",
                        "asks for", "but it holds 4 values");
}

}  // namespace
}  // namespace paircast
