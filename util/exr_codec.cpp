#include "util/exr_codec.h"

#include <openexr.h>

#include <algorithm>
#include <cstring>
#include <type_traits>
#include <utility>

#include "util/error.h"

namespace paircast {
namespace {

// OpenEXR reports through a C callback; its last message goes into the error we throw.
thread_local std::string exrMessage;

void recordError(exr_const_context_t, exr_result_t code, const char* message) {
  exrMessage = message ? message : exr_get_default_error_message(code);
}

void check(exr_result_t rc, const std::string& name, const char* what) {
  if (rc == EXR_ERR_SUCCESS) return;
  const std::string detail = exrMessage.empty() ? exr_get_default_error_message(rc) : exrMessage;
  exrMessage.clear();
  throw Error(name, std::string("cannot ") + what + " EXR: " + detail);
}

struct Memory {
  const unsigned char* data;
  size_t size;
};

int64_t readMemory(exr_const_context_t, void* user, void* buffer, uint64_t bytes, uint64_t offset,
                   exr_stream_error_func_ptr_t) {
  const auto* m = static_cast<const Memory*>(user);
  if (offset >= m->size) return 0;
  const uint64_t n = std::min<uint64_t>(bytes, m->size - offset);
  std::memcpy(buffer, m->data + offset, n);
  return static_cast<int64_t>(n);
}

int64_t sizeOfMemory(exr_const_context_t, void* user) {
  return static_cast<int64_t>(static_cast<const Memory*>(user)->size);
}

int64_t writeMemory(exr_const_context_t, void* user, const void* buffer, uint64_t bytes,
                    uint64_t offset, exr_stream_error_func_ptr_t) {
  auto* out = static_cast<std::vector<unsigned char>*>(user);
  if (offset + bytes > out->size()) out->resize(offset + bytes);
  std::memcpy(out->data() + offset, buffer, bytes);
  return static_cast<int64_t>(bytes);
}

// The context, finished on every path.
struct Context {
  exr_context_t c = nullptr;
  Context() = default;
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;
  ~Context() {
    if (c) exr_finish(&c);
  }
};

// Where channel `channelName` goes among `channels` interleaved ones: R, G, B in that order for
// an RGB image (the file keeps them sorted: B, G, R), the file's order otherwise.
int slotOf(const char* channelName, int fileIndex, int channels, bool rgb) {
  if (!rgb) return fileIndex;
  static const char* const order[] = {"R", "G", "B"};
  for (int k = 0; k < 3; ++k)
    if (std::strcmp(channelName, order[k]) == 0) return k;
  return fileIndex % channels;
}

bool isRgb(const exr_attr_chlist_t* list) {
  if (list->num_channels != 3) return false;
  for (int i = 0; i < 3; ++i) {
    const char* n = list->entries[i].name.str;
    if (std::strcmp(n, "R") && std::strcmp(n, "G") && std::strcmp(n, "B")) return false;
  }
  return true;
}

// Lays each of the pipeline's channels out as float32 interleaved over `channels`, rows of
// `width` pixels from `base`.
template <typename Pipeline>
void layOut(Pipeline& pipe, const float* base, int width, int channels, bool rgb) {
  for (int c = 0; c < pipe.channel_count; ++c) {
    exr_coding_channel_info_t& ch = pipe.channels[c];
    const float* first = base + slotOf(ch.channel_name, c, channels, rgb);
    if constexpr (std::is_same_v<Pipeline, exr_decode_pipeline_t>)
      ch.decode_to_ptr = reinterpret_cast<uint8_t*>(const_cast<float*>(first));
    else
      ch.encode_from_ptr = reinterpret_cast<const uint8_t*>(first);
    ch.user_pixel_stride = static_cast<int32_t>(sizeof(float) * channels);
    ch.user_line_stride = static_cast<int32_t>(sizeof(float) * channels * width);
    ch.user_bytes_per_element = sizeof(float);
    ch.user_data_type = EXR_PIXEL_FLOAT;
  }
}

struct DecodeHeader {
  int width = 0, height = 0, channels = 0, top = 0, linesPerChunk = 1;
  bool rgb = false;
};

DecodeHeader readHeader(exr_context_t c, const std::string& name) {
  int parts = 0;
  check(exr_get_count(c, &parts), name, "read");
  exr_storage_t storage;
  check(exr_get_storage(c, 0, &storage), name, "read");
  if (storage != EXR_STORAGE_SCANLINE)
    throw Error(name, "only scanline EXR images are read here (this one is tiled or deep)");
  exr_attr_box2i_t window;
  check(exr_get_data_window(c, 0, &window), name, "read");
  const exr_attr_chlist_t* list = nullptr;
  check(exr_get_channels(c, 0, &list), name, "read");
  DecodeHeader h;
  h.width = window.max.x - window.min.x + 1;
  h.height = window.max.y - window.min.y + 1;
  h.top = window.min.y;
  h.channels = list->num_channels;
  h.rgb = isRgb(list);
  for (int i = 0; i < list->num_channels; ++i)
    if (list->entries[i].x_sampling != 1 || list->entries[i].y_sampling != 1)
      throw Error(name, "subsampled EXR channels are not read here");
  if (h.width <= 0 || h.height <= 0 || h.channels <= 0) throw Error(name, "empty EXR image");
  check(exr_get_scanlines_per_chunk(c, 0, &h.linesPerChunk), name, "read");
  return h;
}

// Decodes every chunk into `image`, whose size `h` gives.
void decodeChunks(exr_context_t c, const DecodeHeader& h, ImageF& image, const std::string& name) {
  exr_decode_pipeline_t pipe = EXR_DECODE_PIPELINE_INITIALIZER;
  struct Destroy {
    exr_context_t c;
    exr_decode_pipeline_t* p;
    ~Destroy() { exr_decoding_destroy(c, p); }
  } destroy{c, &pipe};
  for (int y = 0; y < h.height; y += h.linesPerChunk) {
    exr_chunk_info_t chunk;
    check(exr_read_scanline_chunk_info(c, 0, h.top + y, &chunk), name, "read");
    if (y == 0)
      check(exr_decoding_initialize(c, 0, &chunk, &pipe), name, "decode");
    else
      check(exr_decoding_update(c, 0, &chunk, &pipe), name, "decode");
    layOut(pipe, image.data.data() + static_cast<size_t>(y) * h.width * h.channels, h.width,
           h.channels, h.rgb);
    if (y == 0) check(exr_decoding_choose_default_routines(c, 0, &pipe), name, "decode");
    check(exr_decoding_run(c, 0, &pipe), name, "decode");
  }
}

// Encodes `image` chunk by chunk into part `part`, whose header is written.
void encodeChunks(exr_context_t c, int part, const ImageF& image, const std::string& name) {
  int32_t lines = 1;
  check(exr_get_scanlines_per_chunk(c, part, &lines), name, "write");
  exr_encode_pipeline_t pipe = EXR_ENCODE_PIPELINE_INITIALIZER;
  struct Destroy {
    exr_context_t c;
    exr_encode_pipeline_t* p;
    ~Destroy() { exr_encoding_destroy(c, p); }
  } destroy{c, &pipe};
  for (int y = 0; y < image.height; y += lines) {
    exr_chunk_info_t chunk;
    check(exr_write_scanline_chunk_info(c, part, y, &chunk), name, "write");
    if (y == 0)
      check(exr_encoding_initialize(c, part, &chunk, &pipe), name, "encode");
    else
      check(exr_encoding_update(c, part, &chunk, &pipe), name, "encode");
    layOut(pipe, image.data.data() + static_cast<size_t>(y) * image.width * image.channels,
           image.width, image.channels, image.channels == 3);
    if (y == 0) check(exr_encoding_choose_default_routines(c, part, &pipe), name, "encode");
    check(exr_encoding_run(c, part, &pipe), name, "encode");
  }
}

}  // namespace

ImageF decodeExrCore(const void* data, size_t size, const std::string& name) {
  Memory memory{static_cast<const unsigned char*>(data), size};
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.user_data = &memory;
  init.read_fn = readMemory;
  init.size_fn = sizeOfMemory;
  init.error_handler_fn = recordError;
  exrMessage.clear();
  Context ctx;
  check(exr_start_read(&ctx.c, name.c_str(), &init), name, "read");
  const DecodeHeader h = readHeader(ctx.c, name);
  ImageF image;
  image.width = h.width;
  image.height = h.height;
  image.channels = h.channels;
  image.data.assign(static_cast<size_t>(h.width) * h.height * h.channels, 0.0f);

  decodeChunks(ctx.c, h, image, name);
  return image;
}

std::vector<unsigned char> encodeExrCore(const ImageF& image) {
  const std::string name = "image.exr";
  if (image.channels != 1 && image.channels != 3)
    throw Error(name,
                "EXR images here have 1 or 3 channels, not " + std::to_string(image.channels));
  std::vector<unsigned char> bytes;
  exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
  init.user_data = &bytes;
  init.write_fn = writeMemory;
  init.error_handler_fn = recordError;
  exrMessage.clear();
  Context ctx;
  check(exr_start_write(&ctx.c, name.c_str(), EXR_WRITE_FILE_DIRECTLY, &init), name, "write");
  int part = 0;
  check(exr_add_part(ctx.c, "main", EXR_STORAGE_SCANLINE, &part), name, "write");
  check(exr_initialize_required_attr_simple(ctx.c, part, image.width, image.height,
                                            EXR_COMPRESSION_ZIP),
        name, "write");
  const bool rgb = image.channels == 3;
  for (const char* channel :
       rgb ? std::vector<const char*>{"R", "G", "B"} : std::vector<const char*>{"Y"})
    check(exr_add_channel(ctx.c, part, channel, EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LINEAR, 1, 1),
          name, "write");
  check(exr_write_header(ctx.c), name, "write");
  encodeChunks(ctx.c, part, image, name);
  check(exr_finish(&ctx.c), name, "write");  // writes the chunk offsets
  return bytes;
}

}  // namespace paircast
