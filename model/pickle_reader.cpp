#include "model/pickle_reader.h"

#include <caffe2/serialize/inline_container.h>

#include <array>
#include <cstring>
#include <deque>
#include <initializer_list>
#include <map>
#include <set>
#include <sstream>
#include <unordered_map>

#include "util/error.h"

namespace paircast {
namespace {

// Limits on what a data.pkl may build: far above what a checkpoint needs (one value or two per
// tensor), far below what would exhaust memory.
constexpr size_t kMaxValues = size_t(1) << 22;
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

std::string hex(int v) {
  std::ostringstream os;
  os << std::hex << v;
  return os.str();
}

}  // namespace

// The pickle machine: a stack, marks into it, and a memo. read() runs one handler per opcode,
// from a table; the handlers below are grouped as in Python's pickletools, and named after the
// opcodes they run.
class PickleReader::Impl {
 public:
  Impl(const std::string& data, caffe2::serialize::PyTorchStreamReader& zip,
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
      if (op == '.') return pop();  // STOP
      const Handler handler = handlers()[op];
      if (!handler) fail("unsupported pickle opcode 0x" + hex(op));
      (this->*handler)(op);
    }
  }

 private:
  using Handler = void (Impl::*)(uint8_t op);

  static const std::array<Handler, 256>& handlers() {
    static const std::array<Handler, 256> table = [] {
      std::array<Handler, 256> t{};
      auto on = [&](std::initializer_list<uint8_t> ops, Handler h) {
        for (uint8_t op : ops) t[op] = h;
      };
      on({0x80}, &Impl::opProto);
      on({0x95}, &Impl::opFrame);
      on({'('}, &Impl::opMark);
      on({'N'}, &Impl::opNone);
      on({0x88, 0x89}, &Impl::opNewBool);  // NEWTRUE, NEWFALSE
      on({'J'}, &Impl::opBinInt);
      on({'K'}, &Impl::opBinInt1);
      on({'M'}, &Impl::opBinInt2);
      on({0x8a}, &Impl::opLong1);
      on({'G'}, &Impl::opBinFloat);
      on({'X', 'T'}, &Impl::opString4);   // BINUNICODE, BINSTRING
      on({0x8c, 'U'}, &Impl::opString1);  // SHORT_BINUNICODE, SHORT_BINSTRING
      on({'B'}, &Impl::opBinBytes);
      on({'C'}, &Impl::opShortBinBytes);
      on({']', '}', ')'}, &Impl::opEmpty);      // EMPTY_LIST, EMPTY_DICT, EMPTY_TUPLE
      on({0x85, 0x86, 0x87}, &Impl::opTupleN);  // TUPLE1, TUPLE2, TUPLE3
      on({'t', 'l'}, &Impl::opMarkedSequence);  // TUPLE, LIST
      on({'a'}, &Impl::opAppend);
      on({'e'}, &Impl::opAppends);
      on({'s'}, &Impl::opSetItem);
      on({'u'}, &Impl::opSetItems);
      on({'q'}, &Impl::opBinPut);
      on({'r'}, &Impl::opLongBinPut);
      on({0x94}, &Impl::opMemoize);
      on({'h'}, &Impl::opBinGet);
      on({'j'}, &Impl::opLongBinGet);
      on({'c'}, &Impl::opGlobal);
      on({0x93}, &Impl::opStackGlobal);
      on({'Q'}, &Impl::opBinPersId);
      on({'R', 0x81}, &Impl::opReduce);  // REDUCE, NEWOBJ
      on({'b'}, &Impl::opBuild);
      return t;
    }();
    return table;
  }

  // ---- framing ----

  void opProto(uint8_t) { byte(); }
  void opFrame(uint8_t) { bytes(8); }
  void opMark(uint8_t) { marks_.push_back(stack_.size()); }

  // ---- constants and numbers ----

  void opNone(uint8_t) { stack_.push_back(make(PyValue::None)); }
  void opNewBool(uint8_t op) {
    auto v = make(PyValue::Bool);
    v->i = op == 0x88;
    stack_.push_back(v);
  }
  void opBinInt(uint8_t) { pushInt(static_cast<int32_t>(le(4))); }
  void opBinInt1(uint8_t) { pushInt(le(1)); }
  void opBinInt2(uint8_t) { pushInt(le(2)); }
  void opLong1(uint8_t) {
    const size_t n = byte();
    if (n > 8) fail("integer too large");
    uint64_t v = le(n);
    if (n > 0 && n < 8 && (v >> (8 * n - 1)) & 1) v |= ~0ull << (8 * n);
    pushInt(static_cast<int64_t>(v));
  }
  void opBinFloat(uint8_t) {  // big-endian
    uint64_t bits = 0;
    for (int k = 0; k < 8; ++k) bits = (bits << 8) | byte();
    auto v = make(PyValue::Float);
    std::memcpy(&v->f, &bits, 8);
    stack_.push_back(v);
  }

  // ---- strings ----

  void opString4(uint8_t) { pushString(PyValue::String, le(4)); }
  void opString1(uint8_t) { pushString(PyValue::String, byte()); }
  void opBinBytes(uint8_t) { pushString(PyValue::Bytes, le(4)); }
  void opShortBinBytes(uint8_t) { pushString(PyValue::Bytes, byte()); }

  // ---- containers ----

  void opEmpty(uint8_t op) {
    stack_.push_back(make(op == ']' ? PyValue::List : op == '}' ? PyValue::Dict : PyValue::Tuple));
  }
  void opTupleN(uint8_t op) {
    auto t = make(PyValue::Tuple);
    const size_t n = op - 0x84;
    need(n);
    t->items.assign(stack_.end() - n, stack_.end());
    stack_.resize(stack_.size() - n);
    stack_.push_back(t);
  }
  void opMarkedSequence(uint8_t op) {
    auto t = make(op == 't' ? PyValue::Tuple : PyValue::List);
    t->items = popMark();
    stack_.push_back(t);
  }
  void opAppend(uint8_t) {
    auto v = pop();
    top(PyValue::List)->items.push_back(v);
  }
  void opAppends(uint8_t) {
    auto items = popMark();
    auto list = top(PyValue::List);
    list->items.insert(list->items.end(), items.begin(), items.end());
  }
  void opSetItem(uint8_t) {
    auto v = pop(), k = pop();
    setItem(top(), k, v);
  }
  void opSetItems(uint8_t) {
    auto items = popMark();
    if (items.size() % 2) fail("SETITEMS with an odd count");
    auto d = top();
    for (size_t k = 0; k < items.size(); k += 2) setItem(d, items[k], items[k + 1]);
  }

  // ---- the memo ----

  void opBinPut(uint8_t) { memo(byte()); }
  void opLongBinPut(uint8_t) { memo(le(4)); }
  void opMemoize(uint8_t) { memo(memo_.size()); }
  void opBinGet(uint8_t) { get(byte()); }
  void opLongBinGet(uint8_t) { get(le(4)); }

  // ---- globals, storages and objects ----

  void opGlobal(uint8_t) {  // module\nname\n
    const std::string module = line(), name = line();
    pushGlobal(module + "." + name, "GLOBAL");
  }
  void opStackGlobal(uint8_t) {
    auto name = pop(), module = pop();
    if (name->kind != PyValue::String || module->kind != PyValue::String)
      fail("STACK_GLOBAL of a non-string");
    pushGlobal(module->s + "." + name->s, "STACK_GLOBAL");
  }
  void opBinPersId(uint8_t) {  // ('storage', type, key, location, numel)
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
  }
  void opReduce(uint8_t) {
    auto args = pop(), callable = pop();
    stack_.push_back(reduce(callable, args));
  }
  void opBuild(uint8_t) {  // an object's state
    auto state = pop();
    auto obj = top();
    if (obj->kind == PyValue::Object && state->kind == PyValue::Dict) obj->dict = state->dict;
  }

  // ---- reading bytes ----

  [[noreturn]] void fail(const std::string& what) const {
    throw Error(source_,
                "cannot read checkpoint (data.pkl at byte " + std::to_string(pos_) + "): " + what);
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

  // ---- the stack, the memo and the arena ----

  PyPtr make(PyValue::Kind k) {
    if (values_.size() >= kMaxValues)
      fail("data.pkl builds more than " + std::to_string(kMaxValues) + " values");
    values_.emplace_back();
    values_.back().kind = k;
    return &values_.back();
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
  void pushGlobal(const std::string& name, const char* opcode) {
    if (!allowedGlobal(name))
      fail("refusing global '" + name + "' (" + opcode +
           " opcode): a checkpoint holds only tensors and plain values, never code");
    auto g = make(PyValue::Global);
    g->s = name;
    stack_.push_back(g);
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

  // ---- calls: the few the reader knows, the rest inert ----

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

  // ---- tensors ----

  // A tensor's sizes or strides, from a tuple of integers; `what` names them in errors.
  std::vector<int64_t> integers(const PyPtr& tuple, const char* what) {
    std::vector<int64_t> out;
    for (const auto& v : tuple->items) {
      if (v->kind != PyValue::Int) fail(std::string("tensor ") + what + " holds a non-integer");
      out.push_back(v->i);
    }
    return out;
  }

  // The storage's elements, read from its record the first time it is named.
  const torch::Tensor& storageTensor(const PyValue& storage) {
    auto& base = storages_[storage.s];
    if (base.defined()) return base;
    const std::string record = prefix_ + "data/" + storage.s;
    if (!zip_.hasRecord(record)) fail("missing storage record '" + record + "'");
    auto [ptr, bytesLen] = zip_.getRecord(record);
    const size_t elem = c10::elementSize(storage.dtype);
    if (storage.i < 0 || bytesLen % elem != 0 || bytesLen / elem != uint64_t(storage.i))
      fail("storage '" + storage.s + "' has " + std::to_string(bytesLen) + " bytes, not " +
           std::to_string(storage.i) + " elements of " + std::to_string(elem) + " bytes");
    base = torch::empty({storage.i}, torch::TensorOptions().dtype(storage.dtype));
    if (bytesLen > 0) std::memcpy(base.data_ptr(), ptr.get(), bytesLen);
    return base;
  }

  // The elements of a view of `base`, after checking in checked arithmetic that the largest
  // index it reaches lies inside the storage, and that it repeats elements only within bounds.
  int64_t viewElements(const torch::Tensor& base, int64_t offset, const std::vector<int64_t>& sizes,
                       const std::vector<int64_t>& strides) {
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
    if (numel != 0 && last >= base.numel()) fail("tensor view outside its storage");
    if (numel > std::max(base.numel(), kMaxBroadcastElements))
      fail("tensor view has " + std::to_string(numel) + " elements, its storage " +
           std::to_string(base.numel()));
    return numel;
  }

  PyPtr rebuildTensor(const PyPtr& storage, int64_t offset, const PyPtr& size,
                      const PyPtr& stride) {
    if (storage->kind != PyValue::Storage) fail("tensor without storage");
    if (size->kind != PyValue::Tuple || stride->kind != PyValue::Tuple)
      fail("tensor size or stride is not a tuple");
    const std::vector<int64_t> sizes = integers(size, "size");
    const std::vector<int64_t> strides = integers(stride, "stride");
    if (sizes.size() != strides.size()) fail("size and stride differ in length");
    const torch::Tensor& base = storageTensor(*storage);
    const int64_t numel = viewElements(base, offset, sizes, strides);
    tensorBytes_ += static_cast<uint64_t>(numel) * base.element_size();
    if (tensorBytes_ > maxTensorBytes_)
      fail("tensors take more than " + std::to_string(maxTensorBytes_) +
           " bytes, far more than the file holds");
    auto t = make(PyValue::Tensor);
    t->tensor = numel == 0 ? torch::empty(sizes, base.options())
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

PickleReader::PickleReader(const std::string& data, caffe2::serialize::PyTorchStreamReader& zip,
                           const std::string& prefix, const std::string& source,
                           uint64_t archiveBytes)
    : impl_(std::make_unique<Impl>(data, zip, prefix, source, archiveBytes)) {}

PickleReader::~PickleReader() = default;

PyPtr PickleReader::read() {
  return impl_->read();
}

}  // namespace paircast
