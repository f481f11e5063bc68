// Error metrics, resource usage and small helpers of the benchmark (bench_util.h).
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numeric>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "bench/bench_util.h"

namespace radiosity::bench {

std::vector<uint8_t> ExistingSlots(const Scene& scene, const Mesh& mesh) {
  std::vector<uint8_t> exists(static_cast<size_t>(mesh.sides().slots()), 0);
  for (size_t s = 0; s < exists.size(); ++s) exists[s] = mesh.sides().exists(static_cast<int>(s));
  return exists;
}

namespace {

double Channel(const Rgb& c, int k) { return k < 3 ? c[k] : c.Luminance(); }

}  // namespace

ErrorMetrics CompareRadiosity(const Mesh& mesh, const std::vector<uint8_t>& exists,
                              const std::vector<Rgb>& estimate, const std::vector<Rgb>& reference) {
  ErrorMetrics m;
  const auto& elements = mesh.elements();
  const size_t slots = std::min({estimate.size(), reference.size(), exists.size()});
  // Area-weighted means of the reference (the floors of the denominators), channels 0-2 and
  // luminance (3).
  double area = 0, mean[4] = {0, 0, 0, 0}, est_power = 0;
  for (size_t s = 0; s < slots; ++s) {
    if (!exists[s]) continue;
    const double a = elements[ElementOfSlot(static_cast<int>(s))].area;
    area += a;
    for (int k = 0; k < 4; ++k) mean[k] += a * Channel(reference[s], k);
    est_power += a * estimate[s].Luminance();
  }
  if (area <= 0) return m;
  m.power_error = mean[3] > 0 ? (est_power - mean[3]) / mean[3] : 0;
  for (double& v : mean) v /= area;

  double sum_sq[4] = {0, 0, 0, 0};
  std::vector<std::pair<double, double>> lum_errors;  // (error, area)
  lum_errors.reserve(slots);
  for (size_t s = 0; s < slots; ++s) {
    if (!exists[s]) continue;
    const double a = elements[ElementOfSlot(static_cast<int>(s))].area;
    for (int k = 0; k < 4; ++k) {
      const double ref = Channel(reference[s], k);
      const double denom = std::max(ref, kFloor * mean[k]);
      const double e = denom > 0 ? std::fabs(Channel(estimate[s], k) - ref) / denom : 0;
      sum_sq[k] += a * e * e;
      if (k == 3) {
        lum_errors.push_back({e, a});
        m.max_lum = std::max(m.max_lum, e);
      }
    }
    ++m.slots;
  }
  for (int k = 0; k < 3; ++k) m.rms_rgb[k] = std::sqrt(sum_sq[k] / area);
  m.rms_lum = std::sqrt(sum_sq[3] / area);
  // Area-weighted 99th percentile: the smallest error below which 99 % of the area lies.
  std::sort(lum_errors.begin(), lum_errors.end());
  double cumulative = 0;
  for (const auto& [e, a] : lum_errors) {
    cumulative += a;
    m.p99_lum = e;
    if (cumulative >= 0.99 * area) break;
  }
  return m;
}

double EstimatedRmsLum(const Mesh& mesh, const std::vector<uint8_t>& exists,
                       const std::vector<Rgb>& std_error, const std::vector<Rgb>& reference) {
  const size_t slots = std::min({std_error.size(), reference.size(), exists.size()});
  if (slots == 0) return std::nan("");
  const auto& elements = mesh.elements();
  double area = 0, mean = 0;
  for (size_t s = 0; s < slots; ++s) {
    if (!exists[s]) continue;
    const double a = elements[ElementOfSlot(static_cast<int>(s))].area;
    area += a;
    mean += a * reference[s].Luminance();
  }
  if (!(area > 0)) return std::nan("");
  mean /= area;
  double sum_sq = 0;
  for (size_t s = 0; s < slots; ++s) {
    if (!exists[s]) continue;
    const double a = elements[ElementOfSlot(static_cast<int>(s))].area;
    const double denom = std::max(reference[s].Luminance(), kFloor * mean);
    const double e = denom > 0 ? std_error[s].Luminance() / denom : 0;
    sum_sq += a * e * e;
  }
  return std::sqrt(sum_sq / area);
}

double BalanceError(const Solution& s) {
  const double emitted = s.emitted_power.Sum();
  if (!(emitted > 0)) return 0;
  return (s.emitted_power - s.absorbed_power - s.escaped_power - s.unshot_power).Sum() / emitted;
}

double CpuSeconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

namespace {

// A "Name:   1234 kB" line of /proc/self/status, in MiB; -1 if missing.
double StatusKiB(const std::string& key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key + ":", 0) == 0) {
      std::istringstream fields(line.substr(key.size() + 1));
      double kib = -1;
      fields >> kib;
      return kib;
    }
  }
  return -1;
}

}  // namespace

double CurrentRssMiB() { return StatusKiB("VmRSS") / 1024.0; }

double PeakRssMiB() {
  double kib = StatusKiB("VmHWM");
  if (kib < 0) {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    kib = static_cast<double>(usage.ru_maxrss);
  }
  return kib / 1024.0;
}

bool ResetPeakRss() {
  std::FILE* f = std::fopen("/proc/self/clear_refs", "w");
  if (f == nullptr) return false;
  const bool ok = std::fputs("5", f) >= 0;
  return std::fclose(f) == 0 && ok;
}

std::vector<std::string> SplitList(const std::string& text) {
  std::vector<std::string> out;
  for (absl::string_view part : absl::StrSplit(text, ',', absl::SkipWhitespace())) {
    out.emplace_back(absl::StripAsciiWhitespace(part));
  }
  return out;
}

int Table::Column(const std::string& name) const {
  for (size_t i = 0; i < header.size(); ++i) {
    if (header[i] == name) return static_cast<int>(i);
  }
  return -1;
}

absl::StatusOr<Table> ReadTable(const std::string& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  Table table;
  std::string line;
  bool first = true;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> fields = absl::StrSplit(line, ',');
    if (first) {
      table.header = std::move(fields);
      first = false;
    } else if (fields == table.header) {
      continue;  // A header repeated by an append.
    } else {
      fields.resize(table.header.size());
      table.rows.push_back(std::move(fields));
    }
  }
  return table;
}

}  // namespace radiosity::bench
