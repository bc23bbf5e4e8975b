// libFuzzer target: EXR depth members through OpenEXR's C library (util/exr_codec.h) and
// decodeImageF (util/image_io.h). Only our code is instrumented: OpenEXR and OpenImageIO are the
// prebuilt Debian libraries, so coverage counts our side of them.
#include "fuzz/util_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  paircast::fuzz::runExrInput({reinterpret_cast<const char*>(data), size});
  return 0;
}
