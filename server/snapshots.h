// Snapshots of a running solve and their fan-out to watchers (WatchJob streams).
//
// A JobChannel holds only the newest snapshot of its job; each watcher registers a SnapshotSink
// and is handed every new snapshot as it is published. A sink keeps at most one snapshot waiting
// (the newest replaces an older one still waiting: latest wins), so a slow reader costs a bounded
// amount of memory however fast the solver publishes. Snapshots are immutable and shared.
#ifndef RADIOSITY_SERVER_SNAPSHOTS_H_
#define RADIOSITY_SERVER_SNAPSHOTS_H_

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "radiosity/v1/service.pb.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"

namespace radiosity::service {

// Packed radiosity, (2 e + side) x 3 + channel, counted in SnapshotBytesLive() while alive.
class FloatBlock {
 public:
  explicit FloatBlock(std::vector<float> data);
  ~FloatBlock();
  FloatBlock(const FloatBlock&) = delete;
  FloatBlock& operator=(const FloatBlock&) = delete;
  const std::vector<float>& data() const { return data_; }

 private:
  std::vector<float> data_;
};

// The radiosity of a solution as packed floats.
std::shared_ptr<const FloatBlock> PackRadiosity(const Solution& solution);
// Solution::std_error packed like PackRadiosity; null when the solution has none.
std::shared_ptr<const FloatBlock> PackStdError(const Solution& solution);

// The element geometry of one mesh version, ready to send: the MeshGeometry messages of its
// announcement (each below 1 MiB), counted in MeshBytesLive() while alive. Immutable and
// shared by the snapshots that refer to it and the watchers sending it.
class MeshAnnouncement {
 public:
  // `back_ranges`: [begin, end) pairs of the elements that have a back side, when known.
  explicit MeshAnnouncement(std::vector<v1::MeshGeometry> chunks,
                            std::shared_ptr<const std::vector<int64_t>> back_ranges = nullptr);
  ~MeshAnnouncement();
  MeshAnnouncement(const MeshAnnouncement&) = delete;
  MeshAnnouncement& operator=(const MeshAnnouncement&) = delete;
  int64_t version() const { return version_; }
  int64_t elements() const { return elements_; }
  const std::vector<v1::MeshGeometry>& chunks() const { return chunks_; }
  // The elements with a back side, as [begin, end) pairs; null when not known (a mesh read back
  // from its file, or more than kMaxBackRanges ranges).
  const std::shared_ptr<const std::vector<int64_t>>& back_ranges() const { return back_ranges_; }

 private:
  std::vector<v1::MeshGeometry> chunks_;
  std::shared_ptr<const std::vector<int64_t>> back_ranges_;
  int64_t version_ = 0, elements_ = 0, bytes_ = 0;
};
using MeshPtr = std::shared_ptr<const MeshAnnouncement>;

// Most elements in one MeshGeometry message: about 100 bytes each, so a message stays near
// 0.85 MiB with its share of the surface names (at most kMaxNameBytesPerMessage).
inline constexpr int64_t kMaxMeshElementsPerMessage = 8192;
// Most faces of agglomerated elements (MeshGeometry.member_faces, each with its 12
// member_corners: 52 bytes) in one message, unless one element holds more (it then goes alone,
// without member_corners).
inline constexpr int64_t kMaxMeshMemberFacesPerMessage = 16384;
// What a message's elements and member faces may take together (about 100 and 52 bytes each).
inline constexpr int64_t kMaxMeshBytesPerMessage = 900'000;
inline constexpr int64_t kMaxNameBytesPerMessage = 64 << 10;
// Most [begin, end) ranges of elements with a back side that a snapshot's first message carries
// (WatchJobResponse.back_ranges; 256 KiB at most beside the values).
inline constexpr int64_t kMaxBackRanges = 8192;

// The announcement of `mesh` (of `scene`) as version `version`.
MeshPtr PackMesh(const Scene& scene, const Mesh& mesh, int64_t version);

// The announcement as bytes (each message length-prefixed) for the results directory, and back.
std::string SerializeMesh(const MeshAnnouncement& mesh);
absl::StatusOr<MeshPtr> ParseMesh(const std::string& bytes);

struct Snapshot {
  int64_t sequence = 0;
  v1::JobState state = v1::JOB_STATE_UNSPECIFIED;
  v1::JobProgress progress;
  bool final = false;
  v1::JobError error;
  int64_t elements = 0;
  std::shared_ptr<const FloatBlock> radiosity;  // Null when there is none.
  // The standard errors of `radiosity`, same layout; null when the method gives none.
  std::shared_ptr<const FloatBlock> std_error;
  // The mesh the radiosity refers to (6 x its elements floats); null when there is no radiosity
  // or its geometry is not at hand. mesh_version is its version (0: unknown), also when the
  // geometry itself was not loaded.
  MeshPtr mesh;
  int64_t mesh_version = 0;
  // Job.attempts when the snapshot was taken (1 on the first run).
  int32_t attempts = 0;
  // The elements of `radiosity` with a back side ([begin, end) pairs), and `radiosity` and
  // `std_error` in the layout of WatchJobRequest.existing_sides_only (each element's front, then
  // its back where back_ranges has it); null when the sides are not known. The same blocks as
  // the full ones when every element has a back side.
  std::shared_ptr<const std::vector<int64_t>> back_ranges;
  std::shared_ptr<const FloatBlock> existing_radiosity, existing_std_error;
};

// Sets snapshot->back_ranges (when null, from snapshot->mesh) and fills existing_radiosity and
// existing_std_error from the full blocks (nothing when the sides are not known or do not fit).
void AddExistingSides(Snapshot* snapshot);

// back_ranges as the bytes of kBackRangesFile, and back (null for bytes that are not ranges of
// `elements` elements).
std::string SerializeBackRanges(const std::vector<int64_t>& ranges);
std::shared_ptr<const std::vector<int64_t>> ParseBackRanges(const std::string& bytes,
                                                            int64_t elements);
using SnapshotPtr = std::shared_ptr<const Snapshot>;

class SnapshotSink {
 public:
  virtual ~SnapshotSink() = default;
  // A new snapshot (called under the channel's lock: must not block or call back into it).
  virtual void OnSnapshot(const SnapshotPtr& snapshot) = 0;
  // The channel closed without a final snapshot (the server is shutting down).
  virtual void OnClose(const absl::Status& status) = 0;
  // Whether it sends existing sides only (WatchJobRequest.existing_sides_only): snapshots then
  // carry that layout too (JobChannel::WantsExistingSides).
  virtual bool WantsExistingSides() const { return false; }
};

class JobChannel {
 public:
  // Makes `snapshot` the newest and hands it to every sink.
  void Publish(SnapshotPtr snapshot);
  // Ends the channel without a final snapshot; sinks (present and future) get OnClose(status).
  void Close(const absl::Status& status);
  // Registers a sink and hands it the newest snapshot, if any (or OnClose if closed).
  void Subscribe(SnapshotSink* sink);
  // After this returns, the sink is never called again.
  void Unsubscribe(SnapshotSink* sink);
  SnapshotPtr latest() const;
  // Whether a sink wants existing sides only: the publisher then adds that layout
  // (AddExistingSides), which costs up to half a snapshot more, only while someone needs it.
  bool WantsExistingSides() const;
  // Whether any sink is registered.
  bool HasSinks() const;

 private:
  mutable std::mutex mu_;
  SnapshotPtr latest_;
  std::vector<SnapshotSink*> sinks_;
  bool closed_ = false;
  absl::Status close_status_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_SNAPSHOTS_H_
