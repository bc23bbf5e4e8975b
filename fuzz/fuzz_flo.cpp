// libFuzzer target: .flo flow members through decodeFlo (util/flo_io.h).
#include "fuzz/util_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  paircast::fuzz::runFloInput({reinterpret_cast<const char*>(data), size});
  return 0;
}
