// Shared pieces of the speed-against-error benchmark (issue 5): reference solutions on disk, error
// metrics against a reference of the same mesh, and process resource usage.
#ifndef RADIOSITY_BENCH_BENCH_UTIL_H_
#define RADIOSITY_BENCH_BENCH_UTIL_H_

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/methods/solve_options.h"

namespace radiosity::bench {

// ---------------------------------------------------------------------------------------------
// References.
//
// A reference is the radiosity of every element side of one mesh, stored as a gzip stream:
//   "radiosity-reference 1\n", then "key=value\n" lines (scene, max_elements, patch_depth,
//   element_size, elements, mesh_hash, method, command, noise_rms, ...), then "end\n",
//   then 2 x elements x 3 float32 (little endian): every element's front RGB, then every
//   element's back RGB (zero where the surface has no back side).
// `zcat FILE | head` shows the header. The mesh hash identifies the mesh exactly (face and (u, v)
// rectangle of every element), so a reference is never compared with another mesh.
struct Reference {
  std::map<std::string, std::string> meta;
  std::vector<Rgb> radiosity;  // Indexed by Slot(element, side), 2 x elements.
};

// FNV-1a over every element's face and (u, v) rectangle, and the element count.
uint64_t MeshHash(const Mesh& mesh);

absl::Status WriteReference(const std::string& path, const Reference& ref);
absl::StatusOr<Reference> ReadReference(const std::string& path);

// OK when `ref` was made on exactly this mesh (element count and hash).
absl::Status CheckReferenceMesh(const Reference& ref, const Mesh& mesh);

// Whether slot s (Slot(element, side)) exists: the front always, the back of surfaces with a
// back side (two-sided or transmitting).
std::vector<uint8_t> ExistingSlots(const Scene& scene, const Mesh& mesh);

// ---------------------------------------------------------------------------------------------
// Error metrics (bench/REPORT.md, bench/REPORT.md "Metrics").
//
// Relative error of slot i in a quantity q (luminance, or one channel):
//   e_i = |q_i - q_i^ref| / max(q_i^ref, kFloor x qbar^ref),
// where qbar^ref is the area-weighted mean of q^ref over the existing slots. The floor keeps
// elements the light never reaches (the floor under a block, with q^ref = 0) from dividing by
// zero; they count with an error relative to the scene's mean.
struct ErrorMetrics {
  double rms_lum = 0;             // sqrt(sum_i A_i e_i^2 / sum_i A_i), luminance.
  double rms_rgb[3] = {0, 0, 0};  // The same per channel.
  double p99_lum = 0;             // Area-weighted 99th percentile of e_i (luminance).
  double max_lum = 0;             // Largest e_i (luminance).
  double power_error = 0;         // (sum A_i B_i - sum A_i B_i^ref) / sum A_i B_i^ref, luminance.
  int64_t slots = 0;              // Slots compared.
};
constexpr double kFloor = 1e-3;

ErrorMetrics CompareRadiosity(const Mesh& mesh, const std::vector<uint8_t>& exists,
                              const std::vector<Rgb>& estimate, const std::vector<Rgb>& reference);

// The solver's own estimate of rms_lum: the area-weighted RMS of its standard errors (luminance),
// relative to the same denominators as CompareRadiosity; NaN when it gave none.
double EstimatedRmsLum(const Mesh& mesh, const std::vector<uint8_t>& exists,
                       const std::vector<Rgb>& std_error, const std::vector<Rgb>& reference);

// bench/sensors.cc: the deterministic reference of sensor points in an empty convex room, and
// solves measured against it (time of meshing, solving and gathering; RMS relative error).
int RoomReferenceCommand(const std::string& scene_path, const std::string& sensors_path,
                         int64_t elements, const std::string& out_path);
int SensorsCommand(const std::string& scene_path, const std::string& sensors_path,
                   const std::string& reference_path, const SolveOptions& options, int64_t elements,
                   int samples, const std::string& csv_path, const std::string& label);

// bench/luminaire.cc: a point luminaire's direct light on a floor's elements at each number of
// points in `samples` (a comma list), against the closed form; a table on stdout, rows to CSV.
int LuminaireCommand(double element_size, const std::string& samples, const std::string& csv_path);

// Energy-balance error of a solution's books: (emitted - absorbed - escaped - unshot) / emitted
// (channel sums). Exact methods keep it at rounding; Russian roulette only in expectation.
double BalanceError(const Solution& solution);

// ---------------------------------------------------------------------------------------------
// Resource usage of this process.
double CpuSeconds();     // User + system time of all threads so far (getrusage).
double CurrentRssMiB();  // VmRSS.
double PeakRssMiB();     // VmHWM (peak resident set since start or the last reset).
// Resets the peak resident set size to the current one (Linux >= 4.0: "5" > /proc/self/clear_refs)
// so that the peak of each run can be measured in one process. Returns false if not supported
// (PeakRssMiB is then the peak of the whole process).
bool ResetPeakRss();

// ---------------------------------------------------------------------------------------------
// Small helpers.
std::vector<std::string> SplitList(const std::string& text);  // "a,b, c" -> {a, b, c}
// Reads a CSV with a header; fields split on commas (our files never quote).
struct Table {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  int Column(const std::string& name) const;
};
absl::StatusOr<Table> ReadTable(const std::string& path);

// Writes the report: plots (gnuplot) and bench/REPORT.md from the CSVs in results_dir.
struct ReportOptions {
  std::string bench_dir;    // bench/
  std::string results_dir;  // bench/results
  std::string figures_dir;  // bench/figures
  std::string out;          // bench/REPORT.md
  std::string mode;         // "quick" or "full"
  std::string gnuplot = "gnuplot";
};
absl::Status WriteReport(const ReportOptions& options);

}  // namespace radiosity::bench

#endif  // RADIOSITY_BENCH_BENCH_UTIL_H_
