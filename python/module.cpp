// paircast._paircast: the renderer, co-visibility, live pair stream and shard reader for Python.
// Arrays leave C++ without a copy where C++ owns one buffer per array (the buffer moves into a
// capsule that numpy frees), and with one copy where views are stacked into [V, ...]. The GIL is
// released around loading, rendering, waiting for pairs and decoding.
//
// Legend: V views, H, W pixels.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <sys/mman.h>
#include <unistd.h>

#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <thread>

#include "covis/covisibility.h"
#include "dataset/pair_stream.h"
#include "dataset/shard.h"
#include "render/ray_caster.h"
#include "render/scene_loader.h"
#include "shard/shard_batches.h"
#include "shard/shard_set.h"
#include "util/error.h"
#include "util/flo_io.h"
#include "util/image_io.h"

namespace py = pybind11;

namespace paircast {
namespace {

// ---- Arrays -------------------------------------------------------------------------------------

// Hands `data` to numpy without a copy: the vector moves into a capsule that numpy frees.
template <typename T>
py::array_t<T> adopt(std::vector<T>&& data, std::vector<py::ssize_t> shape) {
  auto* owner = new std::vector<T>(std::move(data));
  py::capsule free(owner, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(std::move(shape), owner->data(), free);
}

// [H, W, C] as numpy; a 1-channel map drops the channel axis ([H, W]).
template <typename T>
py::array_t<T> adopt(Image<T>&& image) {
  std::vector<py::ssize_t> shape{image.height, image.width};
  if (image.channels != 1) shape.push_back(image.channels);
  return adopt(std::move(image.data), std::move(shape));
}

// Views of equal size stacked into [V, H, W(, C)]: the one copy of a multi-view array.
template <typename T>
py::array_t<T> stack(const std::vector<const Image<T>*>& views) {
  PAIRCAST_CHECK(!views.empty());
  const Image<T>& first = *views[0];
  std::vector<py::ssize_t> shape{static_cast<py::ssize_t>(views.size()), first.height, first.width};
  if (first.channels != 1) shape.push_back(first.channels);
  py::array_t<T> out(shape);
  T* dst = out.mutable_data();
  for (const Image<T>* v : views) {
    PAIRCAST_CHECK(v->size() == first.size());
    std::memcpy(dst, v->data.data(), v->size() * sizeof(T));
    dst += v->size();
  }
  return out;
}

// A float32 [H, W] (or [H, W, 1]) depth map from numpy, checked against its camera.
ImageF depthFromPy(const py::array& array, const Camera& camera, const std::string& name) {
  auto a = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(array);
  if (!a) throw Error(name, "depth is not a numeric array");
  const bool shapeOk = (a.ndim() == 2 || (a.ndim() == 3 && a.shape(2) == 1)) &&
                       a.shape(0) == camera.height && a.shape(1) == camera.width;
  if (!shapeOk)
    throw Error(name, "depth must be float32 [H, W] matching the camera (" +
                          std::to_string(camera.height) + " x " + std::to_string(camera.width) +
                          ")");
  ImageF depth(camera.width, camera.height, 1);
  std::memcpy(depth.data.data(), a.data(), depth.size() * sizeof(float));
  return depth;
}

// ---- Cameras ------------------------------------------------------------------------------------

// Python values (dicts, lists, tuples, numbers, numpy arrays and scalars) as JSON, so that a
// camera dict goes through the same cameraFromJson checks as render_view's camera files.
nlohmann::json toJson(py::handle h, const std::string& name) {
  if (h.is_none()) return nullptr;
  if (py::isinstance<py::bool_>(h)) return h.cast<bool>();
  if (py::isinstance<py::int_>(h)) return h.cast<int64_t>();
  if (py::isinstance<py::float_>(h)) return h.cast<double>();
  if (py::isinstance<py::str>(h)) return h.cast<std::string>();
  if (py::isinstance<py::dict>(h)) {
    nlohmann::json j = nlohmann::json::object();
    for (auto item : h.cast<py::dict>())
      j[py::str(item.first).cast<std::string>()] = toJson(item.second, name);
    return j;
  }
  if (py::isinstance<py::list>(h) || py::isinstance<py::tuple>(h)) {
    nlohmann::json j = nlohmann::json::array();
    for (auto item : h) j.push_back(toJson(item, name));
    return j;
  }
  if (py::hasattr(h, "tolist")) return toJson(h.attr("tolist")(), name);  // numpy
  throw Error(name, "unsupported value of type " +
                        py::str(h.get_type().attr("__name__")).cast<std::string>());
}

Camera cameraFromPy(py::handle h, const std::string& name) {
  return cameraFromJson(toJson(h, name), name);
}

py::array_t<double> matrixToPy(const Eigen::Matrix3d& m) {
  py::array_t<double> a({3, 3});
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) a.mutable_at(r, c) = m(r, c);
  return a;
}

// CroCo's keys, with numpy arrays: camera_intrinsics [3, 3], R_cam2world [3, 3], t_cam2world [3].
py::dict cameraToPy(const Camera& c) {
  py::dict d;
  d["camera_intrinsics"] = matrixToPy(c.K);
  d["R_cam2world"] = matrixToPy(c.R_cam2world);
  py::array_t<double> t(3);
  for (int i = 0; i < 3; ++i) t.mutable_at(i) = c.t_cam2world[i];
  d["t_cam2world"] = t;
  d["width"] = c.width;
  d["height"] = c.height;
  return d;
}

// ---- Samples ------------------------------------------------------------------------------------

// The one conversion of a PairSample to Python, shared by every sample source. `flows`, when
// given for every view, become "flows": float32 [V, H, W, 2], view k's flow into flowTarget(k).
py::dict sampleToDict(const PairSample& s, const std::vector<ImageF>& flows = {}) {
  const int V = s.views();
  PAIRCAST_CHECK(V >= 1 && s.rgb.size() == static_cast<size_t>(V) &&
                 s.covis.size() == static_cast<size_t>(V));
  std::vector<const Image8*> rgb;
  std::vector<const ImageF*> depth;
  py::list cameras;
  py::array_t<double> covis(V - 1);
  for (int k = 0; k < V; ++k) {
    rgb.push_back(&s.rgb[k]);
    if (k < static_cast<int>(s.depth.size()) && !s.depth[k].data.empty())
      depth.push_back(&s.depth[k]);
    cameras.append(cameraToPy(s.camera[k]));
    if (k > 0) covis.mutable_at(k - 1) = s.covis[k].covis;
  }
  py::dict d;
  d["images"] = stack(rgb);                                    // uint8 [V, H, W, 3]
  if (depth.size() == rgb.size()) d["depths"] = stack(depth);  // float32 [V, H, W]
  if (flows.size() == rgb.size()) {
    std::vector<const ImageF*> flow;
    for (const ImageF& f : flows) flow.push_back(&f);
    d["flows"] = stack(flow);
  }
  d["cameras"] = cameras;
  d["covis"] = covis;  // [V - 1]: covis of each view k >= 1 with view 0 (the reference)
  if (s.visibility.size() == static_cast<size_t>(V)) {
    // [V, V]: v_ij, the share of view i seen by view j; each view's valid fraction on the diagonal.
    py::array_t<double> visibility({V, V});
    for (int i = 0; i < V; ++i)
      for (int j = 0; j < V; ++j) visibility.mutable_at(i, j) = s.visibility[i].at(j);
    d["visibility"] = visibility;
  }
  d["scene"] = s.scene;
  d["index"] = s.index;
  d["seed"] = s.seed;
  return d;
}

// ---- Scenes -------------------------------------------------------------------------------------

// A loaded scene and its BVH; the caster refers to scene.mesh, so neither ever moves.
struct PyScene {
  Scene scene;
  std::unique_ptr<RayCaster> caster;
};

// A str or os.PathLike as a path.
std::string pathFromPy(py::handle h) {
  return py::module_::import("os").attr("fspath")(h).cast<std::string>();
}

// One path, or an iterable of them (scene files, folders, .txt lists).
std::vector<std::string> pathsFromPy(py::handle h) {
  if (py::isinstance<py::str>(h) || py::hasattr(h, "__fspath__")) return {pathFromPy(h)};
  std::vector<std::string> out;
  for (auto item : h) out.push_back(pathFromPy(item));
  return out;
}

std::unique_ptr<PyScene> loadPyScene(py::handle pathObject, const std::string& up, double scale) {
  const std::string path = pathFromPy(pathObject);
  LoadOptions options;
  options.up = parseUpAxis(up);
  options.scale = scale;
  if (!(scale > 0) || !std::isfinite(scale)) throw Error(path, "scale must be positive");
  auto s = std::make_unique<PyScene>();
  py::gil_scoped_release release;
  s->scene = loadScene(path, options);
  s->caster = std::make_unique<RayCaster>(s->scene.mesh);
  return s;
}

py::dict renderPy(const PyScene& s, py::handle cameraDict, bool rgb, bool depth, bool normals,
                  int supersample) {
  const Camera camera = cameraFromPy(cameraDict, "camera");
  if (supersample < 1 || supersample > 4) throw Error("supersample must be in 1..4");
  RenderOptions options;
  options.rgb = rgb;
  options.normals = normals;
  options.ids = false;
  options.supersample = supersample;
  Frame frame;
  {
    py::gil_scoped_release release;
    s.caster->render(camera, options, frame);
  }
  py::dict d;
  if (rgb) d["rgb"] = adopt(std::move(frame.rgb));              // uint8 [H, W, 3]
  if (depth) d["depth"] = adopt(std::move(frame.depth));        // float32 [H, W]
  if (normals) d["normals"] = adopt(std::move(frame.normals));  // float32 [H, W, 3]
  return d;
}

py::dict covisibilityPy(py::handle cam1, const py::array& depth1, py::handle cam2,
                        const py::array& depth2, double absTol, double relTol,
                        const std::string& normalize) {
  const Camera c1 = cameraFromPy(cam1, "cam1"), c2 = cameraFromPy(cam2, "cam2");
  const ImageF d1 = depthFromPy(depth1, c1, "depth1"), d2 = depthFromPy(depth2, c2, "depth2");
  CovisOptions options;
  options.absTol = static_cast<float>(absTol);
  options.relTol = static_cast<float>(relTol);
  options.normalize = parseCovisNormalize(normalize);
  CovisResult r;
  {
    py::gil_scoped_release release;
    r = computeCovisibility(c1, d1, c2, d2, options);
  }
  py::dict d;
  d["v12"] = r.v_ij;
  d["v21"] = r.v_ji;
  d["covis"] = r.covis;
  d["valid1"] = r.valid_i;
  d["valid2"] = r.valid_j;
  return d;
}

// ---- The live stream ----------------------------------------------------------------------------

class PyPairStream {
 public:
  PyPairStream(py::handle scenes, uint64_t seed, int resolution, double hfov, double minCovis,
               double maxCovis, int views, const std::string& up, double scale, int threads,
               int start, int step, uint64_t offset, size_t queue, bool flow)
      : flow_(flow) {
    // The pair options are checked by PairOptions::validate(), as generate_pairs' are; these
    // two are the binding's own.
    if (threads < 0) throw Error("threads must be >= 0 (0: one per core)");
    if (!(scale > 0) || !std::isfinite(scale)) throw Error("scale must be positive");
    PairStreamOptions o;
    o.scenes = pathsFromPy(scenes);
    o.load.up = parseUpAxis(up);
    o.load.scale = scale;
    o.pair.resolution = resolution;
    o.pair.hfov = hfov;
    o.pair.minCovis = minCovis;
    o.pair.maxCovis = maxCovis;
    o.pair.views = views;
    o.pair.validate();  // here, not per scene inside PairStream, where it would skip
    o.seed = seed;
    o.firstIndex = offset;
    o.threads = threads > 0 ? threads : static_cast<int>(std::thread::hardware_concurrency());
    o.queueCapacity = std::max<size_t>(1, queue);
    o.partIndex = start;
    o.partCount = step;
    py::gil_scoped_release release;
    stream_ = std::make_shared<PairStream>(o);
  }

  py::dict next() {
    // A local owner: close() from another thread must not free the stream under next().
    std::shared_ptr<PairStream> stream = stream_;
    if (!stream) throw py::stop_iteration();
    std::optional<PairSample> s;
    {
      py::gil_scoped_release release;
      s = stream->next();
    }
    if (!s) throw py::stop_iteration();
    std::vector<ImageF> flows;
    if (flow_) {
      py::gil_scoped_release release;
      flows = viewFlows(*s);
    }
    return sampleToDict(*s, flows);
  }

  void close() {
    std::shared_ptr<PairStream> stream = std::move(stream_);
    if (!stream) return;
    stream->stop();  // wakes a next() waiting in another thread
    py::gil_scoped_release release;
    stream.reset();  // joins the workers, unless a next() still holds it
  }

  size_t scenes() const { return stream_ ? stream_->usableScenes() : 0; }
  uint64_t position() const { return stream_ ? stream_->position() : 0; }

 private:
  bool flow_;
  std::shared_ptr<PairStream> stream_;
};

// ---- Shards -------------------------------------------------------------------------------------

// Each message as a Python RuntimeWarning.
void warnAll(const std::vector<std::string>& messages) {
  for (const auto& w : messages)
    if (PyErr_WarnEx(PyExc_RuntimeWarning, w.c_str(), 1) < 0) throw py::error_already_set();
}

// A shard read through ShardIndex on a background thread that decodes into a bounded queue, so
// that decoding overlaps the training step. Samples the index refuses become warnings; so does a
// damaged shard's tail, and a shard with nothing usable is an error.
class PyShardReader {
 public:
  struct Decoded {
    std::string key;
    SampleRecord record;
    std::vector<Image8> rgb;
    std::vector<ImageF> depth;
    std::vector<ImageF> flow;
  };

  PyShardReader(py::handle path, bool depth, size_t queue, bool flow)
      : path_(pathFromPy(path)), depth_(depth), flow_(flow), capacity_(std::max<size_t>(1, queue)) {
    thread_ = std::thread([this] { run(); });
  }
  ~PyShardReader() { close(); }

  // The next decoded sample as a dict, or StopIteration; rethrows the reader's error.
  py::dict next() {
    std::optional<Decoded> d;
    std::vector<std::string> warnings;
    std::exception_ptr error;
    {
      py::gil_scoped_release release;
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [&] { return !queue_.empty() || done_ || !warnings_.empty(); });
      warnings.swap(warnings_);
      if (!queue_.empty()) {
        d = std::move(queue_.front());
        queue_.pop_front();
        cv_.notify_all();
      } else if (done_) {
        error = error_;
        error_ = nullptr;
      }
    }
    warnAll(warnings);
    if (error) std::rethrow_exception(error);
    if (!d) {
      if (!warnings.empty()) return next();
      throw py::stop_iteration();
    }
    return toDict(std::move(*d));
  }

  void close() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) {
      py::gil_scoped_release release;
      thread_.join();
    }
  }

 private:
  struct Stopped {};

  void warn(const std::string& message) {
    std::lock_guard<std::mutex> lock(mu_);
    warnings_.push_back(message);
    cv_.notify_all();
  }

  Decoded decode(const ShardIndex& index, size_t i) {
    const IndexedSample& s = index[i];
    Decoded d{s.key, s.record, {}, {}, {}};
    for (int k = 0; k < s.record.views; ++k) {
      const std::string name = index.describe(i, MemberKind::kImage, k + 1);
      const Bytes jpeg = index.read(s.image[k]);
      // Every map is checked against its view's camera: a skip with a warning, not a failure
      // of the stack that puts a batch together.
      const Camera& camera = s.record.camera[k];
      auto expectCameraSize = [&](const auto& image, const std::string& member, int channels) {
        if (image.width != camera.width || image.height != camera.height ||
            image.channels != channels)
          throw Error(member, "is " + std::to_string(image.width) + "x" +
                                  std::to_string(image.height) + "x" +
                                  std::to_string(image.channels) + ", its camera " +
                                  std::to_string(camera.width) + "x" +
                                  std::to_string(camera.height) + "x" + std::to_string(channels));
      };
      d.rgb.push_back(decodeImage8(jpeg.data(), jpeg.size(), name));
      expectCameraSize(d.rgb.back(), name, 3);
      if (depth_ && !s.depth.empty()) {
        const std::string depthName = index.describe(i, MemberKind::kDepth, k + 1);
        const Bytes exr = index.read(s.depth[k]);
        d.depth.push_back(decodeImageF(exr.data(), exr.size(), depthName));
        expectCameraSize(d.depth.back(), depthName, 1);
      }
      if (flow_) {
        const std::string name = index.describe(i, MemberKind::kFlow, k + 1);
        const Bytes flo = index.read(s.flow[k]);
        d.flow.push_back(decodeFlo(flo.data(), flo.size(), name));
        expectCameraSize(d.flow.back(), name, 2);
      }
    }
    return d;
  }

  void run() {
    try {
      const ShardIndex index = ShardIndex::open(path_, [&](const std::string& m) { warn(m); });
      if (index.damaged() && index.size() == 0) throw Error(path_, index.damage());
      index.warnOfDamage([&](const std::string& m) { warn(m); });
      for (size_t i = 0; i < index.size() && flow_; ++i)
        if (index[i].flow.empty())
          throw Error(path_, "sample " + index[i].key +
                                 " has no flow (write it with generate_pairs --save-flow)");
      for (size_t i = 0; i < index.size(); ++i) {
        std::optional<Decoded> d;
        try {
          d = decode(index, i);
        } catch (const Error& e) {
          warn(std::string(e.what()) + ", skipped");
          continue;
        }
        std::unique_lock<std::mutex> lock(mu_);
        cv_.wait(lock, [&] { return stop_ || queue_.size() < capacity_; });
        if (stop_) throw Stopped{};
        queue_.push_back(std::move(*d));
        cv_.notify_all();
      }
    } catch (const Stopped&) {
    } catch (...) {
      std::lock_guard<std::mutex> lock(mu_);
      error_ = std::current_exception();
    }
    std::lock_guard<std::mutex> lock(mu_);
    done_ = true;
    cv_.notify_all();
  }

  // The record's schema as a PairSample, for sampleToDict.
  py::dict toDict(Decoded&& d) {
    const SampleRecord& r = d.record;
    const size_t V = static_cast<size_t>(r.views);
    PairSample s;
    s.scene = r.scene;
    s.index = r.index;
    s.seed = r.seed.value_or(0);
    s.camera = r.camera;
    s.rgb = std::move(d.rgb);
    if (d.depth.size() == V) s.depth = std::move(d.depth);
    s.covis.resize(V);
    s.covis[0].covis = 1.0;
    for (size_t k = 1; k < V; ++k)
      s.covis[k].covis = r.covisibilityRatios.size() == V ? r.covisibilityRatios[k]
                         : k == 1                         ? r.covis
                                                          : 0.0;
    s.visibility = r.pairwiseVisibility;
    py::dict out = sampleToDict(s, d.flow);
    out["key"] = d.key;
    return out;
  }

  std::string path_;
  bool depth_, flow_;
  size_t capacity_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Decoded> queue_;
  std::vector<std::string> warnings_;
  std::exception_ptr error_;
  bool stop_ = false, done_ = false;
  std::thread thread_;
};

// Several shards as one indexed list (ShardSet), for paircast.torch.ShardPairs: the sample's
// size and name for the caller's random draws, then each view's crop decoded straight into a
// numpy array, float32 normalised or uint8, [3, H, W], with the GIL released.
class PyShardSet {
 public:
  explicit PyShardSet(py::handle paths) {
    const std::vector<std::string> files = pathsFromPy(paths);
    std::vector<std::string> warnings;
    {
      py::gil_scoped_release release;
      set_ = ShardSet::open(files, [&](const std::string& m) { warnings.push_back(m); });
    }
    warnAll(warnings);
  }

  size_t size() const { return set_.size(); }
  const ShardSet& set() const { return set_; }

  // [(path, first sample, count)] of each shard, in order.
  py::list ranges() const {
    py::list out;
    for (const auto& r : set_.ranges()) out.append(py::make_tuple(r.path, r.first, r.count));
    return out;
  }

  // (key, scene, index, views, height, width) of sample i.
  py::tuple info(size_t i) const {
    check(i);
    const IndexedSample& s = set_[i];
    return py::make_tuple(s.key, s.record.scene, s.record.index, s.record.views,
                          s.record.camera[0].height, s.record.camera[0].width);
  }

  py::array decode(size_t i, int view, int top, int left, int height, int width,
                   const std::string& dtype) const {
    if (dtype != "float32" && dtype != "uint8")
      throw py::value_error("dtype must be 'float32' or 'uint8', not '" + dtype + "'");
    const CropBox box{top, left, height, width};
    const std::vector<py::ssize_t> shape{3, height, width};
    if (dtype == "uint8") {
      py::array_t<uint8_t> out(shape);
      decodeInto(i, view, box, PixelLayout::kUint8CHW, out.mutable_data());
      return std::move(out);
    }
    py::array_t<float> out(shape);
    decodeInto(i, view, box, PixelLayout::kNormalizedFloatCHW, out.mutable_data());
    return std::move(out);
  }

  // decode() into `out`, a writable C-contiguous array of shape [3, height, width] and the
  // dtype's type (a slot of a batch tensor): no array is allocated.
  void decodeIntoArray(size_t i, int view, int top, int left, py::array out) const {
    const bool isFloat = py::isinstance<py::array_t<float>>(out),
               isUint8 = py::isinstance<py::array_t<uint8_t>>(out);
    if ((!isFloat && !isUint8) || out.ndim() != 3 || out.shape(0) != 3 || !out.writeable() ||
        !(out.flags() & py::array::c_style))
      throw py::value_error("out must be a writable C-contiguous float32 or uint8 [3, H, W] array");
    const CropBox box{top, left, static_cast<int>(out.shape(1)), static_cast<int>(out.shape(2))};
    decodeInto(i, view, box, isFloat ? PixelLayout::kNormalizedFloatCHW : PixelLayout::kUint8CHW,
               out.mutable_data());
  }

 private:
  void check(size_t i) const {
    if (i >= set_.size())
      throw py::index_error("sample " + std::to_string(i) + " of " + std::to_string(set_.size()));
  }
  // The one path of decode() and decode_into(): sample, view and box checked, then the decode.
  void decodeInto(size_t i, int view, const CropBox& box, PixelLayout layout, void* out) const {
    check(i);
    if (view < 0 || view >= set_[i].record.views)
      throw py::index_error("view " + std::to_string(view) + " of a sample of " +
                            std::to_string(set_[i].record.views));
    if (box.height < 1 || box.width < 1) throw Error("the crop must be at least 1 x 1");
    py::gil_scoped_release release;
    set_.decodeView(i, view, box, layout, out);
  }

  ShardSet set_;
};

// ShardBatches (shard/shard_batches.h) for paircast.torch.ShardLoader: batches of pairs drawn and
// decoded by threads, with the GIL released, into the loader's own tensors (numpy views of
// them, kept alive here).
class PyShardBatches {
 public:
  // buffers: [(view1, view2)] numpy arrays, each C-contiguous [B, 3, H, W], float32 or uint8;
  // or [(view1, view2, flow1, valid1, pose)] with the ground truth ([B, 2, H, W] float32,
  // [B, H, W] bool, [B, 4, 4] float64).
  PyShardBatches(py::object shards, py::list buffers, std::vector<size_t> order, uint64_t seed,
                 uint64_t epoch, int threads, int prefetch, int keep, bool dropLast)
      : shards_(std::move(shards)), arrays_(buffers) {
    ShardBatches::Options o;
    o.threads = threads;
    o.prefetch = prefetch;
    o.keep = keep;
    o.dropLast = dropLast;
    o.seed = seed;
    o.epoch = epoch;
    std::vector<std::array<void*, 2>> pointers;
    std::vector<TruthBuffers> truth;
    bool first = true, isFloat = false;
    for (py::handle pair : buffers) {
      const auto views = pair.cast<py::tuple>();
      if ((views.size() != 2 && views.size() != 5) || (!first && (views.size() == 5) != o.flow))
        throw py::value_error(
            "the buffers are all (view1, view2), or all (view1, view2, flow1, valid1, pose)");
      o.flow = views.size() == 5;
      std::array<void*, 2> p{};
      for (int k = 0; k < 2; ++k) {
        auto a = views[k].cast<py::array>();
        const bool f = py::isinstance<py::array_t<float>>(a),
                   u = py::isinstance<py::array_t<uint8_t>>(a);
        if ((!f && !u) || a.ndim() != 4 || a.shape(1) != 3 || !a.writeable() ||
            !(a.flags() & py::array::c_style))
          throw py::value_error(
              "buffers must be writable C-contiguous [B, 3, H, W] float32 or uint8 arrays");
        if (first) {
          isFloat = f;
          o.batchSize = static_cast<int>(a.shape(0));
          o.height = static_cast<int>(a.shape(2));
          o.width = static_cast<int>(a.shape(3));
          first = false;
        } else if (f != isFloat || a.shape(0) != o.batchSize || a.shape(2) != o.height ||
                   a.shape(3) != o.width) {
          throw py::value_error("buffers must all have one shape and dtype");
        }
        p[k] = a.mutable_data();
      }
      pointers.push_back(p);
      if (o.flow) truth.push_back(truthBuffers(views, o));
    }
    o.layout = isFloat ? PixelLayout::kNormalizedFloatCHW : PixelLayout::kUint8CHW;
    const ShardSet& set = shards_.cast<const PyShardSet&>().set();
    batches_ = std::make_unique<ShardBatches>(set, std::move(order), o, std::move(pointers),
                                              std::move(truth));
  }

  // (buffer, size, [messages of the pairs skipped]), or None after the last batch.
  py::object next() {
    if (!batches_) throw Error("the loader's batches are closed");
    std::optional<ShardBatches::Batch> b;
    {
      py::gil_scoped_release release;
      b = batches_->next();
    }
    if (!b) return py::none();
    return py::make_tuple(b->buffer, b->size, b->skipped);
  }
  // The ground-truth arrays of a buffer (views[2:5]), checked against the images' shape.
  static TruthBuffers truthBuffers(const py::tuple& views, const ShardBatches::Options& o) {
    auto array = [&](int k, const std::vector<py::ssize_t>& shape, const char* what) {
      auto a = views[k].cast<py::array>();
      bool ok = a.ndim() == static_cast<py::ssize_t>(shape.size()) && a.writeable() &&
                (a.flags() & py::array::c_style);
      for (size_t d = 0; ok && d < shape.size(); ++d) ok = a.shape(d) == shape[d];
      if (!ok)
        throw py::value_error(std::string("the ground-truth buffers must be writable ") + what);
      return a;
    };
    const py::ssize_t B = o.batchSize, H = o.height, W = o.width;
    auto flow = array(2, {B, 2, H, W}, "C-contiguous [B, 2, H, W] float32 flows");
    auto valid = array(3, {B, H, W}, "C-contiguous [B, H, W] bool masks");
    auto pose = array(4, {B, 4, 4}, "C-contiguous [B, 4, 4] float64 poses");
    if (!py::isinstance<py::array_t<float>>(flow) || !py::isinstance<py::array_t<bool>>(valid) ||
        !py::isinstance<py::array_t<double>>(pose))
      throw py::value_error("the ground-truth buffers are float32, bool and float64");
    return {static_cast<float*>(flow.mutable_data()), static_cast<uint8_t*>(valid.mutable_data()),
            static_cast<double*>(pose.mutable_data())};
  }

  // Stops the threads (the loader's buffers may then go).
  void close() {
    py::gil_scoped_release release;
    batches_.reset();
  }

 private:
  py::object shards_;
  py::list arrays_;
  std::unique_ptr<ShardBatches> batches_;
};

// Faults in the pages of a fresh array in one call (MADV_POPULATE_WRITE, Linux 5.14), instead of
// one page fault at a time while a decoder writes it: a batch tensor in shared memory is tens of
// megabytes. False where the kernel does not offer it (nothing changes then).
bool prefaultPy(py::array array) {
  if (!array.writeable()) throw py::value_error("prefault needs a writable array");
#ifdef MADV_POPULATE_WRITE
  const uintptr_t page = static_cast<uintptr_t>(::sysconf(_SC_PAGESIZE));
  const uintptr_t begin = reinterpret_cast<uintptr_t>(array.mutable_data()) & ~(page - 1);
  const uintptr_t end = reinterpret_cast<uintptr_t>(array.mutable_data()) + array.nbytes();
  py::gil_scoped_release release;
  return ::madvise(reinterpret_cast<void*>(begin), end - begin, MADV_POPULATE_WRITE) == 0;
#else
  return false;
#endif
}

py::array_t<uint8_t> decodeImagePy(const py::bytes& data, const std::string& name) {
  const std::string_view bytes = data;
  Image8 image;
  {
    py::gil_scoped_release release;
    image = decodeImage8(bytes.data(), bytes.size(), name, 3);
  }
  return adopt(std::move(image));
}

// uint8 [H, W, 3] (or [H, W] gray) to PNG or JPEG bytes, with the encoder generate_pairs uses.
py::bytes encodeImagePy(const py::array& array, const std::string& format, int quality) {
  auto a = py::array_t<uint8_t, py::array::c_style>::ensure(array);
  if (!a || a.dtype().kind() != 'u' || !(a.ndim() == 2 || (a.ndim() == 3 && a.shape(2) == 3)))
    throw Error("image must be uint8 [H, W, 3] or [H, W]");
  if (quality < 1 || quality > 100) throw Error("quality must be in 1..100");
  Image8 image(static_cast<int>(a.shape(1)), static_cast<int>(a.shape(0)), a.ndim() == 3 ? 3 : 1);
  std::memcpy(image.data.data(), a.data(), image.size());
  std::vector<unsigned char> bytes;
  {
    py::gil_scoped_release release;
    bytes = encodeImage(image, format, quality);
  }
  return py::bytes(reinterpret_cast<const char*>(bytes.data()), bytes.size());
}

// A float image (EXR) held in bytes: [H, W] for one channel, else [H, W, C].
py::array_t<float> decodeExrPy(const py::bytes& data, const std::string& name) {
  const std::string_view bytes = data;
  ImageF image;
  {
    py::gil_scoped_release release;
    image = decodeImageF(bytes.data(), bytes.size(), name);
  }
  return adopt(std::move(image));
}

}  // namespace
}  // namespace paircast

PYBIND11_MODULE(_paircast, m) {
  using namespace paircast;
  m.doc() = "paircast: Embree rendering, co-visibility and live CroCo pairs";
  // Bad input (a missing scene, a bad camera, a corrupt shard): one line naming what is wrong.
  py::register_exception<Error>(m, "Error", PyExc_ValueError);

  py::class_<PyScene>(m, "Scene", "A mesh scene with its BVH, ready to render")
      .def_property_readonly("name", [](const PyScene& s) { return s.scene.name; })
      .def_property_readonly("path", [](const PyScene& s) { return s.scene.path; })
      .def_property_readonly("triangles",
                             [](const PyScene& s) { return s.scene.mesh.triangles.size(); })
      .def_property_readonly("warnings", [](const PyScene& s) { return s.scene.warnings; })
      .def("render", &renderPy, py::arg("camera"), py::arg("rgb") = true, py::arg("depth") = true,
           py::arg("normals") = false, py::arg("supersample") = 1,
           "Renders one view. camera: a dict with CroCo's keys (camera_intrinsics, R_cam2world, "
           "t_cam2world, width, height). Returns a dict of numpy arrays: rgb uint8 [H, W, 3], "
           "depth float32 [H, W] z-depth in scene units (0 on a miss), normals float32 [H, W, 3] "
           "(unit world-frame normals facing the camera, 0 on a miss).")
      .def("__repr__", [](const PyScene& s) {
        return "<paircast.Scene '" + s.scene.name + "', " +
               std::to_string(s.scene.mesh.triangles.size()) + " triangles>";
      });

  m.def("load_scene", &loadPyScene, py::arg("path"), py::arg("up") = "y", py::arg("scale") = 1.0,
        "Loads a mesh scene (glb, gltf, obj, ply, ...) and builds its BVH. up: 'y' or 'z'; "
        "scale multiplies positions (file units to metres).");

  m.def("covisibility", &covisibilityPy, py::arg("cam1"), py::arg("depth1"), py::arg("cam2"),
        py::arg("depth2"), py::arg("abs_tol") = 0.03, py::arg("rel_tol") = 0.03,
        py::arg("normalize") = "valid",
        "Co-visibility of two views from their z-depth maps (float32 [H, W], 0 on a miss), by "
        "reprojection. Returns v12 (share of view 1 seen by view 2), v21, covis = min(v12, v21), "
        "valid1, valid2.");

  py::class_<PyPairStream>(m, "PairStream",
                           "Pairs rendered live by worker threads, as generate_pairs makes them")
      .def(py::init<py::handle, uint64_t, int, double, double, double, int, const std::string&,
                    double, int, int, int, uint64_t, size_t, bool>(),
           py::arg("scenes"), py::arg("seed") = 0, py::arg("resolution") = 256,
           py::arg("hfov") = 60.0, py::arg("min_covis") = 0.5, py::arg("max_covis") = 1.0,
           py::arg("views") = 2, py::arg("up") = "y", py::arg("scale") = 1.0,
           py::arg("threads") = 0, py::arg("start") = 0, py::arg("step") = 1, py::arg("offset") = 0,
           py::arg("queue") = 16, py::arg("flow") = false)
      .def("__iter__", [](py::object self) { return self; })
      .def("__next__", &PyPairStream::next)
      .def("close", &PyPairStream::close)
      .def("__enter__", [](py::object self) { return self; })
      .def("__exit__", [](PyPairStream& s, py::args) { s.close(); })
      .def_property_readonly("scenes", &PyPairStream::scenes)
      .def_property_readonly("position", &PyPairStream::position);

  py::class_<PyShardReader>(m, "ShardReader", "The samples of one tar shard, decoded")
      .def(py::init<py::handle, bool, size_t, bool>(), py::arg("path"), py::arg("depth") = false,
           py::arg("queue") = 8, py::arg("flow") = false)
      .def("__iter__", [](py::object self) { return self; })
      .def("__next__", &PyShardReader::next)
      .def("close", &PyShardReader::close)
      .def("__enter__", [](py::object self) { return self; })
      .def("__exit__", [](PyShardReader& r, py::args) { r.close(); });

  py::class_<PyShardSet>(m, "ShardSet",
                         "Samples of several shards, indexed; views decoded straight into crops")
      .def(py::init<py::handle>(), py::arg("paths"))
      .def("__len__", &PyShardSet::size)
      .def("ranges", &PyShardSet::ranges, "[(path, first sample, count)] of each shard, in order")
      .def("info", &PyShardSet::info, py::arg("i"),
           "(key, scene, index, views, height, width) of sample i")
      .def("decode", &PyShardSet::decode, py::arg("i"), py::arg("view"), py::arg("top"),
           py::arg("left"), py::arg("height"), py::arg("width"), py::arg("dtype") = "float32",
           "The crop of view `view` (from 0) of sample i as [3, height, width]: float32 "
           "normalised with ImageNet's mean and std, or uint8. Only the crop is decoded.")
      .def("decode_into", &PyShardSet::decodeIntoArray, py::arg("i"), py::arg("view"),
           py::arg("top"), py::arg("left"), py::arg("out"),
           "decode() into `out`, a writable C-contiguous [3, height, width] float32 (normalised) "
           "or uint8 array, such as one slot of a batch tensor's numpy view.");

  py::class_<PyShardBatches>(m, "ShardBatches",
                             "Batches of pairs drawn as ShardPairs draws them and decoded by "
                             "threads into the caller's buffers (ShardLoader's engine)")
      .def(py::init<py::object, py::list, std::vector<size_t>, uint64_t, uint64_t, int, int, int,
                    bool>(),
           py::arg("shards"), py::arg("buffers"), py::arg("order"), py::arg("seed") = 0,
           py::arg("epoch") = 0, py::arg("threads") = 2, py::arg("prefetch") = 2,
           py::arg("keep") = 1, py::arg("drop_last") = false)
      .def("next", &PyShardBatches::next,
           "(buffer, size, messages of the pairs skipped), or None after the last batch")
      .def("close", &PyShardBatches::close);

  m.def("prefault", &prefaultPy, py::arg("array"),
        "Faults in a fresh array's pages in one call (Linux 5.14+); False where unavailable.");
  m.def("decode_image", &decodeImagePy, py::arg("data"), py::arg("name") = "image.jpg",
        "Decodes a PNG or JPEG held in bytes to uint8 [H, W, 3]; name picks the format.");
  m.def("encode_image", &encodeImagePy, py::arg("image"), py::arg("format") = "png",
        py::arg("quality") = 95,
        "Encodes uint8 [H, W, 3] as 'png' or 'jpg' bytes (generate_pairs' encoder; quality for "
        "JPEG).");
  m.def("decode_exr", &decodeExrPy, py::arg("data"), py::arg("name") = "image.exr",
        "Decodes an EXR held in bytes to float32 [H, W] (one channel) or [H, W, C].");
}
