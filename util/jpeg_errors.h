// libjpeg's error handling for our decoders and encoder (util/jpeg_decoder.cpp,
// util/jpeg_encoder.cpp, and util/image_io_jpeg.cpp in the trainer-only build). libjpeg reports
// errors through error_exit, which must not return: it longjmps back to the setjmp of the function
// that called libjpeg, where no C++ object with a destructor may be alive.
#pragma once

#include <csetjmp>
#include <cstdio>  // before jpeglib.h, which uses FILE

#include <jpeglib.h>

namespace paircast::jpeg {

struct ErrorManager {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

// error_exit: the message into ErrorManager::message, then the jump.
inline void onError(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  std::longjmp(err->jump, 1);
}

// emit_message for readers that refuse corrupt data: libjpeg's warnings (level < 0; a premature
// end fills the rest with grey) become errors, trace messages pass.
inline void onMessageStrict(j_common_ptr cinfo, int level) {
  if (level < 0) onError(cinfo);
}

// emit_message for readers that decode what they can: warnings are ignored.
inline void onMessageLenient(j_common_ptr, int) {}

// Points `cinfo`'s error manager at `err`, with `emit` for messages.
inline jpeg_error_mgr* install(ErrorManager& err, void (*emit)(j_common_ptr, int)) {
  jpeg_error_mgr* mgr = jpeg_std_error(&err.mgr);
  mgr->error_exit = onError;
  mgr->emit_message = emit;
  return mgr;
}

}  // namespace paircast::jpeg
