// Fuzz entry points for util/'s decoders of shard members: .flo flow (util/flo_io.h) and EXR
// float maps, through OpenEXR's C library (util/exr_codec.h) where the build has it and through
// decodeImageF (util/image_io.h: OpenImageIO in the full build, the C library in the trainer-only
// one). See fuzz_inputs.h.
#pragma once

#include "fuzz/fuzz_inputs.h"
#include "util/exr_codec.h"
#include "util/flo_io.h"
#include "util/image_io.h"

namespace paircast::fuzz {

inline bool runFloInput(std::string_view bytes) {
  return acceptedOrRefused([&] { decodeFlo(bytes.data(), bytes.size(), "input.flo"); });
}

// True when every EXR decoder of the build accepts the bytes. PAIRCAST_HAVE_OPENEXR_CORE is set
// where paircast_util compiles exr_codec.cpp (fuzz/CMakeLists.txt, tests/CMakeLists.txt).
inline bool runExrInput(std::string_view bytes) {
  bool accepted = true;
#ifdef PAIRCAST_HAVE_OPENEXR_CORE
  accepted &= acceptedOrRefused([&] { decodeExrCore(bytes.data(), bytes.size(), "input.exr"); });
#endif
  accepted &= acceptedOrRefused([&] { decodeImageF(bytes.data(), bytes.size(), "input.exr"); });
  return accepted;
}

}  // namespace paircast::fuzz
