// Ray queries against the input geometry with Embree 3 (docs/design/architecture.md).
//
// The Embree scene holds one quad per MeshFace, in the mesh's recentred coordinates, converted to
// float only after recentring in double. Hits report (face, u, v) in the parameterisation of
// mesh.h, which is Embree's own quad parameterisation.
//
// One Embree device serves the whole process: created on first use (thread-safely), never
// released. Embree reports an error to the device's error callback on the thread whose API call
// failed (errors of build tasks reach the thread that called rtcCommitScene); every call made for
// a Visibility marks that thread as working for it, so the callback hands the error to that
// Visibility, which reports it through status(), never by aborting.
#ifndef RADIOSITY_SOLVER_TRANSPORT_VISIBILITY_H_
#define RADIOSITY_SOLVER_TRANSPORT_VISIBILITY_H_

#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/vec.h"
#include "solver/util/progress.h"
#include "solver/util/stop.h"

// oneTBB's task_arena (oneapi/tbb/task_arena.h declares it so), without including TBB here.
namespace tbb {
namespace detail::d1 {
class task_arena;
}  // namespace detail::d1
inline namespace v1 {
using detail::d1::task_arena;
}  // namespace v1
}  // namespace tbb

namespace radiosity {

struct Hit {
  int face = -1;  // -1: the ray escaped.
  float u = 0, v = 0;
  float t = 0;
  // The hit half's front normal, not normalised (Embree's geometry normal: the front is the
  // counter-clockwise side, as the mesh's normals): Dot(dir, ng) < 0 means the ray strikes the
  // front, without reading the face.
  float ng[3] = {0, 0, 0};
  bool valid() const { return face >= 0; }
  bool StrikesFront(const Vec3& dir) const {
    return dir.x * ng[0] + dir.y * ng[1] + dir.z * ng[2] < 0;
  }
};

class Visibility {
 public:
  // Builds the acceleration structure over mesh.faces(). With `arena`, the build's parallel work
  // runs in that arena (the commit is made inside arena->execute), so a job's thread count holds
  // for it too; without, in the calling thread's arena. With `stop`, Embree's build progress
  // callback checks it and a stop cancels the build (StopStatus: CANCELLED or DEADLINE_EXCEEDED).
  // `progress` hears Embree's fraction built in steps of at least 1 %, and 1 when it is done.
  static absl::StatusOr<std::unique_ptr<Visibility>> Build(const Mesh& mesh,
                                                           tbb::task_arena* arena = nullptr,
                                                           const StopToken* stop = nullptr,
                                                           const ProgressCallback& progress = {});
  ~Visibility();
  Visibility(const Visibility&) = delete;
  Visibility& operator=(const Visibility&) = delete;

  // Closest hit along origin + t dir for t in [tnear, tfar], never on face `ignore` (the face a
  // ray leaves from: skipping it, rather than offsetting the origin, keeps rays that start at a
  // corner from slipping past the wall beside them), nor on a face parallel to it where the hit
  // lies within epsilon() of the plane through the origin parallel to it (for a ray leaving the
  // face: a coplanar neighbour, which the origin rounded to float can land on at a shared edge),
  // nor on the back of a face within epsilon() of the origin that lies on the other side of the
  // ignored face's plane than the ray goes (the face beyond a convex edge, which the rounded
  // origin can land on likewise; a face on the ray's side is hit) or whose plane the origin, in
  // double, is not behind (the wall at a concave edge, the ray leaving away from its front).
  // Thread-safe. Coordinates are the mesh's recentred ones; dir need not be normalised (t is in
  // units of |dir|).
  Hit Intersect(const Vec3& origin, const Vec3& dir, double tnear, double tfar,
                int ignore = -1) const;
  // Whether anything other than face `ignore` (and its coplanar neighbours, as for Intersect)
  // blocks the segment [tnear, tfar]. Thread-safe.
  bool Occluded(const Vec3& origin, const Vec3& dir, double tnear, double tfar,
                int ignore = -1) const;

  // OK unless Embree reported an error for a call made by this Visibility since Build (then the
  // first one, as INTERNAL).
  absl::Status status() const;

  // For tests of the error routing: makes one Embree call for this Visibility that fails (a
  // geometry of no known type, on the process's device), as a failing build or trace would.
  void FailAnEmbreeCallForTesting() const;

  // A length below which self-intersection is avoided: 1e-6 of the scene diagonal.
  double epsilon() const { return epsilon_; }

 private:
  Visibility() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  double epsilon_ = 0;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_VISIBILITY_H_
