// The one place that knows which Embree paircast is built with. CMake sets PAIRCAST_EMBREE_MAJOR
// (3 or 4) from the installed package; everything else includes this header and calls Query.
//
// Embree 4 changed how a traversal is configured: Embree 3 passes an RTCIntersectContext (with
// the coherence flags) as the third argument of rtcIntersect8, Embree 4 takes the ray first and
// an optional RTCIntersectArguments last, whose flags carry the same hints. Scenes, geometries,
// buffers, the ray and hit structures and the error callback are the same in both.
#pragma once

#ifndef PAIRCAST_EMBREE_MAJOR
#error "PAIRCAST_EMBREE_MAJOR is set by CMake: link the paircast_embree target"
#endif

#if PAIRCAST_EMBREE_MAJOR >= 4
#include <embree4/rtcore.h>
#else
#include <embree3/rtcore.h>
#endif

namespace paircast::embree {

// How the rays of one query relate: coherent rays (neighbouring pixels of a large image) are
// traversed together; incoherent ones (Embree's default) one by one inside the packet.
enum class Rays { kCoherent, kIncoherent };

// The settings of a traversal, for any number of calls from one thread.
class Query {
 public:
  explicit Query(Rays rays = Rays::kIncoherent) {
    const bool coherent = rays == Rays::kCoherent;
#if PAIRCAST_EMBREE_MAJOR >= 4
    rtcInitIntersectArguments(&args_);
    args_.flags = coherent ? RTC_RAY_QUERY_FLAG_COHERENT : RTC_RAY_QUERY_FLAG_INCOHERENT;
    rtcInitOccludedArguments(&occludedArgs_);
    occludedArgs_.flags = args_.flags;
#else
    rtcInitIntersectContext(&context_);
    context_.flags =
        coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
#endif
  }

  // The closest hits of a packet of eight rays; valid[i] is -1 for the rays to trace, 0 else.
  void intersect8(const int* valid, RTCScene scene, RTCRayHit8& rayhit) {
#if PAIRCAST_EMBREE_MAJOR >= 4
    rtcIntersect8(valid, scene, &rayhit, &args_);
#else
    rtcIntersect8(valid, scene, &context_, &rayhit);
#endif
  }

  // The closest hit of one ray.
  void intersect1(RTCScene scene, RTCRayHit& rayhit) {
#if PAIRCAST_EMBREE_MAJOR >= 4
    rtcIntersect1(scene, &rayhit, &args_);
#else
    rtcIntersect1(scene, &context_, &rayhit);
#endif
  }

  // Whether anything lies on each ray of a packet of eight between tnear and tfar; valid[i] is
  // -1 for the rays to trace, 0 else. Embree sets a blocked ray's tfar to -inf.
  void occluded8(const int* valid, RTCScene scene, RTCRay8& ray) {
#if PAIRCAST_EMBREE_MAJOR >= 4
    rtcOccluded8(valid, scene, &ray, &occludedArgs_);
#else
    rtcOccluded8(valid, scene, &context_, &ray);
#endif
  }

  // Whether anything lies on the ray between tnear and tfar (any hit, no closest one: cheaper).
  bool occluded1(RTCScene scene, RTCRay& ray) {
#if PAIRCAST_EMBREE_MAJOR >= 4
    rtcOccluded1(scene, &ray, &occludedArgs_);
#else
    rtcOccluded1(scene, &context_, &ray);
#endif
    return ray.tfar < 0.0f;  // Embree sets it to -inf on a hit
  }

 private:
#if PAIRCAST_EMBREE_MAJOR >= 4
  RTCIntersectArguments args_;
  RTCOccludedArguments occludedArgs_;
#else
  RTCIntersectContext context_;
#endif
};

}  // namespace paircast::embree
