// Replicas: the latest snapshot of a running job, shared through the blob directory with the
// replicas whose watchers follow the job (docs/service/stores.md). Only while someone elsewhere
// watches: the following replica touches a file, and the holder writes while it is fresh.
//
//   BLOBS/jobs/{job}/live/watched          touched by a following replica (its mtime: interest)
//   BLOBS/jobs/{job}/live/snapshot         the latest snapshot with its radiosity (below)
//   BLOBS/jobs/{job}/live/mesh-{version}   the announcement of the mesh it refers to
//                                          (SerializeMesh)
//
// The snapshot file: "RLIVE1\n", then little-endian int64 sequence, mesh_version, elements,
// radiosity and std-error float counts, attempts, the JobProgress message's length, that message,
// then the floats. Files are replaced atomically, so a reader sees one whole version.
#ifndef RADIOSITY_SERVER_LIVE_SHARE_H_
#define RADIOSITY_SERVER_LIVE_SHARE_H_

#include <chrono>
#include <string>

#include "absl/status/statusor.h"
#include "server/snapshots.h"

namespace radiosity::service {

// How long a touch of `watched` keeps the holder writing.
inline constexpr std::chrono::seconds kLiveInterest(3);

// The live directory of the job whose files are in `job_dir` (DataDir::Job).
std::string LiveDir(const std::string& job_dir);

// Follower: says that a watcher here follows the job.
void TouchLiveInterest(const std::string& job_dir);
// Holder: whether a follower touched the interest file within kLiveInterest.
bool LiveWatched(const std::string& job_dir);

// Holder: writes `snapshot` (with radiosity and mesh) as the job's latest; its mesh's file first,
// once per version.
absl::Status WriteLiveSnapshot(const std::string& job_dir, const Snapshot& snapshot);

// Follower: the latest snapshot, when it is newer than `after_sequence` (null otherwise, or when
// there is none); its mesh read from its file unless `*mesh` is that version already (then
// reused; replaced when read).
absl::StatusOr<SnapshotPtr> ReadLiveSnapshot(const std::string& job_dir, int64_t after_sequence,
                                             MeshPtr* mesh);

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_LIVE_SHARE_H_
