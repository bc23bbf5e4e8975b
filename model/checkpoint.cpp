#include "model/checkpoint.h"

#include <caffe2/serialize/inline_container.h>
#include <caffe2/serialize/istream_adapter.h>
#include <torch/csrc/jit/serialization/export.h>
#include <torch/csrc/jit/serialization/pickler.h>
#include <torch/serialize.h>

#include <cstring>
#include <deque>
#include <filesystem>
#include <memory>
#include <set>
#include <sstream>
#include <unordered_map>
#include <variant>

#include "util/atomic_file.h"
#include "util/error.h"

namespace paircast {
namespace {

// ---- a value-only pickle reader ----

// Values point at each other with plain pointers and all live in the reader's arena until the
// load ends, so a pickle that builds a cycle (a list appended to itself through the memo) or a
// chain a million deep can neither leak nor overflow the stack when it is freed.
struct PyValue;
using PyPtr = PyValue*;

struct PyValue {
  enum Kind {
    None,
    Bool,
    Int,
    Float,
    String,
    Bytes,
    List,
    Tuple,
    Dict,
    Tensor,
    Global,
    Object,
    Storage
  } kind = None;
  int64_t i = 0;
  double f = 0;
  std::string s;                              // String, Bytes, Global ("module.name"), Storage key
  std::vector<PyPtr> items;                   // List, Tuple
  std::vector<std::pair<PyPtr, PyPtr>> dict;  // Dict (insertion order), Object state
  torch::Tensor tensor;
  torch::ScalarType dtype = torch::kFloat32;  // Storage
};

// Limits on what a data.pkl may build: far above what a checkpoint needs (one value or two per
// tensor; a state_dict nests 2 levels, optimizer state 5), far below what would exhaust memory.
constexpr size_t kMaxValues = size_t(1) << 22;
constexpr int kMaxDepth = 100;
// Tensors are copied out of their storages; a view may repeat elements (stride 0) but not
// without bound, and all copies together are bounded by the file's size.
constexpr int64_t kMaxBroadcastElements = int64_t(1) << 24;
constexpr uint64_t kTensorBytesSlack = uint64_t(64) << 20;

// The globals a checkpoint may name: the reader never calls anything, but a file naming
// os.system or builtins.eval is hostile or not a checkpoint, and is refused outright. Those
// reduce() does not know become inert objects holding their state.
bool allowedGlobal(const std::string& name) {
  static const std::set<std::string> exact = {
      "collections.OrderedDict",
      "torch.jit._pickle.restore_type_tag",  // LibTorch's typed containers
      "torch.device",
      "torch.Size",
      "argparse.Namespace",  // the official CroCo checkpoints' "args"
      "numpy.dtype",
      "numpy.ndarray",
      "_codecs.encode",  // numpy scalars' bytes under protocol 2
  };
  auto startsWith = [&](const char* prefix) { return name.rfind(prefix, 0) == 0; };
  auto endsWith = [&](const std::string& suffix) {
    return name.size() >= suffix.size() &&
           name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0;
  };
  return exact.count(name) || startsWith("torch._utils._rebuild_") ||
         startsWith("numpy.core.multiarray.") ||
         (startsWith("torch.") && endsWith("Storage") && name.find('.', 6) == std::string::npos);
}

torch::ScalarType storageDtype(const std::string& global, const std::string& source) {
  static const std::map<std::string, torch::ScalarType> types = {
      {"torch.FloatStorage", torch::kFloat32}, {"torch.DoubleStorage", torch::kFloat64},
      {"torch.HalfStorage", torch::kFloat16},  {"torch.BFloat16Storage", torch::kBFloat16},
      {"torch.LongStorage", torch::kInt64},    {"torch.IntStorage", torch::kInt32},
      {"torch.ShortStorage", torch::kInt16},   {"torch.CharStorage", torch::kInt8},
      {"torch.ByteStorage", torch::kUInt8},    {"torch.BoolStorage", torch::kBool}};
  auto it = types.find(global);
  if (it == types.end()) throw Error(source, "unsupported storage type " + global);
  return it->second;
}

class PickleReader {
 public:
  // `archiveBytes` (the checkpoint's size) bounds the bytes of the tensors built.
  PickleReader(const std::string& data, caffe2::serialize::PyTorchStreamReader& zip,
               const std::string& prefix, const std::string& source, uint64_t archiveBytes)
      : data_(data),
        zip_(zip),
        prefix_(prefix),
        source_(source),
        maxTensorBytes_(2 * archiveBytes + kTensorBytesSlack) {}

  PyPtr read() {
    while (true) {
      if (pos_ >= data_.size()) fail("data.pkl ends before STOP");
      const uint8_t op = byte();
      switch (op) {
        case 0x80:
          byte();
          break;  // PROTO
        case 0x95:
          bytes(8);
          break;  // FRAME
        case '.':
          return pop();  // STOP
        case '(':
          marks_.push_back(stack_.size());
          break;
        case 'N':
          stack_.push_back(make(PyValue::None));
          break;
        case 0x88:
        case 0x89: {  // NEWTRUE, NEWFALSE
          auto v = make(PyValue::Bool);
          v->i = op == 0x88;
          stack_.push_back(v);
          break;
        }
        case 'J':
          pushInt(static_cast<int32_t>(le(4)));
          break;
        case 'K':
          pushInt(le(1));
          break;
        case 'M':
          pushInt(le(2));
          break;
        case 0x8a: {  // LONG1
          const size_t n = byte();
          if (n > 8) fail("integer too large");
          uint64_t v = le(n);
          if (n > 0 && n < 8 && (v >> (8 * n - 1)) & 1) v |= ~0ull << (8 * n);
          pushInt(static_cast<int64_t>(v));
          break;
        }
        case 'G': {  // BINFLOAT, big-endian
          uint64_t bits = 0;
          for (int k = 0; k < 8; ++k) bits = (bits << 8) | byte();
          auto v = make(PyValue::Float);
          std::memcpy(&v->f, &bits, 8);
          stack_.push_back(v);
          break;
        }
        case 'X':
          pushString(PyValue::String, le(4));
          break;
        case 0x8c:
          pushString(PyValue::String, byte());
          break;
        case 'T':
          pushString(PyValue::String, le(4));
          break;
        case 'U':
          pushString(PyValue::String, byte());
          break;
        case 'B':
          pushString(PyValue::Bytes, le(4));
          break;
        case 'C':
          pushString(PyValue::Bytes, byte());
          break;
        case ']':
          stack_.push_back(make(PyValue::List));
          break;
        case '}':
          stack_.push_back(make(PyValue::Dict));
          break;
        case ')':
          stack_.push_back(make(PyValue::Tuple));
          break;
        case 0x85:
        case 0x86:
        case 0x87: {  // TUPLE1..3
          auto t = make(PyValue::Tuple);
          const size_t n = op - 0x84;
          need(n);
          t->items.assign(stack_.end() - n, stack_.end());
          stack_.resize(stack_.size() - n);
          stack_.push_back(t);
          break;
        }
        case 't': {
          auto t = make(PyValue::Tuple);
          t->items = popMark();
          stack_.push_back(t);
          break;
        }
        case 'l': {
          auto t = make(PyValue::List);
          t->items = popMark();
          stack_.push_back(t);
          break;
        }
        case 'a': {
          auto v = pop();
          top(PyValue::List)->items.push_back(v);
          break;
        }
        case 'e': {
          auto items = popMark();
          auto list = top(PyValue::List);
          list->items.insert(list->items.end(), items.begin(), items.end());
          break;
        }
        case 's': {
          auto v = pop(), k = pop();
          setItem(top(), k, v);
          break;
        }
        case 'u': {
          auto items = popMark();
          if (items.size() % 2) fail("SETITEMS with an odd count");
          auto d = top();
          for (size_t k = 0; k < items.size(); k += 2) setItem(d, items[k], items[k + 1]);
          break;
        }
        case 'q':
          memo(byte());
          break;
        case 'r':
          memo(le(4));
          break;
        case 0x94:
          memo(memo_.size());
          break;  // MEMOIZE
        case 'h':
          get(byte());
          break;
        case 'j':
          get(le(4));
          break;
        case 'c': {  // GLOBAL module\nname\n
          const std::string module = line(), name = line();
          pushGlobal(module + "." + name, "GLOBAL");
          break;
        }
        case 0x93: {  // STACK_GLOBAL
          auto name = pop(), module = pop();
          if (name->kind != PyValue::String || module->kind != PyValue::String)
            fail("STACK_GLOBAL of a non-string");
          pushGlobal(module->s + "." + name->s, "STACK_GLOBAL");
          break;
        }
        case 'Q': {  // BINPERSID: ('storage', type, key, location, numel)
          auto pid = pop();
          if (pid->kind != PyValue::Tuple || pid->items.size() < 5 || pid->items[0]->s != "storage")
            fail("unsupported persistent id");
          if (pid->items[1]->kind != PyValue::Global || pid->items[2]->kind != PyValue::String ||
              pid->items[4]->kind != PyValue::Int)
            fail("malformed storage persistent id");
          auto st = make(PyValue::Storage);
          st->dtype = storageDtype(pid->items[1]->s, source_);
          st->s = pid->items[2]->s;
          st->i = pid->items[4]->i;
          stack_.push_back(st);
          break;
        }
        case 'R':
        case 0x81: {  // REDUCE, NEWOBJ
          auto args = pop(), callable = pop();
          stack_.push_back(reduce(callable, args));
          break;
        }
        case 'b': {  // BUILD: object state
          auto state = pop();
          auto obj = top();
          if (obj->kind == PyValue::Object && state->kind == PyValue::Dict) obj->dict = state->dict;
          break;
        }
        default:
          fail("unsupported pickle opcode 0x" + hex(op));
      }
    }
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    throw Error(source_,
                "cannot read checkpoint (data.pkl at byte " + std::to_string(pos_) + "): " + what);
  }
  static std::string hex(int v) {
    std::ostringstream os;
    os << std::hex << v;
    return os.str();
  }
  PyPtr make(PyValue::Kind k) {
    if (values_.size() >= kMaxValues)
      fail("data.pkl builds more than " + std::to_string(kMaxValues) + " values");
    values_.emplace_back();
    values_.back().kind = k;
    return &values_.back();
  }
  void pushGlobal(const std::string& name, const char* opcode) {
    if (!allowedGlobal(name))
      fail("refusing global '" + name + "' (" + opcode +
           " opcode): a checkpoint holds only tensors and plain values, never code");
    auto g = make(PyValue::Global);
    g->s = name;
    stack_.push_back(g);
  }
  uint8_t byte() {
    if (pos_ >= data_.size()) fail("unexpected end");
    return static_cast<uint8_t>(data_[pos_++]);
  }
  std::string bytes(size_t n) {
    if (n > data_.size() - pos_) fail("length beyond the end");
    std::string s = data_.substr(pos_, n);
    pos_ += n;
    return s;
  }
  uint64_t le(size_t n) {
    uint64_t v = 0;
    for (size_t k = 0; k < n; ++k) v |= static_cast<uint64_t>(byte()) << (8 * k);
    return v;
  }
  std::string line() {
    const size_t end = data_.find('\n', pos_);
    if (end == std::string::npos) fail("unterminated GLOBAL");
    std::string s = data_.substr(pos_, end - pos_);
    pos_ = end + 1;
    return s;
  }
  void need(size_t n) {
    if (stack_.size() < n) fail("stack underflow");
  }
  PyPtr pop() {
    need(1);
    auto v = stack_.back();
    stack_.pop_back();
    return v;
  }
  PyPtr top(int kind = -1) {
    need(1);
    if (kind >= 0 && stack_.back()->kind != kind) fail("unexpected value type");
    return stack_.back();
  }
  std::vector<PyPtr> popMark() {
    if (marks_.empty()) fail("no MARK");
    const size_t m = marks_.back();
    marks_.pop_back();
    if (m > stack_.size()) fail("bad MARK");
    std::vector<PyPtr> items(stack_.begin() + m, stack_.end());
    stack_.resize(m);
    return items;
  }
  void pushInt(int64_t v) {
    auto p = make(PyValue::Int);
    p->i = v;
    stack_.push_back(p);
  }
  void pushString(PyValue::Kind kind, size_t n) {
    auto p = make(kind);
    p->s = bytes(n);
    stack_.push_back(p);
  }
  void memo(size_t index) {
    need(1);
    memo_[index] = stack_.back();  // a map: a 4-byte index must not size a vector
  }
  void get(size_t index) {
    auto it = memo_.find(index);
    if (it == memo_.end()) fail("memo key not found");
    stack_.push_back(it->second);
  }
  void setItem(const PyPtr& target, const PyPtr& k, const PyPtr& v) {
    if (target->kind != PyValue::Dict && target->kind != PyValue::Object)
      fail("SETITEM on a non-dict");
    target->dict.emplace_back(k, v);
  }

  PyPtr reduce(const PyPtr& callable, const PyPtr& args) {
    if (callable->kind != PyValue::Global) fail("REDUCE of a non-global");
    const std::string& name = callable->s;
    if (name == "collections.OrderedDict") return make(PyValue::Dict);
    if (name == "torch._utils._rebuild_tensor_v2" || name == "torch._utils._rebuild_tensor") {
      if (args->kind != PyValue::Tuple || args->items.size() < 4 ||
          args->items[1]->kind != PyValue::Int)
        fail("bad tensor arguments");
      return rebuildTensor(args->items[0], args->items[1]->i, args->items[2], args->items[3]);
    }
    if (name == "torch.jit._pickle.restore_type_tag") {  // LibTorch's typed containers
      if (args->kind != PyValue::Tuple || args->items.empty())
        fail("bad restore_type_tag arguments");
      return args->items[0];
    }
    if (name == "torch._utils._rebuild_parameter") {
      if (args->kind != PyValue::Tuple || args->items.empty()) fail("bad parameter arguments");
      return args->items[0];
    }
    // Anything else (argparse.Namespace, numpy scalars, ...) becomes an inert object.
    auto obj = make(PyValue::Object);
    obj->s = name;
    return obj;
  }

  PyPtr rebuildTensor(const PyPtr& storage, int64_t offset, const PyPtr& size,
                      const PyPtr& stride) {
    if (storage->kind != PyValue::Storage) fail("tensor without storage");
    if (size->kind != PyValue::Tuple || stride->kind != PyValue::Tuple)
      fail("tensor size or stride is not a tuple");
    std::vector<int64_t> sizes, strides;
    for (const auto& v : size->items) {
      if (v->kind != PyValue::Int) fail("tensor size holds a non-integer");
      sizes.push_back(v->i);
    }
    for (const auto& v : stride->items) {
      if (v->kind != PyValue::Int) fail("tensor stride holds a non-integer");
      strides.push_back(v->i);
    }
    if (sizes.size() != strides.size()) fail("size and stride differ in length");
    auto& base = storages_[storage->s];
    if (!base.defined()) {
      const std::string record = prefix_ + "data/" + storage->s;
      if (!zip_.hasRecord(record)) fail("missing storage record '" + record + "'");
      auto [ptr, bytesLen] = zip_.getRecord(record);
      const size_t elem = c10::elementSize(storage->dtype);
      if (storage->i < 0 || bytesLen % elem != 0 || bytesLen / elem != uint64_t(storage->i))
        fail("storage '" + storage->s + "' has " + std::to_string(bytesLen) + " bytes, not " +
             std::to_string(storage->i) + " elements of " + std::to_string(elem) + " bytes");
      base = torch::empty({storage->i}, torch::TensorOptions().dtype(storage->dtype));
      if (bytesLen > 0) std::memcpy(base.data_ptr(), ptr.get(), bytesLen);
    }
    // Bounds, in checked arithmetic: the largest index reached must lie inside the storage.
    if (offset < 0) fail("negative storage offset");
    int64_t last = offset, numel = 1;
    for (size_t k = 0; k < sizes.size(); ++k) {
      if (sizes[k] < 0 || strides[k] < 0) fail("negative size or stride");
      int64_t reach = 0;
      if (sizes[k] > 0 && (__builtin_mul_overflow(sizes[k] - 1, strides[k], &reach) ||
                           __builtin_add_overflow(last, reach, &last)))
        fail("tensor view outside its storage");
      if (__builtin_mul_overflow(numel, sizes[k], &numel)) fail("tensor size overflows");
    }
    const bool empty = numel == 0;
    if (!empty && last >= base.numel()) fail("tensor view outside its storage");
    if (numel > std::max(base.numel(), kMaxBroadcastElements))
      fail("tensor view has " + std::to_string(numel) + " elements, its storage " +
           std::to_string(base.numel()));
    tensorBytes_ += static_cast<uint64_t>(numel) * base.element_size();
    if (tensorBytes_ > maxTensorBytes_)
      fail("tensors take more than " + std::to_string(maxTensorBytes_) +
           " bytes, far more than the file holds");
    auto t = make(PyValue::Tensor);
    t->tensor = empty ? torch::empty(sizes, base.options())
                      : base.as_strided(sizes, strides, offset).clone();
    return t;
  }

  const std::string& data_;
  caffe2::serialize::PyTorchStreamReader& zip_;
  std::string prefix_, source_;
  uint64_t maxTensorBytes_, tensorBytes_ = 0;
  size_t pos_ = 0;
  std::deque<PyValue> values_;  // the arena: a deque never moves what it holds
  std::vector<PyPtr> stack_;
  std::unordered_map<uint64_t, PyPtr> memo_;
  std::vector<size_t> marks_;
  std::map<std::string, torch::Tensor> storages_;
};

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
// the plain dicts and lists; our reader (above) needs no tags either.
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

}  // namespace

std::map<std::string, torch::Tensor> stateDict(CroCoNet& model) {
  std::map<std::string, torch::Tensor> out;
  for (const auto& p : model->named_parameters()) out[p.key()] = p.value();
  for (const auto& b : model->named_buffers()) out[b.key()] = b.value();
  return out;
}

void saveCheckpoint(const std::string& path, CroCoNet& model, int64_t epoch,
                    const nlohmann::json& extra,
                    const std::map<std::string, torch::Tensor>& extraTensors) {
  c10::impl::GenericDict state(c10::StringType::get(), c10::TensorType::get());
  for (const auto& [k, t] : stateDict(model))
    state.insert(k, t.detach().to(torch::kCPU).contiguous());
  c10::impl::GenericDict root(c10::StringType::get(), c10::AnyType::get());
  root.insert("model", state);
  root.insert("args", jsonToIValue(configToJson(model->config())));
  root.insert("epoch", epoch);
  for (auto it = extra.begin(); it != extra.end(); ++it)
    root.insert(it.key(), jsonToIValue(it.value()));
  auto nested = nestTensors(extraTensors);
  for (const auto& entry : nested) root.insert_or_assign(entry.key(), entry.value());
  const std::vector<char> bytes = pickleSave(root);
  writeFileAtomic(path, std::string_view(bytes.data(), bytes.size()));
}

Checkpoint loadCheckpoint(const std::string& path) {
  if (!std::filesystem::exists(path)) throw Error(path, "no such checkpoint");
  std::string data = readFile(path);
  const uint64_t archiveBytes = data.size();
  if (data.size() < 4 || data.compare(0, 2, "PK") != 0)
    throw Error(path,
                "not a zip checkpoint (legacy torch.save format or not a checkpoint); re-save it "
                "with torch.save(obj, path) from PyTorch >= 1.6");
  std::unique_ptr<caffe2::serialize::PyTorchStreamReader> zip;
  std::string pkl, prefix;
  try {
    zip = std::make_unique<caffe2::serialize::PyTorchStreamReader>(
        std::make_shared<StringAdapter>(std::move(data)));
    std::string pklName;
    for (const auto& r : zip->getAllRecords())
      if (r == "data.pkl" || (r.size() > 9 && r.compare(r.size() - 9, 9, "/data.pkl") == 0))
        pklName = r;
    if (pklName.empty()) throw Error(path, "checkpoint archive has no data.pkl");
    prefix = pklName.substr(0, pklName.size() - 8);
    auto [ptr, len] = zip->getRecord(pklName);
    pkl.assign(static_cast<const char*>(ptr.get()), len);
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(path, "corrupt checkpoint archive: " + oneLine(e));
  }
  PickleReader reader(pkl, *zip, prefix, path, archiveBytes);  // owns the values until return
  PyPtr root = nullptr;
  try {
    root = reader.read();
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    throw Error(path, "corrupt checkpoint: " + oneLine(e));
  }

  Checkpoint ck;
  PyPtr modelDict = nullptr;
  if (isStateDict(root)) {
    modelDict = root;
  } else if (root->kind == PyValue::Dict) {
    for (const auto& [k, v] : root->dict) {
      const std::string key = keyString(k);
      if (key == "model")
        modelDict = v;
      else if (key == "args" && (v->kind == PyValue::Dict || v->kind == PyValue::Object)) {
        ck.args = toJson(v, key, path);
        ck.hasArgs = true;
      } else if (key == "epoch" && v->kind == PyValue::Int)
        ck.epoch = v->i;
      else {
        std::map<std::string, torch::Tensor> tensors;
        collectTensors(v, key, tensors, path);
        ck.extraTensors.insert(tensors.begin(), tensors.end());
        if (tensors.empty()) ck.extra[key] = toJson(v, key, path);
      }
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

void loadStateDictStrict(CroCoNet& model, const std::map<std::string, torch::Tensor>& state,
                         const std::string& source) {
  auto own = stateDict(model);
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

}  // namespace paircast
