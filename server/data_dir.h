// The layout of --data-dir, and reading scenes stored in it.
//
//   DIR/radiosity.db                  SQLite: scenes and jobs, unless --store names another
//                                     (server/store.h)
//   DIR/lock                          flock()ed by the one server using DIR
//   DIR/scenes/{scene}/FILE...        uploaded files, as named by the upload
//   DIR/jobs/{job}/results/FILE...    results of an ended job (+ .radiosity.f32, the final
//                                     radiosity as packed little-endian floats)
//   DIR/jobs/{job}/work/              results being written by a running job
//   DIR/uploads/{token}/              uploads in progress (removed at start-up)
//
// With --blob-dir BLOBS (replicas sharing a PostgreSQL store, docs/service/stores.md), scenes/ and
// jobs/ are BLOBS/scenes and BLOBS/jobs, a directory every replica mounts; the database, the
// lock and uploads in progress stay in each replica's own DIR.
#ifndef RADIOSITY_SERVER_DATA_DIR_H_
#define RADIOSITY_SERVER_DATA_DIR_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "radiosity/v1/service.pb.h"
#include "solver/geometry/scene.h"
#include "solver/methods/solve_options.h"
#include "solver/util/stop.h"

namespace radiosity::service {

// Name of the final radiosity inside a job's results directory (not listed in Job.results).
inline constexpr char kRadiosityFile[] = ".radiosity.f32";
// Its standard errors, same layout, where the method estimated them (not listed either).
inline constexpr char kStdErrorFile[] = ".std_error.f32";
// The geometry of the mesh that radiosity refers to (SerializeMesh), for WatchJob's mesh
// announcements of ended jobs (not listed either).
inline constexpr char kMeshGeometryFile[] = ".mesh.geometry";
// The elements of that mesh with a back side, [begin, end) pairs as little-endian int64, for
// WatchJob's existing_sides_only on ended jobs (not listed either).
inline constexpr char kBackRangesFile[] = ".back_ranges.i64";

class DataDir {
 public:
  // `blob_root` "": scenes and jobs under `root`.
  explicit DataDir(std::string root, std::string blob_root = "")
      : root_(std::move(root)), blob_root_(blob_root.empty() ? root_ : std::move(blob_root)) {}
  // Creates the directories.
  absl::Status Create() const;
  const std::string& root() const { return root_; }
  // Where scenes and jobs are: root(), or the --blob-dir shared by replicas.
  const std::string& blob_root() const { return blob_root_; }
  bool shared() const { return blob_root_ != root_; }
  std::string Scene(const std::string& id) const { return blob_root_ + "/scenes/" + id; }
  std::string Job(const std::string& id) const { return blob_root_ + "/jobs/" + id; }
  std::string Results(const std::string& id) const { return Job(id) + "/results"; }
  std::string Work(const std::string& id) const { return Job(id) + "/work"; }
  // The running solve's latest checkpoint (JobSpec::checkpoint_path), kept across restarts.
  std::string Checkpoint(const std::string& id) const { return Job(id) + "/checkpoint"; }
  std::string Uploads() const { return root_ + "/uploads"; }
  // Takes the directory's lock (one server per data directory); FAILED_PRECONDITION when another
  // process (or server in this process) holds it. The lock lasts while the returned fd is open.
  absl::StatusOr<int> Lock() const;
  // `status` without the server's paths: each path inside the data directory in its message is
  // cut to its last component ("/srv/data/jobs/ab/work/x.f32: cannot write: ..." becomes
  // "x.f32: cannot write: ..."), the code and the OS's reason kept. For what clients are told.
  absl::Status Redact(const absl::Status& status) const;

 private:
  std::string root_;
  std::string blob_root_;
};

// Renames the directory `from` to `to`; when they are on different file systems (uploads in the
// data directory, scenes on a shared --blob-dir), copies it beside `to` and renames the copy, so
// `to` appears whole or not at all, then removes `from`.
absl::Status MoveDirectory(const std::string& from, const std::string& to);

// Loads and validates the scene whose files are in `dir` (described by `info`: files, format,
// display_name). Messages and Scene::source name the files as the client does: the directory is
// replaced by the display name's. For OBJ, every `mtllib` must name a file inside `dir` (an
// absolute path or '..' is INVALID_ARGUMENT), so a scene can never make the server read other
// files. Loader warnings are appended to `warnings` (may be null). Models are read in a child
// process (ModelImporter()) that `stop` (may be null) kills: a cancelled job or a shutdown never
// waits for an importer.
absl::StatusOr<Scene> LoadStoredScene(const std::string& dir, const v1::SceneInfo& info,
                                      std::vector<std::string>* warnings,
                                      const StopToken* stop = nullptr);

// Checks each file of a stored scene against the size and sha256 its upload recorded in `info`:
// DATA_LOSS naming the scene and the file otherwise. Replicas verify scenes they read from the
// shared --blob-dir, which another machine wrote.
absl::Status VerifyStoredScene(const std::string& dir, const v1::SceneInfo& info);

// Reads the photometric files of the luminaires of `solve` from a stored scene's directory
// (LoadScenePhotometry) into their `photometry`; messages name the field
// ("solve.luminaires[2] (lamp.ies): ...") and the file in the client's directory.
absl::Status LoadStoredLuminaires(const std::string& dir, const v1::SceneInfo& info,
                                  SolveOptions* solve);

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_DATA_DIR_H_
