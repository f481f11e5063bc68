#include "solver/transport/visibility.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "tbb/task_arena.h"

namespace radiosity {

namespace {

const char* ErrorName(RTCError code) {
  switch (code) {
    case RTC_ERROR_NONE:
      return "none";
    case RTC_ERROR_UNKNOWN:
      return "unknown";
    case RTC_ERROR_INVALID_ARGUMENT:
      return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION:
      return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY:
      return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU:
      return "unsupported CPU";
    case RTC_ERROR_CANCELLED:
      return "cancelled";
  }
  return "?";
}

// The owner of an Embree scene handle (as in Embree's tutorials/minimal).
struct SceneDeleter {
  void operator()(RTCScene s) const { rtcReleaseScene(s); }
};
using ScenePtr = std::unique_ptr<RTCSceneTy, SceneDeleter>;

// Where the Embree errors of one Visibility go.
struct ErrorSink {
  std::mutex mu;
  absl::Status error;  // The first error reported.

  void Report(RTCError code, const char* message) {
    std::lock_guard<std::mutex> lock(mu);
    if (error.ok()) {
      error = absl::InternalError(
          absl::StrCat("Embree error (", ErrorName(code), "): ", message ? message : ""));
    }
  }
  absl::Status Get() {
    std::lock_guard<std::mutex> lock(mu);
    return error;
  }
};

// The Visibility that the Embree calls of this thread are made for, if any.
thread_local ErrorSink* current_sink = nullptr;

// Marks the calling thread as working for `sink` while alive (nests).
class WorkingFor {
 public:
  explicit WorkingFor(ErrorSink* sink) : previous_(current_sink) { current_sink = sink; }
  ~WorkingFor() { current_sink = previous_; }
  WorkingFor(const WorkingFor&) = delete;
  WorkingFor& operator=(const WorkingFor&) = delete;

 private:
  ErrorSink* const previous_;
};

// Embree invokes this on the thread whose API call failed. An error of a call made for no
// Visibility has nobody to report to and is dropped.
void OnDeviceError(void* /*user*/, RTCError code, const char* message) {
  if (current_sink != nullptr) current_sink->Report(code, message);
}

struct ProcessDevice {
  RTCDevice device = nullptr;
  absl::Status status;  // Why there is no device.
};

// The process's one device. Created on first use (a function-local static: thread-safe) and
// never released, so that no thread still tracing at exit can outlive it.
const ProcessDevice& Device() {
  static const ProcessDevice* const device = [] {
    auto* d = new ProcessDevice;
    // threads=0: Embree sets no global thread limit; the caller's arena decides (Build).
    d->device = rtcNewDevice("threads=0");
    if (d->device == nullptr) {
      d->status = absl::InternalError(absl::StrCat("Embree could not create a device: ",
                                                   ErrorName(rtcGetDeviceError(nullptr))));
    } else {
      rtcSetDeviceErrorFunction(d->device, &OnDeviceError, nullptr);
    }
    return d;
  }();
  return *device;
}

// Mesh faces are traced as two Embree geometries: quads, and triangles (a triangle as a quad
// would cost two triangle tests). Embree's triangle (u, v) is the face's own on its one half:
// P = p0 + u (p1 - p0) + v (p2 - p0), as mesh.h's map for u + v <= 1 with p3 = p2.
constexpr unsigned kQuadGeometry = 0, kTriangleGeometry = 1;

// An intersect context that carries the face to ignore, as (geometry, primitive), its unit
// normal, and the height above its plane below which a hit on a face parallel to it is ignored
// too (Embree 3 context filter functions).
struct IgnoreContext {
  RTCIntersectContext context;
  unsigned geometry, primitive;
  float normal[3];
  float height;
  const int32_t* face_of[2];                // Mesh face of each primitive, per geometry.
  const std::array<float, 3>* centroid_of;  // Each mesh face's centroid.
  const std::array<double, 4>* plane_of;    // Each mesh face's plane: unit normal n, n . p.
  double origin[3];                         // The ray's origin before rounding to float.
};

// A ray leaves from a point of the ignored face, given in double and traced in float: at a shared
// edge the rounded origin can lie on the coplanar neighbour, which the ray then hits at t ~ 0 from
// behind (a ray lost; one in about 10^6 in a room of 2 000 tiles, which no longer closed). A face
// coplanar with the one a ray leaves cannot be seen from it (F = 0), so a hit on a face parallel
// to it, within `height` of its plane, is skipped as the face itself is. Likewise at a convex
// edge the rounded origin can lie on the face beyond the edge, which the ray then hits from
// behind at t ~ 0: a hit on the back of a face within `height` of the origin, when that face lies
// on the other side of the ignored face's plane than the ray goes (its centroid), is skipped. A
// face on the ray's side (a fin standing on the face, or the neighbour at a corner seen from
// inside a closed object) is hit however close to it the ray starts, but only from behind: at a
// concave edge (a floor tile against a wall) the origin a hair in front of the wall rounds onto
// its plane, and a ray leaving the floor away from the wall hit the wall's back at t = 0 (a ray
// lost in the 600-facet furnished room), so a back hit within `height` is skipped too when the
// origin, in double, is not behind the face's plane.
void IgnoreFilter(const RTCFilterFunctionNArguments* args) {
  const auto* ctx = reinterpret_cast<const IgnoreContext*>(args->context);
  const unsigned n = args->N;
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] == 0) continue;
    if (RTCHitN_primID(args->hit, n, i) == ctx->primitive &&
        RTCHitN_geomID(args->hit, n, i) == ctx->geometry) {
      args->valid[i] = 0;
      continue;
    }
    const float dx = RTCRayN_dir_x(args->ray, n, i), dy = RTCRayN_dir_y(args->ray, n, i),
                dz = RTCRayN_dir_z(args->ray, n, i), t = RTCRayN_tfar(args->ray, n, i);
    const float gx = RTCHitN_Ng_x(args->hit, n, i), gy = RTCHitN_Ng_y(args->hit, n, i),
                gz = RTCHitN_Ng_z(args->hit, n, i);
    const float up = dx * ctx->normal[0] + dy * ctx->normal[1] + dz * ctx->normal[2];
    // On the back (Hit::StrikesFront's convention), within `height` of the origin, and on the
    // far side of the ignored face's plane from where the ray goes.
    if (dx * gx + dy * gy + dz * gz > 0 &&
        t * t * (dx * dx + dy * dy + dz * dz) <= ctx->height * ctx->height) {
      const unsigned geometry = RTCHitN_geomID(args->hit, n, i);
      const unsigned primitive = RTCHitN_primID(args->hit, n, i);
      const std::array<float, 3>& c = ctx->centroid_of[ctx->face_of[geometry][primitive]];
      const float side = (c[0] - RTCRayN_org_x(args->ray, n, i)) * ctx->normal[0] +
                         (c[1] - RTCRayN_org_y(args->ray, n, i)) * ctx->normal[1] +
                         (c[2] - RTCRayN_org_z(args->ray, n, i)) * ctx->normal[2];
      const std::array<double, 4>& plane = ctx->plane_of[ctx->face_of[geometry][primitive]];
      const double ahead = ctx->origin[0] * plane[0] + ctx->origin[1] * plane[1] +
                           ctx->origin[2] * plane[2] - plane[3];
      if (side * up <= 0 || ahead >= 0) {
        args->valid[i] = 0;
        continue;
      }
    }
    const float along = gx * ctx->normal[0] + gy * ctx->normal[1] + gz * ctx->normal[2];
    if (along * along < (1 - 2e-6f) * (gx * gx + gy * gy + gz * gz)) continue;  // Not parallel.
    const float height = t * up;
    if (std::fabs(height) <= ctx->height) args->valid[i] = 0;
  }
}

}  // namespace

struct Visibility::Impl {
  ScenePtr scene;
  ErrorSink errors;
  // Mesh face of each primitive of the two geometries, and each face's (geometry, primitive).
  std::vector<int32_t> face_of[2];
  std::vector<uint32_t> primitive_of;
  std::vector<uint8_t> geometry_of;
  std::vector<std::array<float, 3>> normal_of;    // Each face's unit normal (area-weighted).
  std::vector<std::array<float, 3>> centroid_of;  // Each face's corners' mean.
  std::vector<std::array<double, 4>> plane_of;    // Each face's plane (IgnoreContext::plane_of).
  float coplanar_height = 0;                      // IgnoreContext::height: Visibility::epsilon().

  void InitContext(IgnoreContext* ctx, int ignore, const Vec3& origin) const {
    rtcInitIntersectContext(&ctx->context);
    ctx->geometry = ctx->primitive = RTC_INVALID_GEOMETRY_ID;
    if (ignore >= 0 && static_cast<size_t>(ignore) < primitive_of.size()) {
      ctx->geometry = geometry_of[ignore];
      ctx->primitive = primitive_of[ignore];
      for (int k = 0; k < 3; ++k) ctx->normal[k] = normal_of[ignore][k];
      ctx->height = coplanar_height;
      ctx->face_of[0] = face_of[0].data();
      ctx->face_of[1] = face_of[1].data();
      ctx->centroid_of = centroid_of.data();
      ctx->plane_of = plane_of.data();
      ctx->origin[0] = origin.x;
      ctx->origin[1] = origin.y;
      ctx->origin[2] = origin.z;
      ctx->context.filter = &IgnoreFilter;
    }
  }
};

absl::StatusOr<std::unique_ptr<Visibility>> Visibility::Build(const Mesh& mesh,
                                                              tbb::task_arena* arena,
                                                              const StopToken* stop,
                                                              const ProgressCallback& progress) {
  constexpr char kBuilding[] = "building the ray-tracing structure";
  const ProcessDevice& device = Device();
  if (device.device == nullptr) return device.status;
  std::unique_ptr<Visibility> vis(new Visibility());
  vis->impl_ = std::make_unique<Impl>();
  Impl& impl = *vis->impl_;
  ErrorSink* const errors = &impl.errors;
  WorkingFor working(errors);
  impl.scene.reset(rtcNewScene(device.device));
  if (!impl.scene) {
    absl::Status error = errors->Get();
    return error.ok() ? absl::InternalError("rtcNewScene failed") : error;
  }
  rtcSetSceneBuildQuality(impl.scene.get(), RTC_BUILD_QUALITY_HIGH);
  rtcSetSceneFlags(impl.scene.get(),
                   RTC_SCENE_FLAG_ROBUST | RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION);

  // Embree's build progress, which may come from several build threads at once.
  struct Monitor {
    const StopToken* stop;
    std::mutex mu;
    StepReporter reporter;
  } monitor{stop, {}, StepReporter(progress)};
  if (stop != nullptr || progress) {
    // Returning false cancels the build (RTC_ERROR_CANCELLED).
    rtcSetSceneProgressMonitorFunction(
        impl.scene.get(),
        [](void* data, double fraction) {
          auto* m = static_cast<Monitor*>(data);
          {
            std::lock_guard<std::mutex> lock(m->mu);
            m->reporter.Report(std::min(fraction, 0.99));  // 1 once the commit is done.
          }
          return m->stop == nullptr || !m->stop->ShouldStop();
        },
        &monitor);
  }

  const auto& faces = mesh.faces();
  impl.primitive_of.resize(faces.size());
  impl.geometry_of.resize(faces.size());
  impl.normal_of.resize(faces.size());
  impl.centroid_of.resize(faces.size());
  impl.plane_of.resize(faces.size());
  for (size_t f = 0; f < faces.size(); ++f) {
    const Vec3 normal = faces[f].Normal();
    impl.normal_of[f] = {static_cast<float>(normal.x), static_cast<float>(normal.y),
                         static_cast<float>(normal.z)};
    const auto& p = faces[f].p;
    const Vec3 centroid = (p[0] + p[1] + p[2] + p[3]) * 0.25;
    impl.centroid_of[f] = {static_cast<float>(centroid.x), static_cast<float>(centroid.y),
                           static_cast<float>(centroid.z)};
    impl.plane_of[f] = {normal.x, normal.y, normal.z, Dot(normal, centroid)};
    const unsigned g = faces[f].triangle ? kTriangleGeometry : kQuadGeometry;
    impl.geometry_of[f] = static_cast<uint8_t>(g);
    impl.primitive_of[f] = static_cast<uint32_t>(impl.face_of[g].size());
    impl.face_of[g].push_back(static_cast<int32_t>(f));
  }
  for (const unsigned g : {kQuadGeometry, kTriangleGeometry}) {
    const std::vector<int32_t>& members = impl.face_of[g];
    if (members.empty()) continue;
    const int corners = g == kQuadGeometry ? 4 : 3;
    RTCGeometry geom = rtcNewGeometry(
        device.device, g == kQuadGeometry ? RTC_GEOMETRY_TYPE_QUAD : RTC_GEOMETRY_TYPE_TRIANGLE);
    if (geom == nullptr) {
      absl::Status error = errors->Get();
      return error.ok() ? absl::InternalError("rtcNewGeometry failed") : error;
    }
    auto* vertices = static_cast<float*>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                3 * sizeof(float), corners * members.size()));
    auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, g == kQuadGeometry ? RTC_FORMAT_UINT4 : RTC_FORMAT_UINT3,
        corners * sizeof(unsigned), members.size()));
    if (vertices == nullptr || indices == nullptr) {
      rtcReleaseGeometry(geom);
      absl::Status error = errors->Get();
      return error.ok() ? absl::ResourceExhaustedError("Embree could not allocate buffers") : error;
    }
    // Coordinates were recentred in double precision by the mesh; only now do they become float.
    for (size_t i = 0; i < members.size(); ++i) {
      for (int k = 0; k < corners; ++k) {
        const Vec3& p = faces[members[i]].p[k];
        const size_t at = corners * i + k;
        vertices[3 * at + 0] = static_cast<float>(p.x);
        vertices[3 * at + 1] = static_cast<float>(p.y);
        vertices[3 * at + 2] = static_cast<float>(p.z);
        indices[at] = static_cast<unsigned>(at);
      }
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(impl.scene.get(), geom, g);
    rtcReleaseGeometry(geom);
  }
  // The BVH build: Embree runs its tasks in the arena of the thread that commits. The functor
  // may run on another thread of the arena (when the caller cannot join it), hence the mark.
  auto commit = [&] {
    WorkingFor in_arena(errors);
    rtcCommitScene(impl.scene.get());
  };
  if (arena != nullptr) {
    arena->execute(commit);
  } else {
    commit();
  }
  // The monitor lives on this stack: the scene must not call it again.
  rtcSetSceneProgressMonitorFunction(impl.scene.get(), nullptr, nullptr);
  // A stop makes Embree cancel the build (an error of its own): said as the stop it was.
  if (absl::Status st = StopStatus(stop, kBuilding); !st.ok()) return st;
  if (absl::Status error = errors->Get(); !error.ok()) return error;
  monitor.reporter.Report(1);
  vis->epsilon_ = 1e-6 * mesh.scale();
  impl.coplanar_height = static_cast<float>(vis->epsilon_);
  return vis;
}

Visibility::~Visibility() = default;

Hit Visibility::Intersect(const Vec3& origin, const Vec3& dir, double tnear, double tfar,
                          int ignore) const {
  IgnoreContext ctx;
  impl_->InitContext(&ctx, ignore, origin);
  RTCRayHit rh;
  rh.ray.org_x = static_cast<float>(origin.x);
  rh.ray.org_y = static_cast<float>(origin.y);
  rh.ray.org_z = static_cast<float>(origin.z);
  rh.ray.dir_x = static_cast<float>(dir.x);
  rh.ray.dir_y = static_cast<float>(dir.y);
  rh.ray.dir_z = static_cast<float>(dir.z);
  rh.ray.tnear = static_cast<float>(tnear);
  rh.ray.tfar = static_cast<float>(std::min<double>(tfar, std::numeric_limits<float>::max()));
  rh.ray.mask = 0xFFFFFFFF;
  rh.ray.time = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  {
    WorkingFor working(&impl_->errors);
    rtcIntersect1(impl_->scene.get(), &ctx.context, &rh);
  }
  Hit hit;
  if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
    hit.face = impl_->face_of[rh.hit.geomID][rh.hit.primID];
    hit.u = rh.hit.u;
    hit.v = rh.hit.v;
    hit.t = rh.ray.tfar;
    hit.ng[0] = rh.hit.Ng_x;
    hit.ng[1] = rh.hit.Ng_y;
    hit.ng[2] = rh.hit.Ng_z;
  }
  return hit;
}

bool Visibility::Occluded(const Vec3& origin, const Vec3& dir, double tnear, double tfar,
                          int ignore) const {
  IgnoreContext ctx;
  impl_->InitContext(&ctx, ignore, origin);
  RTCRay ray;
  ray.org_x = static_cast<float>(origin.x);
  ray.org_y = static_cast<float>(origin.y);
  ray.org_z = static_cast<float>(origin.z);
  ray.dir_x = static_cast<float>(dir.x);
  ray.dir_y = static_cast<float>(dir.y);
  ray.dir_z = static_cast<float>(dir.z);
  ray.tnear = static_cast<float>(tnear);
  ray.tfar = static_cast<float>(std::min<double>(tfar, std::numeric_limits<float>::max()));
  ray.mask = 0xFFFFFFFF;
  ray.time = 0;
  ray.flags = 0;
  {
    WorkingFor working(&impl_->errors);
    rtcOccluded1(impl_->scene.get(), &ctx.context, &ray);
  }
  // Embree sets tfar to -inf when the ray is blocked.
  return ray.tfar < 0;
}

absl::Status Visibility::status() const { return impl_->errors.Get(); }

void Visibility::FailAnEmbreeCallForTesting() const {
  WorkingFor working(&impl_->errors);
  // 127: within the enumeration's range of values, and no geometry type.
  RTCGeometry geom = rtcNewGeometry(Device().device, static_cast<RTCGeometryType>(127));
  if (geom != nullptr) rtcReleaseGeometry(geom);
}

}  // namespace radiosity
