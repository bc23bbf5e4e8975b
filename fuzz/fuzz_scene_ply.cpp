// libFuzzer target: .ply scene files through loadScene (render/scene_loader.h).
#include "fuzz/render_inputs.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  paircast::fuzz::runSceneInput({reinterpret_cast<const char*>(data), size}, ".ply");
  return 0;
}
