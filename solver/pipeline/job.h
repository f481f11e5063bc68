// One solve job from a loaded scene to result files: mesh, visibility, solver, outputs. The CLI's
// local mode and the service's workers both run jobs through RunJob, so they behave alike.
#ifndef RADIOSITY_SOLVER_PIPELINE_JOB_H_
#define RADIOSITY_SOLVER_PIPELINE_JOB_H_

#include <atomic>
#include <functional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/methods/adaptive.h"
#include "solver/methods/method_choice.h"
#include "solver/methods/solve_options.h"
#include "solver/methods/solver.h"
#include "solver/results/summary.h"
#include "solver/transport/gather.h"

namespace radiosity {

// Most materials or surfaces one job may make emit.
inline constexpr size_t kMaxEmitOverrides = 1000;

struct JobSpec {
  // A job's method defaults to "auto" (ChooseMethod), the CLI's and the service's default.
  JobSpec() {
    solve.method = "auto";
    mesh.agglomerate_degrees = kDefaultAgglomerateDegrees;
  }
  // Meshing; agglomeration (mesh.agglomerate_degrees, on by default) applies where the method
  // takes agglomerated meshes (TakesAgglomeratedMesh) and the job does not refine.
  MeshOptions mesh;
  // Adaptive refinement (off when refine.tolerance is 0): mesh.max_elements is then the budget
  // and the first mesh is built with a sixteenth of it (or mesh.element_size when given).
  RefineOptions refine;
  SolveOptions solve;
  std::string camera;  // ParseCamera syntax; empty: DefaultCamera.
  int width = 512, height = 512;
  std::vector<SensorPoint> sensors;  // Written to sensors.csv when not empty.
  // Cosine-distributed rays per sensor for its indirect light (gather.h).
  int sensor_samples = kDefaultSensorSamples;
  // Materials or surfaces made to emit before solving (ApplyEmitOverrides; `--emit`).
  std::vector<EmitOverride> emit;
  bool write_ply = true;
  bool write_image = true;
  // Checkpoints (docs/service/server.md; not for adaptive refinement): with a path, the solver's
  // state is written there every checkpoint_seconds of solving (after a step that ran to its
  // end), and a job that starts with a checkpoint of the same spec, method and mesh there resumes
  // from it: with the same seed it ends with the same result, element for element, as a run
  // never interrupted. Every method saves its state.
  std::string checkpoint_path;
  double checkpoint_seconds = 10;
  std::string ToString() const;
};

// What happened to a job's checkpoint (JobObserver::on_checkpoint).
struct CheckpointEvent {
  enum class Kind {
    kWritten,      // A checkpoint was written (bytes, write_seconds).
    kResumed,      // The solve continues from the checkpoint found at the start.
    kDiscarded,    // The checkpoint found was not usable (status says why); the solve restarts.
    kWriteFailed,  // Writing failed (status: e.g. RESOURCE_EXHAUSTED, a full disk); it goes on.
    kUnsupported,  // The method cannot save its state; no checkpoint is written.
  };
  Kind kind = Kind::kWritten;
  Progress progress;  // The solver's progress at the checkpoint.
  int64_t bytes = 0;
  // kWritten, kWriteFailed: how long the solve waited while its state was copied, and how long
  // the write took after (on another thread, while the solve went on).
  double pause_seconds = 0, write_seconds = 0;
  absl::Status status;
  std::string ToString() const;
};

// A phase of a job besides solving, and how far it has come (JobObserver::on_phase).
struct PhaseProgress {
  enum class Phase { kMeshing, kWriting };
  Phase phase = Phase::kMeshing;
  double fraction = 0;  // 0 to 1, non-decreasing within a phase.
  std::string item;     // Writing: the file being written ("mesh.glb").
};

struct JobObserver {
  // Called when a mesh is built, before solving on it (again after each refinement, so that
  // snapshots that follow refer to the new mesh).
  std::function<void(const Mesh&)> on_mesh;
  // Called once, before the first solve, with the method that runs and why (for "auto", what
  // ChooseMethod decided on the first mesh; otherwise "requested").
  std::function<void(const MethodChoice&)> on_method;
  // Called once after on_method when the method ignores options the spec sets (IgnoredOptions,
  // named as the CLI's flags), with one message each; not called when there are none.
  std::function<void(const std::vector<std::string>&)> on_warnings;
  // Called as meshing (the mesh, then its ray-tracing structure, before the first on_mesh) and
  // writing the result files (after the last on_snapshot) advance: at 0 when each starts, in
  // steps of at least 1 %, at 1 when done, and at each file written. Meshing's calls may come
  // from Embree's build threads, one at a time.
  std::function<void(const PhaseProgress&)> on_phase;
  // Called after every solver step.
  std::function<void(const Progress&)> on_progress;
  // Called with the current solution at most every `snapshot_interval` seconds, and once at the
  // end. 0 disables snapshots.
  std::function<void(const Progress&, const Solution&)> on_snapshot;
  double snapshot_interval = 0;
  // Called for each checkpoint event (JobSpec::checkpoint_path); kWritten and kWriteFailed from
  // the thread that writes (one at a time, before RunJob returns).
  std::function<void(const CheckpointEvent&)> on_checkpoint;
};

struct JobResult {
  Solution solution;
  StopReason reason = StopReason::kConverged;
  int64_t elements = 0, patches = 0, faces = 0;
  double mesh_seconds = 0;
  int passes = 1;       // Solves run (more than one with adaptive refinement).
  MethodChoice method;  // The method that ran, and why.
  // Options it ignored, and an element budget the faces exceed (also in summary.json).
  std::vector<std::string> warnings;
  std::vector<std::string> files;  // Names of the files written into the output directory.
  // The job's progress after its steps (every step until kMaxConvergencePoints, then thinned to
  // every other point, so it always spans the whole run), and at its end; kept in checkpoints.
  std::vector<ConvergencePoint> convergence;
  static constexpr size_t kMaxConvergencePoints = 1024;
};

// What a checkpoint of `spec` solved with `method` on `mesh` must match to be resumed: the spec,
// the method, and the mesh's elements (positions and areas, hashed).
std::string CheckpointFingerprint(const JobSpec& spec, const std::string& method, const Mesh& mesh);

// Checks every field of `spec` (meshing, the solve, refinement, image and sensors): the one
// validation the CLI and the service both call. INVALID_ARGUMENT names the first bad field as
// `naming` says, e.g. "--refine-passes: 0 is outside [1, 64]" or "solve.refine.max_passes: ...".
absl::Status ValidateJobSpec(const JobSpec& spec, FieldNaming naming);

// The label of a field of a job spec: its CLI flag, or "solve." and its path in SolveSpec.
std::string JobFieldLabel(const std::string& key, FieldNaming naming);

// Meshes and solves `scene` and writes elements.csv (and elements_back.csv), summary.json,
// mesh.ply, image.exr, image.png and sensors.csv into `out_dir` (created if missing). Stops early
// (still writing results) when *stop becomes true. Progress.rays counts every pass's rays, so it
// never goes back. Errors: INVALID_ARGUMENT (ValidateJobSpec) / RESOURCE_EXHAUSTED for bad
// options, FAILED_PRECONDITION for a scene with no emitter, INTERNAL for Embree or I/O errors.
absl::StatusOr<JobResult> RunJob(const Scene& scene, const JobSpec& spec,
                                 const std::string& out_dir, const std::atomic<bool>* stop,
                                 const JobObserver& observer);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_PIPELINE_JOB_H_
