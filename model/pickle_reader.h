// A value-only pickle reader for the data.pkl of checkpoints that Python's torch.save writes
// (LibTorch 1.13's own unpickler turns their collections.OrderedDict state_dicts into None). It
// builds values (dicts, lists, tuples, numbers, strings, tensors) and never runs code: a global
// that names code (os.system, builtins.eval) is refused, and a class it does not know becomes an
// inert placeholder holding its state. What a pickle may build is bounded (values, tensor views
// and bytes), so a small hostile file cannot exhaust memory.
#pragma once

#include <torch/torch.h>

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace caffe2::serialize {
class PyTorchStreamReader;
}

namespace paircast {

// Values point at each other with plain pointers and all live in the reader's arena until the
// reader goes, so a pickle that builds a cycle (a list appended to itself through the memo) or a
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

class PickleReader {
 public:
  // Reads the pickle `data`, whose tensors' storages are the records `prefix` + "data/<key>" of
  // `zip`. `source` names the file in errors; `archiveBytes` (the checkpoint's size) bounds the
  // bytes of the tensors built. `data` and `zip` must outlive the reader.
  PickleReader(const std::string& data, caffe2::serialize::PyTorchStreamReader& zip,
               const std::string& prefix, const std::string& source, uint64_t archiveBytes);
  ~PickleReader();
  PickleReader(const PickleReader&) = delete;
  PickleReader& operator=(const PickleReader&) = delete;

  // The value the pickle builds, valid while the reader lives. Throws paircast::Error naming
  // `source` and the byte at fault, for a malformed pickle, an opcode the reader does not support,
  // a global outside those a checkpoint names, or values over the limits; the zip reader's own
  // exceptions (a damaged storage record) pass through.
  PyPtr read();

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace paircast
