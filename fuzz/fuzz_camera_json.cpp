// libFuzzer target: camera JSON through cameraFromJson (render/camera.h).
#include "fuzz/render_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  paircast::fuzz::runCameraJsonInput({reinterpret_cast<const char*>(data), size});
  return 0;
}
