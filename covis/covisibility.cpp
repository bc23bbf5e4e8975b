#include "covis/covisibility.h"

#include <algorithm>
#include <cmath>

#include "covis/unproject.h"
#include "util/error.h"
#include "util/simd.h"

// With GCC or Clang on x86-64 the kernel is also compiled for AVX-512 and AVX2 (16 and 8 lanes
// against SSE2's 4, and hardware gathers): PAIRCAST_CLONES in util/simd.h. Measured side by side
// on 256x256 pairs: docs/covis.md.

namespace paircast {
namespace {

// Points nearer than this to camera j's plane (metres) count as behind it.
constexpr float kMinDepth = 1e-6f;
// Pixels per chunk of a row: the projection pass runs over fixed-size stack arrays, so the
// compiler vectorises it, and the lookup pass that follows is a short gather. A 256-pixel row
// is one chunk; smaller chunks measured no faster.
constexpr int kChunk = 256;

// The kernel: counts over the sampled pixels of i. `m` maps (u, v, z) of i to homogeneous pixel
// coordinates of j.
// Without j's depth (depthJ null: a Wj x Hj frame), the depth test is left out and the count is
// of pixels inside j's frame and in front of it.
PAIRCAST_CLONES VisibleCount countVisibleKernel(const PixelDepthMap& m, const ImageF& depthI,
                                                const ImageF* depthJ, int Wj, int Hj, float absTol,
                                                float relTol, int stride, uint8_t* mask) {
  const int Wi = depthI.width, Hi = depthI.height;
  const float maxX = static_cast<float>(Wj), maxY = static_cast<float>(Hj);
  const float lastX = maxX - 1.0f, lastY = maxY - 1.0f;
  const float* dj = depthJ ? depthJ->data.data() : nullptr;
  const float ax = m.A(0, 0), ay = m.A(1, 0), az = m.A(2, 0);  // d q / d(z u)
  const float bx = m.b.x(), by = m.b.y(), bz = m.b.z();
  VisibleCount count;
  alignas(32) float z[kChunk], qz[kChunk];  // [chunk]
  alignas(32) int32_t index[kChunk], ok[kChunk], valid[kChunk];
  for (int v = 0; v < Hi; v += stride) {
    const float* row = depthI.data.data() + static_cast<size_t>(v) * Wi;
    // A (0, v, 1): the part of A (u, v, 1) that is constant along the row.
    const float rx = m.A(0, 1) * v + m.A(0, 2), ry = m.A(1, 1) * v + m.A(1, 2),
                rz = m.A(2, 1) * v + m.A(2, 2);
    for (int u0 = 0; u0 < Wi; u0 += kChunk * stride) {
      const int n = std::min(kChunk, (Wi - u0 + stride - 1) / stride);
      for (int k = 0; k < n; ++k) z[k] = row[u0 + k * stride];
      // Projection pass: branch-free, so that it vectorises. Rejected lanes are clamped into
      // the frame and masked out in the lookup pass.
      for (int k = 0; k < n; ++k) {
        const float u = static_cast<float>(u0 + k * stride), d = z[k];
        const float px = d * (rx + u * ax) + bx, py = d * (ry + u * ay) + by,
                    pz = d * (rz + u * az) + bz;
        const float inv = 1.0f / pz;
        const float x = px * inv, y = py * inv;
        const int32_t good = validDepth(d);
        ok[k] = good & (pz > kMinDepth) & (x >= 0.0f) & (x < maxX) & (y >= 0.0f) & (y < maxY);
        // NaN goes to 0 and inf to the last pixel, so the conversion to int is defined.
        const float xc = std::min(x > 0.0f ? x : 0.0f, lastX);
        const float yc = std::min(y > 0.0f ? y : 0.0f, lastY);
        index[k] = static_cast<int32_t>(yc) * Wj + static_cast<int32_t>(xc);
        qz[k] = pz;
        valid[k] = good;
      }
      // Lookup pass: the depth test against j's nearest pixel.
      size_t visible = 0, nValid = 0;
      for (int k = 0; k < n; ++k) nValid += valid[k];
      if (!dj) {
        for (int k = 0; k < n; ++k) visible += ok[k] & 1;
      } else {
        for (int k = 0; k < n; ++k) {
          const float d = dj[index[k]];
          visible += ok[k] & validDepth(d) & (std::abs(qz[k] - d) <= absTol + relTol * d);
        }
      }
      // The mask repeats the test per lane; kept out of the loop above so that stays a plain
      // reduction.
      if (mask && dj) {
        uint8_t* out = mask + static_cast<size_t>(v) * Wi + u0;
        for (int k = 0; k < n; ++k) {
          const float d = dj[index[k]];
          const bool seen = ok[k] & validDepth(d) & (std::abs(qz[k] - d) <= absTol + relTol * d);
          out[k * stride] = seen ? 255 : 0;
        }
      }
      count.visible += visible;
      count.valid += nValid;
      count.total += n;
    }
  }
  return count;
}

double fraction(const VisibleCount& c, CovisOptions::Normalize normalize) {
  const size_t den = normalize == CovisOptions::Normalize::All ? c.total : c.valid;
  return den > 0 ? static_cast<double>(c.visible) / static_cast<double>(den) : 0.0;
}

void checkOptions(const CovisOptions& o) {
  if (o.stride < 1) throw Error("covis stride must be >= 1, got " + std::to_string(o.stride));
  if (!(o.absTol >= 0.0f && o.relTol >= 0.0f))
    throw Error("covis tolerances must be >= 0 (absTol " + std::to_string(o.absTol) + ", relTol " +
                std::to_string(o.relTol) + ")");
}

void checkInputs(const Camera& ci, const ImageF& depthI, const Camera& cj, const ImageF& depthJ,
                 const CovisOptions& o) {
  checkDepthMatches(ci, depthI);
  checkDepthMatches(cj, depthJ);
  checkOptions(o);
}
}  // namespace

VisibleCount countVisible(const Camera& ci, const ImageF& depthI, const Camera& cj,
                          const ImageF& depthJ, const CovisOptions& o) {
  checkInputs(ci, depthI, cj, depthJ, o);
  return countVisibleKernel(pixelFromPixelDepth(ci, cj), depthI, &depthJ, depthJ.width,
                            depthJ.height, o.absTol, o.relTol, o.stride, nullptr);
}

double inFrameFraction(const Camera& ci, const ImageF& depthI, const Camera& cj,
                       const CovisOptions& o) {
  checkDepthMatches(ci, depthI);
  PAIRCAST_CHECK(cj.width > 0 && cj.height > 0);
  checkOptions(o);
  return fraction(countVisibleKernel(pixelFromPixelDepth(ci, cj), depthI, nullptr, cj.width,
                                     cj.height, o.absTol, o.relTol, o.stride, nullptr),
                  o.normalize);
}

Image8 visibilityMask(const Camera& ci, const ImageF& depthI, const Camera& cj,
                      const ImageF& depthJ, const CovisOptions& options) {
  CovisOptions o = options;
  o.stride = 1;
  checkInputs(ci, depthI, cj, depthJ, o);
  Image8 mask(depthI.width, depthI.height, 1, 0);
  countVisibleKernel(pixelFromPixelDepth(ci, cj), depthI, &depthJ, depthJ.width, depthJ.height,
                     o.absTol, o.relTol, 1, mask.data.data());
  return mask;
}

double visibleFraction(const Camera& ci, const ImageF& depthI, const Camera& cj,
                       const ImageF& depthJ, const CovisOptions& o) {
  return fraction(countVisible(ci, depthI, cj, depthJ, o), o.normalize);
}

CovisResult computeCovisibility(const Camera& ci, const ImageF& depthI, const Camera& cj,
                                const ImageF& depthJ, const CovisOptions& o) {
  const VisibleCount ij = countVisible(ci, depthI, cj, depthJ, o);
  const VisibleCount ji = countVisible(cj, depthJ, ci, depthI, o);
  CovisResult r;
  r.valid_i = ij.total ? static_cast<double>(ij.valid) / ij.total : 0.0;
  r.valid_j = ji.total ? static_cast<double>(ji.valid) / ji.total : 0.0;
  r.v_ij = fraction(ij, o.normalize);
  r.v_ji = fraction(ji, o.normalize);
  r.covis = std::min(r.v_ij, r.v_ji);
  return r;
}

CovisOptions::Normalize parseCovisNormalize(const std::string& text) {
  if (text == "valid") return CovisOptions::Normalize::Valid;
  if (text == "all") return CovisOptions::Normalize::All;
  throw Error("covis normalisation must be 'valid' or 'all', got '" + text + "'");
}

const char* toString(CovisOptions::Normalize normalize) {
  return normalize == CovisOptions::Normalize::All ? "all" : "valid";
}

}  // namespace paircast
