// `radiosity report`: an HTML page of a finished solve (docs/guide/outputs.md): the image, the
// convergence plot (an SVG of summary.json's history), the energy books, and for sensor points
// the statistics lighting engineers report. Pure functions of the job's result files, so that
// they are tested without a server.
#ifndef RADIOSITY_CLIENT_REPORT_H_
#define RADIOSITY_CLIENT_REPORT_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace radiosity::client {

// Statistics of one grid of sensor points, of each point's illuminance-like value: the
// luminance-weighted irradiance Y(E) (Rgb::Luminance weights; W per square scene unit).
struct SensorGridStats {
  std::string name;
  int points = 0;
  double min = 0, mean = 0, max = 0;
  double u0 = 0;       // Uniformity U0 = Emin / Eavg (0 when Eavg is 0).
  double min_max = 0;  // Emin / Emax (0 when Emax is 0).
  std::string ToString() const;
};

// The grids of a sensors.csv (header x,y,z,nx,ny,nz,r,g,b,...; a `grid` column, when present,
// names each point's grid, else all points form the grid "all"), in order of first appearance.
// INVALID_ARGUMENT naming the line for a malformed row.
absl::StatusOr<std::vector<SensorGridStats>> SensorStatsFromCsv(const std::string& csv);

// An SVG line plot of summary.json's convergence history: unshot fraction (log scale) against
// seconds, with the tolerance as a dashed line when it is > 0. Empty input: a plot saying so.
std::string ConvergenceSvg(const std::vector<double>& seconds,
                           const std::vector<double>& unshot_fraction, double tolerance,
                           const std::vector<double>& std_error = {});

// The report page: `summary_json` (summary.json's text), `image` (a relative path of the PNG, or
// empty), `grids` (may be empty), and the job's name. INVALID_ARGUMENT if summary.json does not
// parse.
absl::StatusOr<std::string> ReportHtml(const std::string& job, const std::string& summary_json,
                                       const std::string& image,
                                       const std::vector<SensorGridStats>& grids);

}  // namespace radiosity::client

#endif  // RADIOSITY_CLIENT_REPORT_H_
