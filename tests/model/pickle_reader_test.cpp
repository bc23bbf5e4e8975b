// The value-only pickle reader on hand-written pickles: each opcode family it supports builds
// the values Python's pickle would, and what it must not run (globals naming code, opcodes it
// does not know, malformed streams) is refused with a message naming the file, the byte and why.
#include "model/pickle_reader.h"

#include <caffe2/serialize/inline_container.h>
#include <gtest/gtest.h>

#include <map>
#include <memory>
#include <sstream>
#include <string>

#include "model/pickle_pieces.h"
#include "util/error.h"

namespace paircast {
namespace {

using testing::i64;
using testing::str;
using testing::tensor;
using namespace std::string_literals;

// A pickle in an in-memory archive as torch.save lays it out (data.pkl and a record data/<key>
// per storage, under the archive's own folder, which the zip reader leaves out), and a reader of
// it.
class Pickled {
 public:
  explicit Pickled(std::string pkl, const std::map<std::string, std::string>& storages = {})
      : pkl_(std::move(pkl)) {
    {
      caffe2::serialize::PyTorchStreamWriter writer([&](const void* bytes, size_t n) {
        archive_.append(static_cast<const char*>(bytes), n);
        return n;
      });
      writer.writeRecord("data.pkl", pkl_.data(), pkl_.size());
      for (const auto& [key, bytes] : storages)
        writer.writeRecord("data/" + key, bytes.data(), bytes.size());
      writer.writeEndOfFile();
    }
    stream_.str(archive_);
    zip_ = std::make_unique<caffe2::serialize::PyTorchStreamReader>(&stream_);
    reader_ = std::make_unique<PickleReader>(pkl_, *zip_, "", "test.pkl", archive_.size());
  }
  PyPtr read() { return reader_->read(); }

 private:
  std::string pkl_, archive_;
  std::istringstream stream_;
  std::unique_ptr<caffe2::serialize::PyTorchStreamReader> zip_;
  std::unique_ptr<PickleReader> reader_;
};

// The message reading `pkl` fails with ("" after a failure when it does not).
std::string refusal(const std::string& pkl) {
  try {
    Pickled(pkl).read();
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "the pickle was read";
  return "";
}

// Pickle pieces.
const std::string kProto2 = "\x80\x02";
std::string shortStr(const std::string& s) {  // SHORT_BINUNICODE
  return "\x8c" + std::string(1, static_cast<char>(s.size())) + s;
}

TEST(PickleReader, ReadsConstantsNumbersAndStrings) {
  // (None, True, False, 7, 0x1234, -2, -1, 0, 1.5, 'ab', 'c', b'xy', b'z')
  const std::string pkl = kProto2 + "(N\x88\x89K\x07M\x34\x12J\xfe\xff\xff\xff" +
                          std::string("\x8a\x01\xff\x8a\x00", 5) +
                          std::string("G\x3f\xf8\x00\x00\x00\x00\x00\x00", 9) + str("ab") +
                          shortStr("c") + std::string("B\x02\x00\x00\x00xy", 7) + "C\x01z" + "t.";
  Pickled p(pkl);
  const PyPtr t = p.read();
  ASSERT_EQ(t->kind, PyValue::Tuple);
  ASSERT_EQ(t->items.size(), 13u);
  EXPECT_EQ(t->items[0]->kind, PyValue::None);
  EXPECT_EQ(t->items[1]->kind, PyValue::Bool);
  EXPECT_EQ(t->items[1]->i, 1);
  EXPECT_EQ(t->items[2]->i, 0);
  const int64_t ints[] = {7, 0x1234, -2, -1, 0};
  for (int k = 0; k < 5; ++k) {
    EXPECT_EQ(t->items[3 + k]->kind, PyValue::Int) << k;
    EXPECT_EQ(t->items[3 + k]->i, ints[k]) << k;
  }
  EXPECT_EQ(t->items[8]->kind, PyValue::Float);
  EXPECT_EQ(t->items[8]->f, 1.5);
  EXPECT_EQ(t->items[9]->kind, PyValue::String);
  EXPECT_EQ(t->items[9]->s, "ab");
  EXPECT_EQ(t->items[10]->s, "c");
  EXPECT_EQ(t->items[11]->kind, PyValue::Bytes);
  EXPECT_EQ(t->items[11]->s, "xy");
  EXPECT_EQ(t->items[12]->s, "z");
}

TEST(PickleReader, BuildsContainersAndSharesMemoizedValues) {
  // Protocol 4, framed: d = {'a': [1, 2], 'b': (3,), 'c': <the same list>, 'e': ()}
  const std::string body = "}\x94(" + shortStr("a") + "]\x94(K\x01K\x02" + "e" + shortStr("b") +
                           "K\x03\x85" + shortStr("c") + "h\x01" + shortStr("e") + ")" + "u.";
  const uint64_t n = body.size();
  Pickled p("\x80\x04\x95" + std::string(reinterpret_cast<const char*>(&n), 8) + body);
  const PyPtr d = p.read();
  ASSERT_EQ(d->kind, PyValue::Dict);
  ASSERT_EQ(d->dict.size(), 4u);
  const char* keys[] = {"a", "b", "c", "e"};
  for (int k = 0; k < 4; ++k) EXPECT_EQ(d->dict[k].first->s, keys[k]) << "insertion order";
  const PyPtr list = d->dict[0].second;
  ASSERT_EQ(list->kind, PyValue::List);
  ASSERT_EQ(list->items.size(), 2u);
  EXPECT_EQ(list->items[1]->i, 2);
  ASSERT_EQ(d->dict[1].second->kind, PyValue::Tuple);
  ASSERT_EQ(d->dict[1].second->items.size(), 1u);
  EXPECT_EQ(d->dict[1].second->items[0]->i, 3);
  EXPECT_EQ(d->dict[2].second, list) << "BINGET gives the memoized value itself";
  EXPECT_EQ(d->dict[3].second->kind, PyValue::Tuple);
  EXPECT_TRUE(d->dict[3].second->items.empty());
}

TEST(PickleReader, ACycleThroughTheMemoIsBuiltAndFreed) {
  // l = []; l.append(l), through BINPUT and BINGET; and (l, l, l) through TUPLE3 and 'l' lists.
  Pickled p(kProto2 + "]q\x00h\x00"s + "a(h\x00lh\x00h\x00\x87."s);
  const PyPtr t = p.read();
  ASSERT_EQ(t->kind, PyValue::Tuple);
  ASSERT_EQ(t->items.size(), 3u);
  const PyPtr inner = t->items[0];
  ASSERT_EQ(inner->kind, PyValue::List);
  ASSERT_EQ(inner->items.size(), 1u);
  const PyPtr l = inner->items[0];
  ASSERT_EQ(l->items.size(), 1u);
  EXPECT_EQ(l->items[0], l);
  EXPECT_EQ(t->items[1], l);
}

TEST(PickleReader, KnownCallsBuildValuesAndOthersBecomeInertObjects) {
  // (OrderedDict(), restore_type_tag([7], 'List[int]'), Namespace() with state {'lr': 2})
  const std::string pkl = kProto2 + "(ccollections\nOrderedDict\n)R" +
                          "ctorch.jit._pickle\nrestore_type_tag\n]K\x07" + "a" + str("List[int]") +
                          "\x86R" + "cargparse\nNamespace\n)\x81}" + str("lr") + "K\x02sb" + "t.";
  Pickled p(pkl);
  const PyPtr t = p.read();
  ASSERT_EQ(t->items.size(), 3u);
  EXPECT_EQ(t->items[0]->kind, PyValue::Dict);
  ASSERT_EQ(t->items[1]->kind, PyValue::List);
  EXPECT_EQ(t->items[1]->items[0]->i, 7);
  const PyPtr ns = t->items[2];
  ASSERT_EQ(ns->kind, PyValue::Object);
  EXPECT_EQ(ns->s, "argparse.Namespace");
  ASSERT_EQ(ns->dict.size(), 1u);
  EXPECT_EQ(ns->dict[0].first->s, "lr");
  EXPECT_EQ(ns->dict[0].second->i, 2);
}

TEST(PickleReader, RebuildsTensorsFromTheirStorageRecords) {
  const float values[4] = {1, 2, 3, 4};
  const std::map<std::string, std::string> storage = {
      {"0", std::string(reinterpret_cast<const char*>(values), 16)}};
  // (a view of 3 from offset 1, the same storage read again as a 2x2 matrix, an empty view)
  Pickled p(kProto2 + "(" + tensor("0", 4, 1, {3}, {1}) + tensor("0", 4, 0, {2, 2}, {2, 1}) +
                tensor("0", 4, 0, {0}, {1}) + "t.",
            storage);
  const PyPtr t = p.read();
  ASSERT_EQ(t->items.size(), 3u);
  for (const PyPtr& v : t->items) ASSERT_EQ(v->kind, PyValue::Tensor);
  EXPECT_TRUE(torch::equal(t->items[0]->tensor, torch::tensor({2.0f, 3.0f, 4.0f})));
  EXPECT_TRUE(
      torch::equal(t->items[1]->tensor, torch::tensor({1.0f, 2.0f, 3.0f, 4.0f}).view({2, 2})));
  EXPECT_EQ(t->items[2]->tensor.numel(), 0);
  // _rebuild_parameter(tensor, requires_grad, hooks) is the tensor.
  Pickled param(
      kProto2 + "ctorch._utils\n_rebuild_parameter\n(" + tensor("0", 4, 0, {4}, {1}) + "\x88)tR.",
      storage);
  const PyPtr w = param.read();
  ASSERT_EQ(w->kind, PyValue::Tensor);
  EXPECT_TRUE(torch::equal(w->tensor, torch::tensor({1.0f, 2.0f, 3.0f, 4.0f})));
}

TEST(PickleReader, RefusesGlobalsThatNameCode) {
  // pickle.dumps of a __reduce__ returning (os.system, ("echo pwned",)).
  EXPECT_EQ(refusal(kProto2 + "cos\nsystem\nq\x01" + str("echo pwned") + "\x85q\x02R."),
            "test.pkl: cannot read checkpoint (data.pkl at byte 13): refusing global 'os.system' "
            "(GLOBAL opcode): a checkpoint holds only tensors and plain values, never code");
  std::string why = refusal("\x80\x04" + shortStr("builtins") + shortStr("eval") + "\x93" +
                            shortStr("1") + "\x85R.");
  EXPECT_NE(why.find("refusing global 'builtins.eval' (STACK_GLOBAL opcode)"), std::string::npos)
      << why;
  // The globals allowed by prefix stop at the prefix: torch.*Storage names a storage type only
  // directly under torch.
  why = refusal(kProto2 + "ctorch.nn\nEvilStorage\n.");
  EXPECT_NE(why.find("refusing global 'torch.nn.EvilStorage'"), std::string::npos) << why;
  why = refusal(kProto2 + "cposix\nsystem\n.");
  EXPECT_NE(why.find("refusing global 'posix.system'"), std::string::npos) << why;
}

TEST(PickleReader, RefusesOpcodesItDoesNotSupport) {
  // INST, OBJ and PERSID run or name code by text; EXT1 names a registered global.
  EXPECT_EQ(
      refusal(kProto2 + "ios\nsystem\n."),
      "test.pkl: cannot read checkpoint (data.pkl at byte 3): unsupported pickle opcode 0x69");
  EXPECT_NE(refusal(kProto2 + "(o.").find("unsupported pickle opcode 0x6f"), std::string::npos);
  EXPECT_NE(refusal(kProto2 + "P0\n.").find("unsupported pickle opcode 0x50"), std::string::npos);
  EXPECT_NE(refusal(kProto2 + "\x82\x01.").find("unsupported pickle opcode 0x82"),
            std::string::npos);
}

TEST(PickleReader, RefusesMalformedPickles) {
  const std::pair<std::string, std::string> cases[] = {
      {kProto2 + "N", "data.pkl ends before STOP"},
      {kProto2 + "X\xff\xff\xff\x00"s + "ab.", "length beyond the end"},
      {kProto2 + "K", "unexpected end"},
      {kProto2 + "a.", "stack underflow"},
      {kProto2 + "N\x87.", "stack underflow"},
      {kProto2 + "t.", "no MARK"},
      {kProto2 + "NNa.", "unexpected value type"},
      {kProto2 + "}(Nu.", "SETITEMS with an odd count"},
      {kProto2 + "]NNs.", "SETITEM on a non-dict"},
      {kProto2 + "h\x05.", "memo key not found"},
      {kProto2 + "\x8a\x09", "integer too large"},
      {kProto2 + "cos", "unterminated GLOBAL"},
      {kProto2 + "K\x01K\x02\x93.", "STACK_GLOBAL of a non-string"},
      {kProto2 + "K\x01)R.", "REDUCE of a non-global"},
      {kProto2 + "(" + str("storage") + "ctorch\nEvilStorage\n" + str("0") + str("cpu") + i64(1) +
           "tQ.",
       "unsupported storage type torch.EvilStorage"},
      {kProto2 + "(" + str("other") + "tQ.", "unsupported persistent id"},
      {kProto2 + tensor("9", 1, 0, {1}, {1}) + ".", "missing storage record 'data/9'"},
  };
  for (const auto& [pkl, reason] : cases) {
    const std::string why = refusal(pkl);
    EXPECT_EQ(why.rfind("test.pkl: ", 0), 0u) << why;
    EXPECT_NE(why.find(reason), std::string::npos) << reason << ": " << why;
  }
}

}  // namespace
}  // namespace paircast
