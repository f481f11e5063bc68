#include "solver/pipeline/job.h"

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <future>
#include <optional>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/strip.h"
#include "solver/geometry/interpolation.h"
#include "solver/methods/adaptive.h"
#include "solver/methods/checkpoint.h"
#include "solver/results/camera.h"
#include "solver/results/elements_csv.h"
#include "solver/results/gltf.h"
#include "solver/results/image.h"
#include "solver/results/ply.h"
#include "solver/results/render.h"
#include "solver/results/sensors_csv.h"
#include "solver/results/summary.h"
#include "solver/transport/gather.h"
#include "solver/transport/specular.h"
#include "solver/transport/visibility.h"
#include "solver/util/field_checker.h"
#include "solver/util/progress.h"
#include "tbb/task_arena.h"

namespace radiosity {

std::string JobSpec::ToString() const {
  return absl::StrCat("JobSpec{", mesh.ToString(), " ", solve.ToString(), " camera='", camera, "' ",
                      width, "x", height, " sensors=", sensors.size(), " emit=", emit.size(), "}");
}

namespace {

// The job's fields outside SolveOptions: key (path below "solve." in SolveSpec) and CLI flag.
constexpr std::pair<const char*, const char*> kJobFields[] = {
    {"mesh.element_size", "--element-size"},
    {"mesh.max_elements", "--max-elements"},
    {"mesh.patch_depth", "--patch-depth"},
    {"mesh.agglomerate_degrees", "--agglomerate"},
    {"camera", "--camera"},
    {"width", "--width"},
    {"height", "--height"},
    {"sensors", "--sensors"},
    {"sensor_samples", "--sensor-samples"},
    {"emit", "--emit"},
    {"checkpoint_seconds", "--checkpoint-seconds"},
    {"refine.tolerance", "--refine"},
    {"refine.min_element_size", "--min-element-size"},
    {"refine.light_samples", "--refine-light-samples"},
    {"refine.max_passes", "--refine-passes"},
    {"refine.direct_samples", "--refine-direct-samples"},
};

constexpr Bounds kMaxElementsBounds{1, 1099511627776.0, "[1, 2^40]"};
constexpr Bounds kPatchDepthBounds{0, 8, "[0, 8]"};
constexpr Bounds kAgglomerateBounds{0, 90, "[0, 90] degrees"};
constexpr Bounds kImageSideBounds{1, 16384, "[1, 16384]"};
constexpr Bounds kRefineToleranceBounds{0, 0.999999, "[0, 1)"};
constexpr Bounds kMinElementSizeBounds{0, 1e300, "[0, inf)"};
constexpr Bounds kLightSamplesBounds{1, 4096, "[1, 4096]"};
constexpr Bounds kRefinePassesBounds{1, 64, "[1, 64]"};
constexpr Bounds kDirectSamplesBounds{1, 65536, "[1, 65536]"};
constexpr Bounds kCheckpointSecondsBounds{0.01, 86400, "[0.01, 86400] seconds"};

}  // namespace

std::string JobFieldLabel(const std::string& key, FieldNaming naming) {
  for (const auto& [field, flag] : kJobFields) {
    if (key.rfind(field, 0) != 0) continue;  // "sensors[3]" is labelled as "sensors".
    return naming == FieldNaming::kField ? "solve." + key : std::string(flag);
  }
  return OptionLabel(key, naming);
}

absl::Status ValidateJobSpec(const JobSpec& spec, FieldNaming naming) {
  if (absl::Status s = Validate(spec.solve, naming); !s.ok()) return s;
  FieldChecker c([naming](const std::string& key) { return JobFieldLabel(key, naming); });
  // Meshing: an element size, or (0) the element budget decides.
  if (spec.mesh.element_size != 0) c.Positive("mesh.element_size", spec.mesh.element_size);
  c.InBounds("mesh.max_elements", static_cast<double>(spec.mesh.max_elements), kMaxElementsBounds);
  c.InBounds("mesh.patch_depth", spec.mesh.patch_depth, kPatchDepthBounds);
  c.InBounds("mesh.agglomerate_degrees", spec.mesh.agglomerate_degrees, kAgglomerateBounds);
  // Outputs.
  if (!spec.camera.empty()) {
    absl::StatusOr<Camera> camera = ParseCamera(spec.camera, Camera());
    if (!camera.ok()) {
      c.Fail("camera", std::string(absl::StripPrefix(camera.status().message(), "camera: ")));
    }
  }
  c.InBounds("width", spec.width, kImageSideBounds);
  c.InBounds("height", spec.height, kImageSideBounds);
  for (size_t i = 0; i < spec.sensors.size(); ++i) {
    const SensorPoint& p = spec.sensors[i];
    const double length = Length(p.n);
    if (!IsFinite(p.p) || !IsFinite(p.n) || !(length > 0) || !std::isfinite(length)) {
      c.Fail(absl::StrCat("sensors[", i, "]"),
             absl::StrCat("sensor point ", i,
                          ": the position must be finite and the normal finite and not zero"));
    }
  }
  c.InBounds("sensor_samples", spec.sensor_samples, kSensorSamplesBounds);
  if (spec.emit.size() > kMaxEmitOverrides) {
    c.Fail("emit", absl::StrCat(spec.emit.size(), " emitters added; at most ", kMaxEmitOverrides));
  }
  for (size_t i = 0; i < spec.emit.size(); ++i) {
    const EmitOverride& e = spec.emit[i];
    if (e.name.empty() || !e.exitance.IsFinite() || e.exitance.Min() < 0) {
      c.Fail(absl::StrCat("emit[", i, "]"),
             absl::StrCat("'", e.ToString(),
                          "': a material or surface name and an exitance finite and >= 0"));
    }
  }
  // Adaptive refinement.
  c.InBounds("refine.tolerance", spec.refine.tolerance, kRefineToleranceBounds);
  c.InBounds("refine.min_element_size", spec.refine.min_element_size, kMinElementSizeBounds);
  c.InBounds("refine.light_samples", spec.refine.light_samples, kLightSamplesBounds);
  c.InBounds("refine.max_passes", spec.refine.max_passes, kRefinePassesBounds);
  c.InBounds("refine.direct_samples", spec.refine.direct_samples, kDirectSamplesBounds);
  if (!spec.checkpoint_path.empty()) {
    c.InBounds("checkpoint_seconds", spec.checkpoint_seconds, kCheckpointSecondsBounds);
  }
  return c.status();
}

std::string CheckpointEvent::ToString() const {
  static constexpr const char* kNames[] = {"written", "resumed", "discarded", "write_failed",
                                           "unsupported"};
  return absl::StrFormat("CheckpointEvent{%s %s bytes=%d pause_seconds=%.3f write_seconds=%.3f%s}",
                         kNames[static_cast<int>(kind)], progress.ToString(), bytes, pause_seconds,
                         write_seconds, status.ok() ? "" : " " + status.ToString());
}

std::string CheckpointFingerprint(const JobSpec& spec, const std::string& method,
                                  const Mesh& mesh) {
  // The thread count changes neither the mesh nor the streams (results depend only on the seed).
  JobSpec canonical = spec;
  canonical.solve.threads = 0;
  uint64_t hash = Fnv1a("");
  auto add = [&hash](const auto& value) {
    hash = Fnv1a(absl::string_view(reinterpret_cast<const char*>(&value), sizeof(value)), hash);
  };
  for (const Element& e : mesh.elements()) {
    add(e.face);
    add(e.patch);
    add(e.area);
    add(e.centroid);
  }
  // What each element's sides do with light (a checkpoint of other materials, or of other
  // meanings of them, does not resume).
  for (int64_t slot = 0; slot < mesh.sides().slots(); ++slot) {
    const SideRule& r = mesh.sides()[static_cast<int>(slot)];
    for (const Rgb& c :
         {r.exitance, r.reflectance, r.transmittance, r.specular, r.glass, r.mirror}) {
      add(c);
    }
  }
  return absl::StrFormat("%s method=%s faces=%d patches=%d elements=%d mesh_hash=%016x",
                         canonical.ToString(), method, mesh.faces().size(), mesh.patches().size(),
                         mesh.elements().size(), hash);
}

absl::StatusOr<JobResult> RunJob(const Scene& input_scene, const JobSpec& spec,
                                 const std::string& out_dir, const std::atomic<bool>* stop,
                                 const JobObserver& observer) {
  // Check what can be checked before any large allocation or long computation.
  if (absl::Status s = ValidateJobSpec(spec, FieldNaming::kFlag); !s.ok()) return s;
  // Lights the spec adds (--emit) go onto a copy.
  std::optional<Scene> lit;
  if (!spec.emit.empty()) {
    lit = input_scene;
    if (absl::Status s = ApplyEmitOverrides(spec.emit, &*lit); !s.ok()) return s;
  }
  const Scene& scene = lit ? *lit : input_scene;
  const bool custom_camera = !spec.camera.empty();

  JobResult result;
  const bool adaptive = spec.refine.tolerance > 0;
  MeshOptions first_mesh = spec.mesh;
  // Refinement splits quadtree leaves, which agglomerated elements are not.
  if (adaptive || !TakesAgglomeratedMesh(spec.solve)) first_mesh.agglomerate_degrees = 0;
  if (adaptive && first_mesh.element_size == 0) {
    // Adaptive runs start coarse and spend --max-elements on refinement.
    first_mesh.max_elements = std::max<int64_t>(1, spec.mesh.max_elements / 16);
  }
  // The job's thread count holds for the BVH builds too (the solvers make arenas of their own).
  tbb::task_arena arena(spec.solve.threads > 0 ? spec.solve.threads : tbb::task_arena::automatic);
  auto mesh_start = std::chrono::steady_clock::now();
  // max_seconds covers meshing and solving: the builds stop at the flag or the deadline.
  const StopToken build_stop(stop, spec.solve.max_seconds);
  auto run_seconds = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - mesh_start).count();
  };
  // A deadline that passes before the mesh is ready leaves nothing to solve: the job fails.
  auto built = [&](const absl::Status& st) {
    if (st.code() != absl::StatusCode::kDeadlineExceeded) return st;
    return absl::DeadlineExceededError(absl::StrFormat(
        "%s %g passed before the mesh was ready (%s); allow more time or fewer elements",
        JobFieldLabel("max_seconds", FieldNaming::kFlag), spec.solve.max_seconds, st.message()));
  };
  // Meshing's progress: the mesh is the first half, its ray-tracing structure the second.
  auto meshing = [&](double from) -> ProgressCallback {
    if (!observer.on_phase) return {};
    return [&observer, from](double f) {
      observer.on_phase({PhaseProgress::Phase::kMeshing, from + 0.5 * f, ""});
    };
  };
  absl::StatusOr<Mesh> mesh = Mesh::Build(scene, first_mesh, &build_stop, meshing(0));
  if (!mesh.ok()) return built(mesh.status());
  auto visibility = Visibility::Build(*mesh, &arena, &build_stop, meshing(0.5));
  if (!visibility.ok()) return built(visibility.status());
  result.mesh_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - mesh_start).count();

  // "auto" is decided once, on the first mesh: adaptive passes keep the method they began with.
  result.method = ResolveMethod(*mesh, spec.solve);
  if (mesh->agglomerated()) {
    SolveOptions resolved = spec.solve;
    resolved.method = result.method.method;
    if (!TakesAgglomeratedMesh(resolved)) {
      // "auto" chose a method that meshes each face (the choice does not depend on the mesh's
      // elements): build that mesh.
      first_mesh.agglomerate_degrees = 0;
      mesh = Mesh::Build(scene, first_mesh, &build_stop);
      if (!mesh.ok()) return built(mesh.status());
      visibility = Visibility::Build(*mesh, &arena, &build_stop);
      if (!visibility.ok()) return built(visibility.status());
    }
  }
  if (observer.on_method) observer.on_method(result.method);
  result.warnings = IgnoredOptions(result.method.method, spec.solve, FieldNaming::kFlag);
  if (mesh->sides().any_specular()) {
    // docs/guide/specular.md: which methods carry light through them.
    const SpecularTable specular(scene);
    const bool traced =
        (result.method.method == "progressive" && spec.solve.formfactor.method == "montecarlo") ||
        result.method.method == "reflection";
    if (!traced) {
      result.warnings.push_back(absl::StrFormat(
          "materials %s have specular parts (mirror, glossy, glass) that --method %s%s treats as "
          "absorbing; progressive refinement with Monte Carlo rays and reflection simulation "
          "carry light through them",
          specular.Names(), result.method.method,
          result.method.method == "progressive"
              ? absl::StrCat(" --formfactor ", spec.solve.formfactor.method)
              : ""));
    }
  }
  // A budget the faces alone exceed is said, not kept silently: every face is one element at
  // least, and agglomeration (where this job has it) gathers faces only within its bound.
  const int64_t mesh_elements = static_cast<int64_t>(mesh->elements().size());
  if (spec.mesh.element_size == 0 && mesh_elements > spec.mesh.max_elements) {
    auto label = [](const char* key) { return JobFieldLabel(key, FieldNaming::kFlag); };
    const std::string why =
        first_mesh.agglomerate_degrees > 0
            ? absl::StrFormat(", and faces are gathered only within %g degrees (%s)",
                              first_mesh.agglomerate_degrees, label("mesh.agglomerate_degrees"))
        : spec.mesh.agglomerate_degrees > 0
            ? absl::StrFormat(" (--method %s%s meshes every face)", result.method.method,
                              adaptive ? absl::StrCat(" with ", label("refine.tolerance")) : "")
            : absl::StrFormat(" (faces are not gathered: %s 0)", label("mesh.agglomerate_degrees"));
    result.warnings.push_back(absl::StrFormat(
        "the mesh has %d elements, more than %s %d: every face is one element at least%s",
        mesh_elements, label("mesh.max_elements"), spec.mesh.max_elements, why));
  }
  if (observer.on_warnings && !result.warnings.empty()) observer.on_warnings(result.warnings);

  auto job_start = std::chrono::steady_clock::now();
  // A checkpoint of this spec, method and mesh: the solve resumes from it (job.seconds, then the
  // solver's state; RestoreState below).
  const bool checkpoints = !spec.checkpoint_path.empty() && !adaptive;
  if (!spec.checkpoint_path.empty() && adaptive && observer.on_checkpoint) {
    CheckpointEvent unsupported;  // Refinement changes the mesh between passes: not saved.
    unsupported.kind = CheckpointEvent::Kind::kUnsupported;
    observer.on_checkpoint(unsupported);
  }
  auto notify = [&](CheckpointEvent::Kind kind, absl::Status status = absl::OkStatus()) {
    CheckpointEvent event;
    event.kind = kind;
    event.status = std::move(status);
    return event;
  };
  std::string fingerprint, resume_state;
  std::optional<StateReader> resume;
  std::chrono::steady_clock::duration spent{0};  // By the solve the checkpoint saved.
  if (checkpoints) {
    fingerprint = CheckpointFingerprint(spec, result.method.method, *mesh);
    absl::StatusOr<std::string> state = ReadCheckpoint(spec.checkpoint_path, fingerprint);
    double seconds = 0;
    if (state.ok()) {
      resume_state = *std::move(state);
      resume.emplace(resume_state);
      // At most a year: a forged value must not turn the elapsed time negative.
      state = resume->Get("job.seconds", &seconds).ok() && seconds >= 0 && seconds <= 3.2e7
                  ? absl::StatusOr<std::string>("")
                  : absl::DataLossError("the checkpoint has no valid job.seconds");
      if (state.ok() && (!resume->GetAnyVector("job.convergence", &result.convergence).ok() ||
                         result.convergence.size() > JobResult::kMaxConvergencePoints)) {
        result.convergence.clear();
        state = absl::DataLossError("the checkpoint has no valid job.convergence");
      }
    }
    if (!state.ok()) {
      resume.reset();
      if (!absl::IsNotFound(state.status()) && observer.on_checkpoint) {
        observer.on_checkpoint(notify(CheckpointEvent::Kind::kDiscarded, state.status()));
      }
    } else {
      // The time already spent counts against max_seconds, as if the solve had not stopped.
      spent = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
          std::chrono::duration<double>(seconds));
      job_start -= spent;
      mesh_start -= spent;
    }
  }
  auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - job_start).count();
  };
  int64_t rays_before = 0;
  Progress last_progress;
  // The convergence history: every step's progress, thinned to every other point when full.
  auto record = [&](const Progress& p) {
    auto& history = result.convergence;
    if (history.size() >= JobResult::kMaxConvergencePoints) {
      size_t kept = 0;
      for (size_t i = 0; i < history.size(); i += 2) history[kept++] = history[i];
      history.resize(kept);
    }
    history.push_back({p.seconds, p.rays, p.unshot_fraction});
  };
  for (int pass = 0;; ++pass) {
    // The first pass solves; later ones re-gather what the refined elements receive (below), or
    // with --refine-resolve solve again on the refined mesh.
    if (pass == 0 || spec.refine.resolve) {
      SolveOptions options = spec.solve;
      options.method = result.method.method;
      // Re-gathering uses the split of each element's light into direct and indirect.
      options.track_direct = adaptive && !spec.refine.resolve;
      // The job's ray and time budgets cover all passes.
      if (options.max_seconds > 0) {
        options.max_seconds = std::max(1e-3, options.max_seconds - run_seconds());
      }
      if (options.max_rays > 0) {
        options.max_rays = std::max<int64_t>(1, options.max_rays - rays_before);
      }
      auto solver = CreateSolver(scene, *mesh, **visibility, options, stop);
      if (!solver.ok()) return solver.status();
      if (resume) {
        if (absl::Status st = (*solver)->RestoreState(&*resume); !st.ok()) {
          // A state that does not fit leaves the solver unusable: a fresh one starts over, with
          // its own convergence history.
          resume.reset();
          result.convergence.clear();
          job_start += spent;
          mesh_start += spent;
          if (observer.on_checkpoint) {
            observer.on_checkpoint(notify(CheckpointEvent::Kind::kDiscarded, st));
          }
          if (options.max_seconds > 0) {
            options.max_seconds = std::max(1e-3, spec.solve.max_seconds - run_seconds());
          }
          solver = CreateSolver(scene, *mesh, **visibility, options, stop);
          if (!solver.ok()) return solver.status();
        } else if (observer.on_checkpoint) {
          CheckpointEvent event = notify(CheckpointEvent::Kind::kResumed);
          event.progress = (*solver)->progress();
          event.bytes = static_cast<int64_t>(resume_state.size());
          observer.on_checkpoint(event);
        }
      }
      if (observer.on_mesh) observer.on_mesh(*mesh);

      auto last_snapshot = std::chrono::steady_clock::now();
      auto last_checkpoint = last_snapshot;
      bool can_checkpoint = checkpoints;
      // After a step that ran to its end, every checkpoint_seconds: the state, atomically.
      // At most one checkpoint write in flight, off the solve's thread; leaving this scope
      // (however) waits for it.
      std::future<void> writing;
      auto checkpoint = [&] {
        auto now = std::chrono::steady_clock::now();
        if (!can_checkpoint || (*solver)->Interrupted() ||
            std::chrono::duration<double>(now - last_checkpoint).count() <
                spec.checkpoint_seconds) {
          return;
        }
        if (writing.valid()) {
          // The previous write is still going: try again after the next step.
          if (writing.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return;
          writing.get();
        }
        StateWriter state;
        state.Put("job.seconds", elapsed());
        state.PutVector("job.convergence", result.convergence);
        if (!(*solver)->SaveState(&state)) {
          can_checkpoint = false;
          if (observer.on_checkpoint) {
            observer.on_checkpoint(notify(CheckpointEvent::Kind::kUnsupported));
          }
          return;
        }
        last_checkpoint = std::chrono::steady_clock::now();
        CheckpointEvent event;
        event.progress = (*solver)->progress();
        event.pause_seconds = std::chrono::duration<double>(last_checkpoint - now).count();
        writing = std::async(std::launch::async, [&, state = std::move(state), event]() mutable {
          const auto start = std::chrono::steady_clock::now();
          event.status = WriteCheckpoint(spec.checkpoint_path, fingerprint, state.data());
          event.kind = event.status.ok() ? CheckpointEvent::Kind::kWritten
                                         : CheckpointEvent::Kind::kWriteFailed;
          event.bytes = static_cast<int64_t>(state.data().size());
          event.write_seconds =
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
          if (observer.on_checkpoint) observer.on_checkpoint(event);
        });
      };
      // Progress of the whole job: the rays and seconds of earlier passes count too (a
      // re-solved pass starts its own counts at 0), so watchers never see them go back.
      auto job_progress = [&](Progress p) {
        p.rays += rays_before;
        p.seconds = elapsed();
        return p;
      };
      if (resume && observer.on_snapshot) {
        // Watchers see the resumed solution at once.
        Solution snapshot = (*solver)->Snapshot();
        observer.on_snapshot(job_progress((*solver)->progress()), snapshot);
      }
      auto on_step = [&](const Progress& step) {
        const Progress p = job_progress(step);
        record(p);
        checkpoint();
        if (observer.on_progress) observer.on_progress(p);
        if (observer.on_snapshot && observer.snapshot_interval > 0) {
          auto now = std::chrono::steady_clock::now();
          if (std::chrono::duration<double>(now - last_snapshot).count() >=
              observer.snapshot_interval) {
            last_snapshot = now;
            Solution snapshot = (*solver)->Snapshot();
            snapshot.rays += rays_before;
            // The estimated error against time (summary.json's convergence, the report's plot).
            result.convergence.back().std_error_relative = RelativeStdErrorRms(*mesh, snapshot);
            observer.on_snapshot(p, snapshot);
          }
        }
      };
      absl::StatusOr<StopReason> reason = RunSolver(**solver, options, stop, on_step);
      if (!reason.ok()) return reason.status();
      result.reason = *reason;
      result.solution = (*solver)->Final();
      last_progress = job_progress((*solver)->progress());
      record(last_progress);
      result.convergence.back().std_error_relative = RelativeStdErrorRms(*mesh, result.solution);
      result.solution.rays += rays_before;
      rays_before = result.solution.rays;
      result.solution.seconds = elapsed();
      if (observer.on_snapshot) observer.on_snapshot(last_progress, result.solution);
    }
    result.passes = pass + 1;

    // Refine, unless this is not an adaptive job or a limit was reached.
    if (!adaptive || result.reason != StopReason::kConverged ||
        pass + 1 >= spec.refine.max_passes) {
      break;
    }
    const int64_t have = static_cast<int64_t>(mesh->elements().size());
    std::vector<RefineCandidate> candidates =
        SelectForRefinement(scene, *mesh, **visibility, result.solution, spec.refine);
    std::vector<int> split;
    // A split adds at most 3 elements (4 children for 1), plus what balancing adds.
    for (const RefineCandidate& c : candidates) {
      if (have + 3 * static_cast<int64_t>(split.size() + 1) > spec.mesh.max_elements) break;
      split.push_back(c.element);
    }
    if (split.empty()) break;
    Mesh refined = RefineMesh(scene, *mesh, split);
    // Balancing splits neighbours too: shed the lowest-priority candidates until within budget.
    while (static_cast<int64_t>(refined.elements().size()) > spec.mesh.max_elements &&
           split.size() > 1) {
      split.resize(split.size() * 3 / 4);
      refined = RefineMesh(scene, *mesh, split);
    }
    if (static_cast<int64_t>(refined.elements().size()) > spec.mesh.max_elements) break;
    if (spec.refine.resolve) {
      *mesh = std::move(refined);
      visibility = Visibility::Build(*mesh, &arena);
      if (!visibility.ok()) return visibility.status();
      continue;
    }
    // Re-gather: the limits are checked between passes (a pass takes a fraction of the solve).
    if (stop != nullptr && stop->load()) {
      result.reason = StopReason::kCancelled;
      break;
    }
    if (spec.solve.max_seconds > 0 && run_seconds() >= spec.solve.max_seconds) {
      result.reason = StopReason::kMaxSeconds;
      break;
    }
    if (spec.solve.max_rays > 0 && rays_before >= spec.solve.max_rays) {
      result.reason = StopReason::kMaxRays;
      break;
    }
    Mesh coarse = std::move(*mesh);
    *mesh = std::move(refined);
    visibility = Visibility::Build(*mesh, &arena);
    if (!visibility.ok()) return visibility.status();
    result.solution = RegatherRefinement(scene, coarse, result.solution, *mesh, **visibility,
                                         spec.refine, spec.solve.seed, pass + 1);
    if (absl::Status st = (*visibility)->status(); !st.ok()) return st;
    last_progress.rays += result.solution.rays - rays_before;
    rays_before = result.solution.rays;
    result.solution.seconds = elapsed();
    last_progress.seconds = result.solution.seconds;
    if (observer.on_progress) observer.on_progress(last_progress);
    if (observer.on_mesh) observer.on_mesh(*mesh);
    if (observer.on_snapshot) observer.on_snapshot(last_progress, result.solution);
  }
  result.elements = static_cast<int64_t>(mesh->elements().size());
  result.patches = static_cast<int64_t>(mesh->patches().size());
  result.faces = static_cast<int64_t>(mesh->faces().size());

  std::error_code ec;
  std::filesystem::create_directories(out_dir, ec);
  if (ec) {
    return absl::InternalError(absl::StrCat(out_dir, ": cannot create directory: ", ec.message()));
  }
  auto path = [&](const std::string& name) {
    result.files.push_back(name);
    return (std::filesystem::path(out_dir) / name).string();
  };
  // Writing's progress: one step per file (or pair: image.exr and image.png, rendered once); a
  // cancel on the way leaves steps out, and the fraction jumps to 1 at the end.
  const bool heavy = (spec.write_ply || spec.write_image) && !(stop != nullptr && stop->load());
  const int steps = 3 + (spec.sensors.empty() ? 0 : 1) + (heavy && spec.write_ply ? 2 : 0) +
                    (heavy && spec.write_image ? 1 : 0);
  int step = 0;
  auto writing = [&](const std::string& item) {
    if (observer.on_phase) {
      observer.on_phase({PhaseProgress::Phase::kWriting, static_cast<double>(step) / steps, item});
    }
    ++step;
  };
  writing("elements.csv");
  absl::Status st = WriteElementsCsv(scene, *mesh, result.solution, path("elements.csv"),
                                     mesh->sides().any_back() ? path("elements_back.csv") : "");
  if (!st.ok()) return st;
  writing("elements_error.csv");
  st = WriteElementsErrorCsv(scene, *mesh, StdErrors(*mesh, result.solution),
                             path("elements_error.csv"),
                             mesh->sides().any_back() ? path("elements_back_error.csv") : "");
  if (!st.ok()) return st;
  if (!spec.sensors.empty()) {
    writing("sensors.csv");
    GatherOptions gather;
    gather.seed = result.solution.seed;
    gather.samples = spec.sensor_samples;
    gather.sky = spec.solve.sky;
    gather.luminaires = spec.solve.luminaires;
    gather.luminaire_samples = spec.solve.luminaire_samples;
    SensorIrradiance sensed;
    // Stopped, the values are partial: written all the same, as the elements are.
    arena.execute([&] {
      sensed = GatherIrradiance(scene, *mesh, **visibility, result.solution, spec.sensors, gather,
                                StopToken(stop, 0));
    });
    if (absl::Status vs = (*visibility)->status(); !vs.ok()) return vs;
    st = WriteSensorsCsv(spec.sensors, sensed.irradiance, sensed.std_error, path("sensors.csv"));
    if (!st.ok()) return st;
  }
  // A cancelled job ends now: what costs by the size of the model (interpolated corners, the
  // PLY and glTF meshes, the image) is left out, the elements and the summary are written.
  const bool cancelled = stop != nullptr && stop->load();
  if ((spec.write_ply || spec.write_image) && !cancelled) {
    auto corners = CornerRadiosity(*mesh, result.solution);
    if (spec.write_ply) {
      writing("mesh.ply");
      st = WritePly(*mesh, result.solution, corners, path("mesh.ply"));
      if (!st.ok()) return st;
      writing("mesh.glb");
      st = WriteGlb(*mesh, corners, path("mesh.glb"));
      if (!st.ok()) return st;
    }
    if (spec.write_image) {
      writing("image.png");
      Camera camera = DefaultCamera(*mesh);
      if (custom_camera) camera = *ParseCamera(spec.camera, camera);
      // A cancel while rendering (whose cost per ray depends on the scene) stops it too.
      const StopToken cancel(stop, 0);
      const SpecularTable specular(scene);
      Image image = RenderImage(*mesh, **visibility, result.solution, corners, camera, spec.width,
                                spec.height, 4, &cancel, &specular);
      if (image.width > 0) {
        st = WriteImage(image, path("image.exr"), path("image.png"));
        if (!st.ok()) return st;
      }
    }
  }
  SummaryFacts facts;
  facts.method_requested = spec.solve.method;
  facts.method = result.method;
  facts.formfactor = spec.solve.formfactor.method;
  facts.threads = spec.solve.threads > 0 ? spec.solve.threads
                                         : static_cast<int>(std::thread::hardware_concurrency());
  facts.refine_tolerance = spec.refine.tolerance;
  facts.refine_passes = result.passes;
  facts.refine_mode = spec.refine.tolerance <= 0 ? "off"
                      : spec.refine.resolve      ? "resolve"
                                                 : "regather";
  facts.mesh_seconds = result.mesh_seconds;
  facts.tolerance = spec.solve.tolerance;
  facts.reason = result.reason;
  facts.luminaires = spec.solve.luminaires;
  facts.warnings = result.warnings;
  facts.convergence = result.convergence;
  writing("summary.json");
  st = WriteSummary(path("summary.json"), scene, *mesh, result.solution, facts);
  if (!st.ok()) return st;
  if (observer.on_phase) observer.on_phase({PhaseProgress::Phase::kWriting, 1, ""});
  return result;
}

}  // namespace radiosity
