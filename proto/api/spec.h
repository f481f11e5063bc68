// Job specifications between their wire form (radiosity.v1.SolveSpec / ViewFactorSpec) and the
// solver's (JobSpec / ViewFactorOptions): defaults for unset fields, then the solver's own
// validation (the CLI's too), with messages naming the wire's field.
#ifndef RADIOSITY_PROTO_API_SPEC_H_
#define RADIOSITY_PROTO_API_SPEC_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "radiosity/v1/service.pb.h"
#include "solver/methods/viewfactor.h"
#include "solver/pipeline/job.h"

namespace radiosity::service {

// Seconds between snapshots when SolveSpec.snapshot_interval is 0.
inline constexpr double kDefaultSnapshotInterval = 0.5;

// The enums of the API's named choices (service.proto) and their names in the solver's options
// and the CLI's flags ("gauss-seidel", "montecarlo", "sobol", "weighted"): UNSPECIFIED and "" for
// each other, and for a name or number that is not defined.
v1::SolveMethod SolveMethodOf(const std::string& name);
std::string SolveMethodName(v1::SolveMethod method);

// The deprecated string fields and their replacements hold one value (service.proto): each form
// that is unset is filled from the other (a camera string is filled from `view`, and `view` from
// a camera string that parses). INVALID_ARGUMENT, naming both fields, when both are set and
// disagree, or for an enum number that service.proto does not define.
absl::Status NormalizeSpec(v1::SolveSpec* spec);
// The camera of a spec in ParseCamera's syntax: from `view` when set, else the deprecated string.
std::string CameraOf(const v1::SolveSpec& spec);
absl::Status NormalizeSpec(v1::ViewFactorSpec* spec);

// The solver's job spec for a wire spec: defaults filled in, every field checked by the solver's
// ValidateJobSpec (INVALID_ARGUMENT naming the field, e.g. "solve.tolerance: 2 is outside [1e-15,
// 0.999999]"). Threads are left as requested (the server caps them).
absl::StatusOr<JobSpec> ToJobSpec(const v1::SolveSpec& spec);
// Seconds between snapshots for a (checked) spec.
double SnapshotInterval(const v1::SolveSpec& spec);

// The wire spec of a solver job spec (every field explicit), as the CLI sends it.
v1::SolveSpec ToSolveSpec(const JobSpec& spec, double snapshot_interval);

absl::StatusOr<ViewFactorOptions> ToViewFactorOptions(const v1::ViewFactorSpec& spec);
v1::ViewFactorSpec ToViewFactorSpec(const ViewFactorOptions& options);

// "QUEUED", "RUNNING", ... (the enum name without its prefix).
std::string StateName(v1::JobState state);
// The inverse, case-insensitive; false for an unknown name.
bool ParseStateName(const std::string& name, v1::JobState* state);
// "meshing", "solving", "writing" ("" for none): JobPhase as the CLI's --json and the browser
// preview write it.
const char* PhaseName(v1::JobPhase phase);

}  // namespace radiosity::service

#endif  // RADIOSITY_PROTO_API_SPEC_H_
