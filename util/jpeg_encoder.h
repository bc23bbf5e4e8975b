// JPEG encoding through libjpeg-turbo, for both builds: the bytes OpenImageIO's writer made (the
// same JFIF header, an empty Exif segment, libjpeg's default tables and 4:2:0 chroma), without
// its per-image plugin set-up, which cost a fifth of a 256x256 image's encoding.
#pragma once

#include <vector>

#include "util/image.h"

namespace paircast {

// 1 or 3 channels, quality 1..100. Throws Error (naming "image.jpg") when libjpeg fails.
std::vector<unsigned char> encodeJpeg(const Image8& image, int quality);

}  // namespace paircast
