#include "solver/methods/exchange.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <utility>

#include "absl/strings/str_cat.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"
#include "tbb/task_arena.h"

namespace radiosity {

namespace {

bool Stopped(const std::atomic<bool>* stop) {
  return stop != nullptr && stop->load(std::memory_order_relaxed);
}

}  // namespace

absl::Status CheckSurfaceThermal(const SurfaceThermal& t) {
  if (!(t.emissivity >= 0 && t.emissivity <= 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat("surface '", t.surface, "': emissivity ", t.emissivity, " is outside [0, 1]"));
  }
  if (!(t.temperature >= 0) || !std::isfinite(t.temperature)) {
    return absl::InvalidArgumentError(absl::StrCat("surface '", t.surface, "': temperature ",
                                                   t.temperature,
                                                   " K is not a finite number >= 0"));
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<SurfaceThermal>> ResolveThermal(const std::vector<std::string>& names,
                                                           const ThermalInput& input) {
  const int n = static_cast<int>(names.size());
  if (n > kMaxExchangeSurfaces) {
    return absl::InvalidArgumentError(
        absl::StrCat("thermal data: exchange factors are computed for at most ",
                     kMaxExchangeSurfaces, " surfaces (a dense n x n system); the scene has ", n));
  }
  if (!(input.ambient_temperature >= 0) || !std::isfinite(input.ambient_temperature)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "ambient temperature ", input.ambient_temperature, " K is not a finite number >= 0"));
  }
  std::map<std::string, std::vector<int>> index;
  for (int i = 0; i < n; ++i) index[names[i]].push_back(i);
  std::vector<SurfaceThermal> out(n);
  std::vector<bool> set(n, false);
  const SurfaceThermal* fallback = nullptr;
  std::set<std::string> seen;
  for (const SurfaceThermal& t : input.surfaces) {
    if (!seen.insert(t.surface).second) {
      return absl::InvalidArgumentError(
          absl::StrCat("thermal data: surface '", t.surface, "' is given twice"));
    }
    if (absl::Status st = CheckSurfaceThermal(t); !st.ok()) return st;
    if (t.surface == "*") {
      fallback = &t;
      continue;
    }
    auto it = index.find(t.surface);
    if (it == index.end()) {
      return absl::InvalidArgumentError(
          absl::StrCat("thermal data: '", t.surface, "' is not a surface of the scene (", n,
                       " surfaces", n > 0 ? ", e.g. '" + names[0] + "'" : "", ")"));
    }
    for (int i : it->second) {
      out[i] = t;
      set[i] = true;
    }
  }
  for (int i = 0; i < n; ++i) {
    if (set[i]) continue;
    if (fallback == nullptr) {
      return absl::InvalidArgumentError(absl::StrCat(
          "thermal data: surface '", names[i],
          "' has no emissivity and temperature (name it, or give a default row for '*')"));
    }
    out[i] = *fallback;
    out[i].surface = names[i];
  }
  return out;
}

absl::StatusOr<RadiantExchange> ComputeExchange(const ViewFactorMatrix& matrix,
                                                const ThermalInput& input,
                                                const std::atomic<bool>* stop, int threads) {
  const auto start = std::chrono::steady_clock::now();
  const int n = matrix.size();
  absl::StatusOr<std::vector<SurfaceThermal>> thermal = ResolveThermal(matrix.surfaces, input);
  if (!thermal.ok()) return thermal.status();
  RadiantExchange x;
  x.surfaces = matrix.surfaces;
  x.area = matrix.area;
  x.ambient_temperature = input.ambient_temperature;
  for (const SurfaceThermal& t : *thermal) {
    x.emissivity.push_back(t.emissivity);
    x.temperature.push_back(t.temperature);
  }
  const auto at = [n](int i, int j) { return static_cast<size_t>(i) * n + j; };
  // Gaussian elimination with partial pivoting on [I - F diag(rho) | F diag(eps)]; the right-hand
  // block becomes B.
  std::vector<double> a(static_cast<size_t>(n) * n), c(static_cast<size_t>(n) * n);
  for (int i = 0; i < n; ++i) {
    a[at(i, i)] = 1;
    for (int64_t k = matrix.row_start[i]; k < matrix.row_start[i + 1]; ++k) {
      const int j = matrix.col[k];
      const double f = matrix.val[k];
      a[at(i, j)] -= f * (1 - x.emissivity[j]);
      c[at(i, j)] += f * x.emissivity[j];
    }
  }
  const auto swap_rows = [&](std::vector<double>& m, int r, int s) {
    std::swap_ranges(m.begin() + at(r, 0), m.begin() + at(r, 0) + n, m.begin() + at(s, 0));
  };
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  absl::Status status = arena.execute([&]() -> absl::Status {
    for (int k = 0; k < n; ++k) {
      if (Stopped(stop)) return absl::CancelledError("exchange computation cancelled");
      int pivot = k;
      for (int i = k + 1; i < n; ++i) {
        if (std::fabs(a[at(i, k)]) > std::fabs(a[at(pivot, k)])) pivot = i;
      }
      // Rows of I - F diag(rho) sum to >= 0 with a unit diagonal: a pivot this small means light
      // goes round for ever (no surface it can reach absorbs).
      if (!(std::fabs(a[at(pivot, k)]) > 1e-12)) {
        return absl::FailedPreconditionError(absl::StrCat(
            "the exchange system is singular at surface '", matrix.surfaces[k],
            "': light from it is never absorbed nor escapes (every surface it reaches has "
            "emissivity 0)"));
      }
      if (pivot != k) {
        swap_rows(a, pivot, k);
        swap_rows(c, pivot, k);
      }
      const double inv = 1 / a[at(k, k)];
      tbb::parallel_for(tbb::blocked_range<int>(k + 1, n, 16),
                        [&](const tbb::blocked_range<int>& r) {
                          for (int i = r.begin(); i < r.end(); ++i) {
                            const double factor = a[at(i, k)] * inv;
                            if (factor == 0) continue;
                            a[at(i, k)] = 0;
                            for (int j = k + 1; j < n; ++j) a[at(i, j)] -= factor * a[at(k, j)];
                            for (int j = 0; j < n; ++j) c[at(i, j)] -= factor * c[at(k, j)];
                          }
                        });
    }
    for (int k = n - 1; k >= 0; --k) {
      if (Stopped(stop)) return absl::CancelledError("exchange computation cancelled");
      const double inv = 1 / a[at(k, k)];
      for (int j = 0; j < n; ++j) c[at(k, j)] *= inv;
      tbb::parallel_for(tbb::blocked_range<int>(0, k, 16), [&](const tbb::blocked_range<int>& r) {
        for (int i = r.begin(); i < r.end(); ++i) {
          const double factor = a[at(i, k)];
          if (factor == 0) continue;
          for (int j = 0; j < n; ++j) c[at(i, j)] -= factor * c[at(k, j)];
        }
      });
    }
    return absl::OkStatus();
  });
  if (!status.ok()) return status;
  x.gebhart = std::move(c);

  const double t_env4 = std::pow(input.ambient_temperature, 4);
  x.emitted.assign(n, 0.0);
  x.absorbed.assign(n, 0.0);
  x.net.assign(n, 0.0);
  x.to_environment.assign(n, 0.0);
  x.from_environment.assign(n, 0.0);
  for (int i = 0; i < n; ++i) {
    x.emitted[i] = x.area[i] * x.emissivity[i] * kStefanBoltzmann * std::pow(x.temperature[i], 4);
  }
  for (int i = 0; i < n; ++i) {
    double row = 0;
    for (int j = 0; j < n; ++j) {
      row += x.b(i, j);
      x.absorbed[j] += x.emitted[i] * x.b(i, j);
    }
    const double escapes = 1 - row;
    x.to_environment[i] = x.emitted[i] * escapes;
    x.from_environment[i] = x.area[i] * x.emissivity[i] * kStefanBoltzmann * t_env4 * escapes;
    if (x.area[i] > 0) x.max_closure_error = std::max(x.max_closure_error, std::fabs(escapes));
  }
  for (int i = 0; i < n; ++i) {
    x.absorbed[i] += x.from_environment[i];
    x.net[i] = x.emitted[i] - x.absorbed[i];
    for (int j = i + 1; j < n; ++j) {
      const double p = x.area[i] * x.emissivity[i] * x.b(i, j);
      const double q = x.area[j] * x.emissivity[j] * x.b(j, i);
      const double big = std::max(std::fabs(p), std::fabs(q));
      if (big > 0)
        x.max_reciprocity_error = std::max(x.max_reciprocity_error, std::fabs(p - q) / big);
    }
  }
  x.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return x;
}

}  // namespace radiosity
