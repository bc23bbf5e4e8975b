#include "model/checkpoint.h"

#include <caffe2/serialize/inline_container.h>
#include <caffe2/serialize/istream_adapter.h>
#include <torch/csrc/jit/serialization/export.h>
#include <torch/csrc/jit/serialization/pickler.h>
#include <torch/serialize.h>

#include <cstring>
#include <filesystem>
#include <memory>
#include <sstream>

#include "model/flops.h"
#include "model/pickle_reader.h"
#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {

std::string trainedTask(const Checkpoint& checkpoint) {
  const nlohmann::json& e = checkpoint.extra;
  return e.is_object() && e.value("task", nlohmann::json()).is_string()
             ? e["task"].get<std::string>()
             : "croco";
}

namespace {

// Deeper nesting than this is refused when the values become JSON or tensors: far above what a
// checkpoint needs (a state_dict nests 2 levels, optimizer state 5).
constexpr int kMaxDepth = 100;

// An exception's message as one line: c10::Error's what() appends a multi-line backtrace.
std::string oneLine(const std::exception& e) {
  const auto* c10e = dynamic_cast<const c10::Error*>(&e);
  std::string msg = c10e ? c10e->what_without_backtrace() : e.what();
  const size_t eol = msg.find('\n');
  return eol == std::string::npos ? msg : msg.substr(0, eol);
}

std::string keyString(const PyPtr& k) {
  if (k->kind == PyValue::String) return k->s;
  if (k->kind == PyValue::Int) return std::to_string(k->i);
  return "?";
}

// Deeper nesting is refused: it only comes from hostile files, and a cycle reaches any depth.
void checkDepth(int depth, const std::string& key, const std::string& source) {
  if (depth > kMaxDepth)
    throw Error(source, "checkpoint entry '" + key.substr(0, key.find('/')) +
                            "' nests deeper than " + std::to_string(kMaxDepth) +
                            " levels (or holds a cycle)");
}

nlohmann::json toJson(const PyPtr& v, const std::string& key, const std::string& source,
                      int depth = 0) {
  checkDepth(depth, key, source);
  switch (v->kind) {
    case PyValue::None:
      return nullptr;
    case PyValue::Bool:
      return static_cast<bool>(v->i);
    case PyValue::Int:
      return v->i;
    case PyValue::Float:
      return v->f;
    case PyValue::String:
      return v->s;
    case PyValue::List:
    case PyValue::Tuple: {
      auto a = nlohmann::json::array();
      for (const auto& x : v->items) a.push_back(toJson(x, key, source, depth + 1));
      return a;
    }
    case PyValue::Dict:
    case PyValue::Object: {
      auto o = nlohmann::json::object();
      for (const auto& [k, x] : v->dict) o[keyString(k)] = toJson(x, key, source, depth + 1);
      return o;
    }
    default:
      return nullptr;
  }
}

// Collects tensors below `v` as "prefix/key/..." (state dicts nested in dicts).
void collectTensors(const PyPtr& v, const std::string& prefix,
                    std::map<std::string, torch::Tensor>& out, const std::string& source,
                    int depth = 0) {
  checkDepth(depth, prefix, source);
  if (v->kind == PyValue::Tensor) {
    out[prefix] = v->tensor;
  } else if (v->kind == PyValue::Dict || v->kind == PyValue::Object) {
    for (const auto& [k, x] : v->dict)
      collectTensors(x, prefix.empty() ? keyString(k) : prefix + "/" + keyString(k), out, source,
                     depth + 1);
  } else if (v->kind == PyValue::List || v->kind == PyValue::Tuple) {
    for (size_t i = 0; i < v->items.size(); ++i)
      collectTensors(v->items[i], prefix + "/" + std::to_string(i), out, source, depth + 1);
  }
}

bool isStateDict(const PyPtr& v) {
  if (v->kind != PyValue::Dict || v->dict.empty()) return false;
  for (const auto& [k, x] : v->dict)
    if (k->kind != PyValue::String || x->kind != PyValue::Tensor) return false;
  return true;
}

class StringAdapter : public caffe2::serialize::ReadAdapterInterface {
 public:
  explicit StringAdapter(std::string data) : data_(std::move(data)) {}
  size_t size() const override { return data_.size(); }
  size_t read(uint64_t pos, void* buf, size_t n, const char* = "") const override {
    if (pos >= data_.size()) return 0;
    n = std::min<size_t>(n, data_.size() - pos);
    std::memcpy(buf, data_.data() + pos, n);
    return n;
  }

 private:
  std::string data_;
};

// A nested generic dict from "a/b" keys.
c10::impl::GenericDict nestTensors(const std::map<std::string, torch::Tensor>& flat) {
  c10::impl::GenericDict root(c10::StringType::get(), c10::AnyType::get());
  for (const auto& [key, t] : flat) {
    c10::impl::GenericDict cur = root;  // shares storage: inserts below land in root
    size_t start = 0, slash;
    while ((slash = key.find('/', start)) != std::string::npos) {
      const std::string part = key.substr(start, slash - start);
      if (!cur.contains(part))
        cur.insert(part, c10::impl::GenericDict(c10::StringType::get(), c10::AnyType::get()));
      cur = cur.at(part).toGenericDict();
      start = slash + 1;
    }
    cur.insert_or_assign(key.substr(start), t);
  }
  return root;
}

c10::IValue jsonToIValue(const nlohmann::json& j) {
  if (j.is_boolean()) return j.get<bool>();
  if (j.is_number_integer()) return j.get<int64_t>();
  if (j.is_number()) return j.get<double>();
  if (j.is_string()) return j.get<std::string>();
  if (j.is_object()) {
    c10::impl::GenericDict d(c10::StringType::get(), c10::AnyType::get());
    for (auto it = j.begin(); it != j.end(); ++it) d.insert(it.key(), jsonToIValue(it.value()));
    return d;
  }
  if (j.is_array()) {
    c10::impl::GenericList l(c10::AnyType::get());
    for (const auto& x : j) l.push_back(jsonToIValue(x));
    return l;
  }
  return c10::IValue();
}

// torch::pickle_save without TorchScript's type tags: it wraps every dict and list in
// torch.jit._pickle.restore_type_tag(value, "Dict[str, Tensor]"), a global that Python's
// torch.load refuses with weights_only=True, its default since PyTorch 2.6. Python needs only
// the plain dicts and lists; our reader (model/pickle_reader.h) needs no tags either.
std::vector<char> pickleSave(const c10::IValue& value) {
  std::vector<char> pickled;
  torch::jit::Pickler pickler(
      [&](const char* bytes, size_t n) { pickled.insert(pickled.end(), bytes, bytes + n); },
      /*tensor_table=*/nullptr, /*type_renamer=*/nullptr, /*memoized_class_types=*/nullptr,
      /*get_tensor_id=*/nullptr, /*tag_aggregates=*/false);
  pickler.protocol();
  pickler.pushIValue(value);
  pickler.stop();
  std::vector<char> archive;
  caffe2::serialize::PyTorchStreamWriter writer([&](const void* bytes, size_t n) {
    const char* b = static_cast<const char*>(bytes);
    archive.insert(archive.end(), b, b + n);
    return n;
  });
  torch::jit::writeArchiveAndTensors("data", pickled.data(), pickled.size(), pickler.tensorData(),
                                     writer);
  writer.writeEndOfFile();
  return archive;
}

// {'name': tensor}, each detached, on the CPU and contiguous, as torch.save would store them.
c10::impl::GenericDict tensorDict(const std::map<std::string, torch::Tensor>& tensors) {
  c10::impl::GenericDict dict(c10::StringType::get(), c10::TensorType::get());
  for (const auto& [k, t] : tensors) {
    auto c = t.detach().to(torch::kCPU).contiguous();
    // A view into a larger buffer (FlatAdamW's) would take the whole buffer into the file.
    if (c.storage_offset() != 0 || c.storage().nbytes() != c.nbytes()) c = c.clone();
    dict.insert(k, c);
  }
  return dict;
}

void writePickled(const std::string& path, const c10::IValue& value) {
  const std::vector<char> bytes = pickleSave(value);
  writeFileAtomic(path, std::string_view(bytes.data(), bytes.size()));
}

}  // namespace

std::map<std::string, torch::Tensor> stateDict(const torch::nn::Module& module) {
  std::map<std::string, torch::Tensor> out;
  for (const auto& p : module.named_parameters()) out[p.key()] = p.value();
  for (const auto& b : module.named_buffers()) out[b.key()] = b.value();
  return out;
}

std::map<std::string, torch::Tensor> stateDict(CroCoNet& model) {
  return stateDict(*model);
}

void saveCheckpoint(const std::string& path, const std::map<std::string, torch::Tensor>& state,
                    int64_t epoch, const nlohmann::json& entries,
                    const std::map<std::string, torch::Tensor>& extraTensors) {
  c10::impl::GenericDict root(c10::StringType::get(), c10::AnyType::get());
  root.insert("model", tensorDict(state));
  root.insert("epoch", epoch);
  for (auto it = entries.begin(); it != entries.end(); ++it)
    root.insert(it.key(), jsonToIValue(it.value()));
  auto nested = nestTensors(extraTensors);
  for (const auto& entry : nested) root.insert_or_assign(entry.key(), entry.value());
  writePickled(path, root);
}

void saveCheckpoint(const std::string& path, CroCoNet& model, int64_t epoch,
                    const nlohmann::json& extra,
                    const std::map<std::string, torch::Tensor>& extraTensors) {
  nlohmann::json entries = extra;
  entries["args"] = configToJson(model->config());
  saveCheckpoint(path, stateDict(model), epoch, entries, extraTensors);
}

void saveTensors(const std::string& path, const std::map<std::string, torch::Tensor>& tensors) {
  writePickled(path, tensorDict(tensors));
}

namespace {

// A checkpoint's zip archive, and its data.pkl.
struct Archive {
  std::unique_ptr<caffe2::serialize::PyTorchStreamReader> zip;
  std::string pkl;
  std::string prefix;  // of the records: "<name>/" when data.pkl is "<name>/data.pkl"
};

Archive openArchive(const std::string& path, std::string data) {
  Archive a;
  try {
    a.zip = std::make_unique<caffe2::serialize::PyTorchStreamReader>(
        std::make_shared<StringAdapter>(std::move(data)));
    std::string pklName;
    for (const auto& r : a.zip->getAllRecords())
      if (r == "data.pkl" || (r.size() > 9 && r.compare(r.size() - 9, 9, "/data.pkl") == 0))
        pklName = r;
    if (pklName.empty()) throw Error(path, "checkpoint archive has no data.pkl");
    a.prefix = pklName.substr(0, pklName.size() - 8);
    auto [ptr, len] = a.zip->getRecord(pklName);
    a.pkl.assign(static_cast<const char*>(ptr.get()), len);
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(path, "corrupt checkpoint archive: " + oneLine(e));
  }
  return a;
}

// The value `reader` builds; the zip reader's exceptions become paircast::Error.
PyPtr readRoot(PickleReader& reader, const std::string& path) {
  try {
    return reader.read();
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(path, "corrupt checkpoint: " + oneLine(e));
  }
}

// One entry of a checkpoint dict other than its state_dict: the args, the epoch, or the rest
// (tensors flattened, other values as JSON).
void takeEntry(const std::string& key, const PyPtr& v, const std::string& path, Checkpoint& ck) {
  if (key == "args" && (v->kind == PyValue::Dict || v->kind == PyValue::Object)) {
    ck.args = toJson(v, key, path);
    ck.hasArgs = true;
  } else if (key == "epoch" && v->kind == PyValue::Int) {
    ck.epoch = v->i;
  } else {
    std::map<std::string, torch::Tensor> tensors;
    collectTensors(v, key, tensors, path);
    ck.extraTensors.insert(tensors.begin(), tensors.end());
    if (tensors.empty()) ck.extra[key] = toJson(v, key, path);
  }
}

// The checkpoint `root` holds: a plain state_dict, or a dict with one under 'model'.
Checkpoint fromRoot(const PyPtr& root, const std::string& path) {
  Checkpoint ck;
  PyPtr modelDict = nullptr;
  if (isStateDict(root)) {
    modelDict = root;
  } else if (root->kind == PyValue::Dict) {
    for (const auto& [k, v] : root->dict) {
      const std::string key = keyString(k);
      if (key == "model")
        modelDict = v;
      else
        takeEntry(key, v, path, ck);
    }
  }
  if (!modelDict || modelDict->kind != PyValue::Dict)
    throw Error(path,
                "checkpoint holds no state_dict (neither a dict of tensors nor a 'model' entry)");
  for (const auto& [k, v] : modelDict->dict) {
    if (v->kind != PyValue::Tensor)
      throw Error(path, "state_dict entry '" + keyString(k) + "' is not a tensor");
    ck.model[keyString(k)] = v->tensor;
  }
  return ck;
}

}  // namespace

Checkpoint loadCheckpoint(const std::string& path) {
  if (!std::filesystem::exists(path)) throw Error(path, "no such checkpoint");
  std::string data = readFile(path);
  const uint64_t archiveBytes = data.size();
  if (data.size() < 4 || data.compare(0, 2, "PK") != 0)
    throw Error(path,
                "not a zip checkpoint (legacy torch.save format or not a checkpoint); re-save it "
                "with torch.save(obj, path) from PyTorch >= 1.6");
  const Archive archive = openArchive(path, std::move(data));
  // The reader owns the values until return.
  PickleReader reader(archive.pkl, *archive.zip, archive.prefix, path, archiveBytes);
  return fromRoot(readRoot(reader, path), path);
}

void loadStateDictStrict(CroCoNet& model, const std::map<std::string, torch::Tensor>& state,
                         const std::string& source) {
  loadStateDictStrict(*model, state, source);
}

void loadStateDictStrict(torch::nn::Module& module,
                         const std::map<std::string, torch::Tensor>& state,
                         const std::string& source) {
  auto own = stateDict(module);
  std::vector<std::string> missing, unexpected, shapes;
  for (const auto& [k, t] : own) {
    auto it = state.find(k);
    if (it == state.end())
      missing.push_back(k);
    else if (it->second.sizes() != t.sizes()) {
      std::ostringstream os;
      os << k << " " << it->second.sizes() << " vs model " << t.sizes();
      shapes.push_back(os.str());
    }
  }
  for (const auto& [k, t] : state)
    if (!own.count(k)) unexpected.push_back(k);
  if (!missing.empty() || !unexpected.empty() || !shapes.empty()) {
    auto list = [](const std::vector<std::string>& v) {
      std::string s;
      for (size_t i = 0; i < v.size() && i < 8; ++i) s += (i ? ", " : "") + v[i];
      if (v.size() > 8) s += ", ... (" + std::to_string(v.size()) + " in all)";
      return s;
    };
    std::string msg = "state_dict does not match the model:";
    if (!missing.empty()) msg += " missing keys [" + list(missing) + "];";
    if (!unexpected.empty()) msg += " unexpected keys [" + list(unexpected) + "];";
    if (!shapes.empty()) msg += " shape mismatches [" + list(shapes) + "];";
    msg.pop_back();
    throw Error(source, msg);
  }
  torch::NoGradGuard noGrad;
  for (auto& [k, t] : own) {
    const auto& src = state.at(k);
    if (!torch::isfinite(src.to(torch::kFloat32)).all().item<bool>())
      throw Error(source, "state_dict entry '" + k + "' holds NaN or inf");
    t.copy_(src.to(t.dtype()));
  }
}

void checkConfigAgainstState(const CroCoConfig& c,
                             const std::map<std::string, torch::Tensor>& state,
                             const std::string& source) {
  auto expect = [&](const std::string& key, std::vector<int64_t> shape, const std::string& fields) {
    auto it = state.find(key);
    if (it == state.end()) throw Error(source, "checkpoint has no '" + key + "'");
    if (it->second.sizes() != c10::IntArrayRef(shape)) {
      std::ostringstream os;
      os << "'" << key << "' has shape " << it->second.sizes() << ", the model config implies "
         << c10::IntArrayRef(shape) << " (check " << fields << ")";
      throw Error(source, os.str());
    }
  };
  expect("patch_embed.proj.weight", {c.enc_embed_dim, 3, c.patch_size, c.patch_size},
         "enc_embed_dim, patch_size");
  expect("decoder_embed.weight", {c.dec_embed_dim, c.enc_embed_dim}, "dec_embed_dim");
  expect("prediction_head.weight", {c.patchDim(), c.dec_embed_dim}, "patch_size");
  if (!c.rope()) expect("enc_pos_embed", {c.numPatches(), c.enc_embed_dim}, "img_size");
  const std::string lastEnc = "enc_blocks." + std::to_string(c.enc_depth - 1) + ".norm1.weight";
  if (!state.count(lastEnc) ||
      state.count("enc_blocks." + std::to_string(c.enc_depth) + ".norm1.weight"))
    throw Error(source, "checkpoint's encoder depth differs from the config's enc_depth " +
                            std::to_string(c.enc_depth));
  const std::string lastDec = "dec_blocks." + std::to_string(c.dec_depth - 1) + ".norm1.weight";
  if (!state.count(lastDec) ||
      state.count("dec_blocks." + std::to_string(c.dec_depth) + ".norm1.weight"))
    throw Error(source, "checkpoint's decoder depth differs from the config's dec_depth " +
                            std::to_string(c.dec_depth));
}

void checkModelFitsState(const CroCoConfig& c, const std::map<std::string, torch::Tensor>& state,
                         const std::string& source, int64_t headParameters) {
  int64_t held = 0;
  for (const auto& [key, t] : state) held += t.numel();
  // A fine-tuning checkpoint keeps the encoder, and the decoder where the task is binocular: the
  // whole CroCo network it is built from is at most a few times that. The slack covers
  // pre-training's own head.
  const int64_t needed =
      countFlops(c).params + headParameters +
      int64_t(c.numPatches()) * (c.enc_embed_dim + c.dec_embed_dim);  // pos_embed
  if (needed > 4 * held + (int64_t(1) << 20))
    throw Error(source, "its model configuration asks for " + std::to_string(needed) +
                            " parameters, but it holds " + std::to_string(held) + " values");
}

}  // namespace paircast
