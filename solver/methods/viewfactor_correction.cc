#include "solver/methods/viewfactor_correction.h"

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"

namespace radiosity {

absl::StatusOr<ViewFactorCorrection> EnforceViewFactors(ViewFactorMatrix* m,
                                                        const std::string& mode,
                                                        const std::atomic<bool>* stop) {
  if (mode != "none" && mode != "reciprocity" && mode != "closure") {
    return absl::InvalidArgumentError(
        absl::StrCat("enforce must be none, reciprocity or closure, got '", mode, "'"));
  }
  ViewFactorCorrection out;
  out.before = CheckViewFactors(*m);
  const int n = m->size();
  if (mode != "none") {
    // G = A F, symmetrised on the union of the patterns of F and F^T (sparse rows).
    ViewFactorMatrix g;
    g.surfaces.resize(n);
    {
      std::vector<std::vector<std::pair<int32_t, double>>> rows(n);
      for (int i = 0; i < n; ++i) {
        for (int64_t k = m->row_start[i]; k < m->row_start[i + 1]; ++k) {
          const int j = m->col[k];
          const double half = 0.5 * m->area[i] * m->val[k];
          rows[i].push_back({j, half});
          rows[j].push_back({i, half});
        }
      }
      g.SetRows(&rows);
    }
    if (mode == "closure") {
      // (diag(G 1) + G) l = A - G 1 over the rows that see something, by Jacobi-preconditioned
      // conjugate gradients.
      std::vector<double> rows(n, 0.0), r(n, 0.0), l(n, 0.0), z(n), p(n), q(n), diag(n);
      for (int i = 0; i < n; ++i) {
        for (int64_t k = g.row_start[i]; k < g.row_start[i + 1]; ++k) rows[i] += g.val[k];
      }
      auto apply = [&](const std::vector<double>& x, std::vector<double>* y) {
        for (int i = 0; i < n; ++i) {
          double s = rows[i] * x[i];
          for (int64_t k = g.row_start[i]; k < g.row_start[i + 1]; ++k) s += g.val[k] * x[g.col[k]];
          (*y)[i] = rows[i] > 0 ? s : 0.0;
        }
      };
      double norm_b = 0;
      for (int i = 0; i < n; ++i) {
        r[i] = rows[i] > 0 ? m->area[i] - rows[i] : 0.0;
        diag[i] = rows[i] + g.at(i, i);
        norm_b += r[i] * r[i];
        z[i] = diag[i] > 0 ? r[i] / diag[i] : 0.0;
        p[i] = z[i];
      }
      double rz = 0;
      for (int i = 0; i < n; ++i) rz += r[i] * z[i];
      const double target = 1e-30 * std::max(norm_b, 1e-300);
      for (int it = 0; it < 10 * n + 100; ++it) {
        double rr = 0;
        for (double x : r) rr += x * x;
        if (rr <= target) break;
        if (stop != nullptr && stop->load(std::memory_order_relaxed)) {
          return absl::CancelledError("view-factor correction cancelled");
        }
        apply(p, &q);
        double pq = 0;
        for (int i = 0; i < n; ++i) pq += p[i] * q[i];
        if (!(pq > 0)) break;
        const double alpha = rz / pq;
        for (int i = 0; i < n; ++i) {
          l[i] += alpha * p[i];
          r[i] -= alpha * q[i];
          z[i] = diag[i] > 0 ? r[i] / diag[i] : 0.0;
        }
        double rz_next = 0;
        for (int i = 0; i < n; ++i) rz_next += r[i] * z[i];
        const double beta = rz_next / rz;
        rz = rz_next;
        for (int i = 0; i < n; ++i) p[i] = z[i] + beta * p[i];
        ++out.iterations;
      }
      for (int i = 0; i < n; ++i) {
        for (int64_t k = g.row_start[i]; k < g.row_start[i + 1]; ++k) {
          g.val[k] *= 1 + l[i] + l[g.col[k]];
        }
      }
    }
    // F = G / A, on G's pattern.
    out.smallest_entry = 0;
    m->row_start = std::move(g.row_start);
    m->col = std::move(g.col);
    m->val = std::move(g.val);
    for (int i = 0; i < n; ++i) {
      for (int64_t k = m->row_start[i]; k < m->row_start[i + 1]; ++k) {
        m->val[k] = m->area[i] > 0 ? m->val[k] / m->area[i] : 0.0;
        out.smallest_entry = std::min(out.smallest_entry, m->val[k]);
      }
    }
  }
  out.after = CheckViewFactors(*m);
  return out;
}

}  // namespace radiosity
