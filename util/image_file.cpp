// The parts of util/image_io.h that both backends share (image_io.cpp through OpenImageIO, and
// image_io_jpeg.cpp for the trainer-only build): they only need the backend's encodeImage.
#include <cctype>
#include <filesystem>

#include "util/atomic_file.h"
#include "util/error.h"
#include "util/image_io.h"

namespace paircast {

std::string lowerExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (auto& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext.empty() ? ext : ext.substr(1);
}

void writeImage(const std::string& path, const Image8& image, int jpegQuality) {
  const std::string ext = lowerExtension(path);
  if (ext != "png" && ext != "jpg" && ext != "jpeg")
    throw Error(path, "unsupported image extension (use .png, .jpg or .jpeg)");
  const auto bytes = encodeImage(image, ext, jpegQuality);
  writeFileAtomic(path,
                  std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

}  // namespace paircast
