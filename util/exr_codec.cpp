#include "util/exr_codec.h"

#include <openexr.h>

#include <algorithm>
#include <cstring>

#include "util/decode_limits.h"
#include "util/error.h"

namespace paircast {
namespace {

// The largest image read here: far beyond any camera (16,384 pixels a side), and 2^31 values.
constexpr int64_t kMaxExrSide = 1 << 16;
constexpr int kMaxExrChannels = 64;

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

// Where the pixels of a scanline part are: rows of `width` float32 pixels of `channels`
// interleaved, from row `top` of the file; `linesPerChunk` rows to a chunk.
struct Layout {
  int width = 0, height = 0, channels = 0, top = 0, linesPerChunk = 1;
  bool rgb = false;
};

// The two directions of OpenEXR's chunk pipeline, so that one loop serves both. `io` and `coding`
// name what failed in the messages.
struct Decoding {
  using Pipeline = exr_decode_pipeline_t;
  static constexpr const char* io = "read";
  static constexpr const char* coding = "decode";
  static exr_result_t chunk(exr_context_t c, int part, int y, exr_chunk_info_t* info) {
    return exr_read_scanline_chunk_info(c, part, y, info);
  }
  static exr_result_t start(exr_context_t c, int part, const exr_chunk_info_t* info, Pipeline* p) {
    return exr_decoding_initialize(c, part, info, p);
  }
  static exr_result_t update(exr_context_t c, int part, const exr_chunk_info_t* info, Pipeline* p) {
    return exr_decoding_update(c, part, info, p);
  }
  static exr_result_t routines(exr_context_t c, int part, Pipeline* p) {
    return exr_decoding_choose_default_routines(c, part, p);
  }
  static exr_result_t run(exr_context_t c, int part, Pipeline* p) {
    return exr_decoding_run(c, part, p);
  }
  static void destroy(exr_context_t c, Pipeline* p) { exr_decoding_destroy(c, p); }
  static void point(exr_coding_channel_info_t& ch, const float* first) {
    ch.decode_to_ptr = reinterpret_cast<uint8_t*>(const_cast<float*>(first));
  }
};

struct Encoding {
  using Pipeline = exr_encode_pipeline_t;
  static constexpr const char* io = "write";
  static constexpr const char* coding = "encode";
  static exr_result_t chunk(exr_context_t c, int part, int y, exr_chunk_info_t* info) {
    return exr_write_scanline_chunk_info(c, part, y, info);
  }
  static exr_result_t start(exr_context_t c, int part, const exr_chunk_info_t* info, Pipeline* p) {
    return exr_encoding_initialize(c, part, info, p);
  }
  static exr_result_t update(exr_context_t c, int part, const exr_chunk_info_t* info, Pipeline* p) {
    return exr_encoding_update(c, part, info, p);
  }
  static exr_result_t routines(exr_context_t c, int part, Pipeline* p) {
    return exr_encoding_choose_default_routines(c, part, p);
  }
  static exr_result_t run(exr_context_t c, int part, Pipeline* p) {
    return exr_encoding_run(c, part, p);
  }
  static void destroy(exr_context_t c, Pipeline* p) { exr_encoding_destroy(c, p); }
  static void point(exr_coding_channel_info_t& ch, const float* first) {
    ch.encode_from_ptr = reinterpret_cast<const uint8_t*>(first);
  }
};

// Lays each of the pipeline's channels out as float32 interleaved, rows from `rows`.
template <typename Coding>
void layOut(typename Coding::Pipeline& pipe, const float* rows, const Layout& l) {
  for (int c = 0; c < pipe.channel_count; ++c) {
    exr_coding_channel_info_t& ch = pipe.channels[c];
    Coding::point(ch, rows + slotOf(ch.channel_name, c, l.channels, l.rgb));
    ch.user_pixel_stride = static_cast<int32_t>(sizeof(float) * l.channels);
    ch.user_line_stride = static_cast<int32_t>(sizeof(float) * l.channels * l.width);
    ch.user_bytes_per_element = sizeof(float);
    ch.user_data_type = EXR_PIXEL_FLOAT;
  }
}

// Decodes every chunk of part `part` into `pixels`, or encodes `pixels` into it (its header
// written), as `l` lays them out.
template <typename Coding>
void codeChunks(exr_context_t c, int part, const Layout& l, const float* pixels,
                const std::string& name) {
  typename Coding::Pipeline pipe{};
  struct Destroy {
    exr_context_t c;
    typename Coding::Pipeline* p;
    ~Destroy() { Coding::destroy(c, p); }
  } destroy{c, &pipe};
  for (int y = 0; y < l.height; y += l.linesPerChunk) {
    exr_chunk_info_t chunk;
    check(Coding::chunk(c, part, l.top + y, &chunk), name, Coding::io);
    check(y == 0 ? Coding::start(c, part, &chunk, &pipe) : Coding::update(c, part, &chunk, &pipe),
          name, Coding::coding);
    layOut<Coding>(pipe, pixels + static_cast<size_t>(y) * l.width * l.channels, l);
    if (y == 0) check(Coding::routines(c, part, &pipe), name, Coding::coding);
    check(Coding::run(c, part, &pipe), name, Coding::coding);
  }
}

Layout readLayout(exr_context_t c, const std::string& name) {
  exr_storage_t storage;
  check(exr_get_storage(c, 0, &storage), name, "read");
  if (storage != EXR_STORAGE_SCANLINE)
    throw Error(name, "only scanline EXR images are read here (this one is tiled or deep)");
  exr_attr_box2i_t window;
  check(exr_get_data_window(c, 0, &window), name, "read");
  const exr_attr_chlist_t* list = nullptr;
  check(exr_get_channels(c, 0, &list), name, "read");
  // In 64 bits: a data window from INT_MIN to INT_MAX overflows an int.
  const int64_t width = int64_t(window.max.x) - window.min.x + 1;
  const int64_t height = int64_t(window.max.y) - window.min.y + 1;
  if (width <= 0 || height <= 0 || list->num_channels <= 0) throw Error(name, "empty EXR image");
  if (width > kMaxExrSide || height > kMaxExrSide || list->num_channels > kMaxExrChannels)
    throw Error(name, "EXR image too large: " + std::to_string(width) + "x" +
                          std::to_string(height) + "x" + std::to_string(list->num_channels));
  Layout l;
  l.width = static_cast<int>(width);
  l.height = static_cast<int>(height);
  l.top = window.min.y;
  l.channels = list->num_channels;
  l.rgb = isRgb(list);
  for (int i = 0; i < list->num_channels; ++i)
    if (list->entries[i].x_sampling != 1 || list->entries[i].y_sampling != 1)
      throw Error(name, "subsampled EXR channels are not read here");
  check(exr_get_scanlines_per_chunk(c, 0, &l.linesPerChunk), name, "read");
  return l;
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
  const Layout l = readLayout(ctx.c, name);
  // The header's size is checked against the file's before the image is allocated: no EXR
  // compression stores more than kMaxValuesPerByte values in one byte, so a short file that
  // claims a huge window is refused here instead of asking for gigabytes.
  const uint64_t values = uint64_t(l.width) * uint64_t(l.height) * uint64_t(l.channels);
  if (values > kMaxValuesPerByte * size)
    throw Error(name, "EXR header claims " + std::to_string(l.width) + "x" +
                          std::to_string(l.height) + "x" + std::to_string(l.channels) +
                          " values in a file of " + std::to_string(size) + " bytes");
  ImageF image;
  image.width = l.width;
  image.height = l.height;
  image.channels = l.channels;
  image.data.assign(static_cast<size_t>(l.width) * l.height * l.channels, 0.0f);
  codeChunks<Decoding>(ctx.c, 0, l, image.data.data(), name);
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
  Layout l;
  l.width = image.width;
  l.height = image.height;
  l.channels = image.channels;
  l.rgb = rgb;
  check(exr_get_scanlines_per_chunk(ctx.c, part, &l.linesPerChunk), name, "write");
  codeChunks<Encoding>(ctx.c, part, l, image.data.data(), name);
  check(exr_finish(&ctx.c), name, "write");  // writes the chunk offsets
  return bytes;
}

}  // namespace paircast
