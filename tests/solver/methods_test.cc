// The matrix solvers (jacobi, gauss-seidel) and reflection simulation against independent truth
// (the furnace's closed form, for every method, is in furnace_test.cc): the residual of the
// returned solution recomputed here from the stored matrix (and the error bound it implies against
// this test's own solve of that matrix), the matrix size limit, agreement of all four methods on
// the Cornell box within their Monte Carlo standard errors, conservation of energy, and
// determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "proto/api/exit_codes.h"
#include "solver/geometry/mesh.h"
#include "solver/input/scene_files.h"
#include "solver/methods/matrix_solver.h"
#include "solver/methods/solver.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

constexpr double kMiB = 1024.0 * 1024.0;

using testing::CornellBoxWorld;
using testing::SolveRun;
using testing::World;

// Per-slot coefficients from the scene, by the rules of docs/guide/scenes.md (front emits and
// reflects; the back only when two-sided; transmission both ways), independent of the solvers.
struct Coefficients {
  std::vector<Rgb> phi, r, t;
  std::vector<bool> exists;
};

Coefficients SlotCoefficients(const World& w) {
  const auto& elements = w.mesh->elements();
  Coefficients c;
  const size_t slots = 2 * elements.size();
  c.phi.assign(slots, Rgb());
  c.r.assign(slots, Rgb());
  c.t.assign(slots, Rgb());
  c.exists.assign(slots, false);
  for (size_t e = 0; e < elements.size(); ++e) {
    const Material& m = w.scene.materials[w.scene.surfaces[elements[e].surface].material];
    for (int side = 0; side < 2; ++side) {
      const size_t s = 2 * e + side;
      const bool faces_out = side == 0 || m.two_sided;
      c.exists[s] = side == 0 || m.two_sided || m.transmittance.Sum() > 0;
      if (!c.exists[s]) continue;
      if (faces_out) {
        c.phi[s] = m.emission * elements[e].area;
        c.r[s] = m.reflectance;
      }
      c.t[s] = m.transmittance;
    }
  }
  return c;
}

// ---------------------------------------------------------------------------------------------
// Stopping on the residual: the returned solution's residual, recomputed here from the stored
// matrix and the scene's coefficients, is below the tolerance, and was above it one sweep earlier.
// Against this test's own solve of the same matrix, the error obeys the bound the residual gives
// (e = K e + u, so |e| <= |u| / (1 - |K|), |K| the largest power fraction a source passes on).

class MatrixResidualTest : public ::testing::TestWithParam<std::string> {};

TEST_P(MatrixResidualTest, ReturnedSolutionHasResidualBelowTolerance) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, CornellBoxWorld(250));
  SolveOptions opt;
  opt.method = GetParam();
  opt.tolerance = 1e-3;
  opt.rays_per_element = 300;
  opt.seed = 5;
  auto created = MatrixSolver::Create(w->scene, *w->mesh, *w->vis, opt, nullptr);
  ASSERT_TRUE(created.ok()) << created.status();
  MatrixSolver& solver = **created;
  std::vector<double> fractions;
  std::vector<bool> assembled;
  auto reason = RunSolver(solver, opt, nullptr, [&](const Progress& p) {
    fractions.push_back(p.unshot_fraction);
    assembled.push_back(solver.assembled());
  });
  ASSERT_TRUE(reason.ok()) << reason.status();
  EXPECT_EQ(*reason, StopReason::kConverged);
  ASSERT_TRUE(solver.assembled());
  const Solution sol = solver.Final();
  const MatrixSolver::Matrix& f = solver.matrix();
  const auto& elements = w->mesh->elements();
  const size_t slots = 2 * elements.size();
  ASSERT_EQ(f.row_start.size(), slots + 1);
  ASSERT_EQ(sol.radiosity.size(), slots);
  const Coefficients c = SlotCoefficients(*w);

  // P = B A, H = F^T P, u = Phi + R H + T H' - P.
  auto incident = [&](const std::vector<Rgb>& p) {
    std::vector<Rgb> h(slots);
    for (size_t k = 0; k < slots; ++k) {
      for (int64_t i = f.row_start[k]; i < f.row_start[k + 1]; ++i) {
        h[k] += p[f.source[i]] * static_cast<double>(f.f[i]);
      }
    }
    return h;
  };
  auto target = [&](const std::vector<Rgb>& h, size_t s) {
    return c.phi[s] + c.r[s] * h[s] + c.t[s ^ 1] * h[s ^ 1];
  };
  std::vector<Rgb> p(slots);
  for (size_t s = 0; s < slots; ++s) p[s] = sol.radiosity[s] * elements[s / 2].area;
  std::vector<Rgb> h = incident(p);
  Rgb residual, signed_residual, emitted;
  for (size_t s = 0; s < slots; ++s) {
    emitted += c.phi[s];
    if (!c.exists[s]) continue;
    Rgb u = target(h, s) - p[s];
    signed_residual += u;
    residual += Rgb(std::fabs(u.r), std::fabs(u.g), std::fabs(u.b));
  }
  const double fraction = residual.Sum() / emitted.Sum();
  EXPECT_LE(fraction, opt.tolerance);
  EXPECT_GT(fraction, 0.0);
  EXPECT_NEAR(fraction, sol.unshot_fraction, 1e-9);
  // It stopped at the first sweep whose residual was below the tolerance.
  ASSERT_GE(fractions.size(), 2u);
  ASSERT_TRUE(assembled[fractions.size() - 2]) << "converged in the assembly step";
  EXPECT_GT(fractions[fractions.size() - 2], opt.tolerance);
  EXPECT_LE(fractions.back(), opt.tolerance);
  // The residual is the unshot power of the books, which balance.
  for (int ch = 0; ch < 3; ++ch) {
    EXPECT_NEAR(sol.unshot_power[ch], signed_residual[ch], 1e-9 * emitted[ch]);
    EXPECT_NEAR(sol.emitted_power[ch],
                sol.absorbed_power[ch] + sol.escaped_power[ch] + sol.unshot_power[ch],
                1e-9 * emitted[ch]);
  }

  // This test's own solve of the stored matrix, to rounding.
  std::vector<Rgb> exact = c.phi, next(slots);
  for (int it = 0; it < 10000; ++it) {
    std::vector<Rgb> he = incident(exact);
    double change = 0;
    for (size_t s = 0; s < slots; ++s) {
      next[s] = c.exists[s] ? target(he, s) : Rgb();
      change += (next[s] - exact[s]).Sum();
    }
    exact.swap(next);
    if (std::fabs(change) < 1e-14 * emitted.Sum()) break;
  }
  // |K| per channel: the most power (as a fraction) a source passes on after one transfer.
  Rgb kappa;
  std::vector<Rgb> passed(slots);
  for (size_t k = 0; k < slots; ++k) {
    for (int64_t i = f.row_start[k]; i < f.row_start[k + 1]; ++i) {
      passed[f.source[i]] += (c.r[k] + c.t[k]) * static_cast<double>(f.f[i]);
    }
  }
  for (const Rgb& q : passed) {
    kappa = Rgb(std::max(kappa.r, q.r), std::max(kappa.g, q.g), std::max(kappa.b, q.b));
  }
  for (int ch = 0; ch < 3; ++ch) {
    ASSERT_LT(kappa[ch], 1.0);
    double error = 0;
    for (size_t s = 0; s < slots; ++s) error += std::fabs(exact[s][ch] - p[s][ch]);
    EXPECT_LE(error, residual[ch] / (1 - kappa[ch]) * (1 + 1e-9)) << "channel " << ch;
    // And the solve was not exact already: the bound is not vacuous.
    EXPECT_GT(error, 0.05 * residual[ch]) << "channel " << ch;
  }
}

INSTANTIATE_TEST_SUITE_P(Methods, MatrixResidualTest, ::testing::Values("jacobi", "gauss-seidel"),
                         [](const auto& param_info) {
                           return param_info.param == "jacobi" ? "Jacobi" : "GaussSeidel";
                         });

// ---------------------------------------------------------------------------------------------
// The matrix size limit: refused before anything is assembled, with RESOURCE_EXHAUSTED and a
// message naming --max-matrix-mb; the worst case it checks bounds the matrix actually stored.

TEST(MatrixSolverTest, RefusesAMatrixOverTheLimit) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, CornellBoxWorld(250));
  SolveOptions opt;
  opt.method = "gauss-seidel";
  opt.rays_per_element = 200;
  opt.tolerance = 1e-3;
  auto solver = MatrixSolver::Create(w->scene, *w->mesh, *w->vis, opt, nullptr);
  ASSERT_TRUE(solver.ok()) << solver.status();
  const double worst = (*solver)->WorstCaseBytes();
  ASSERT_GT(worst, 0.0);

  opt.max_matrix_mb = worst / kMiB * 0.999;
  auto refused = CreateSolver(w->scene, *w->mesh, *w->vis, opt, nullptr);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_NE(refused.status().message().find("--max-matrix-mb"), std::string::npos)
      << refused.status();

  opt.max_matrix_mb = worst / kMiB * 1.001;
  auto accepted = MatrixSolver::Create(w->scene, *w->mesh, *w->vis, opt, nullptr);
  ASSERT_TRUE(accepted.ok()) << accepted.status();
  auto reason = RunSolver(**accepted, opt, nullptr, nullptr);
  ASSERT_TRUE(reason.ok()) << reason.status();
  EXPECT_EQ(*reason, StopReason::kConverged);
  // Stored: a float and an index an entry, held twice while transposed.
  const double stored = 2.0 * (*accepted)->matrix().nonzeros() * 8;
  EXPECT_LE(stored, worst);
  EXPECT_GT(stored, 0.0);
}

// A hemicube row holds one entry per cell at most (3 res^2), so its bound does not grow with N:
// a coarse hemicube over a mesh finer than its cells must be accepted, and still bound what is
// stored.
TEST(MatrixSolverTest, HemicubeBoundUsesItsCells) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, CornellBoxWorld(250));
  SolveOptions opt;
  opt.method = "gauss-seidel";
  opt.tolerance = 1e-3;
  opt.formfactor.method = "hemicube";
  opt.formfactor.hemicube_resolution = 4;  // 48 cells, fewer than the mesh's element sides.
  const double n = static_cast<double>(w->mesh->elements().size());
  ASSERT_GT(2 * n, 48.0);
  auto solver = MatrixSolver::Create(w->scene, *w->mesh, *w->vis, opt, nullptr);
  ASSERT_TRUE(solver.ok()) << solver.status();
  const double worst = (*solver)->WorstCaseBytes();
  auto reason = RunSolver(**solver, opt, nullptr, nullptr);
  ASSERT_TRUE(reason.ok()) << reason.status();
  const double stored = 2.0 * (*solver)->matrix().nonzeros() * 8;
  EXPECT_GT(stored, 0.0);
  EXPECT_LE(stored, worst);
  // Far below the 2 n entries a row could otherwise hold.
  opt.formfactor.method = "analytic";
  auto dense = MatrixSolver::Create(w->scene, *w->mesh, *w->vis, opt, nullptr);
  ASSERT_TRUE(dense.ok()) << dense.status();
  EXPECT_LT(worst, 0.5 * (*dense)->WorstCaseBytes());
}

TEST(MatrixSolverTest, CliRefusesAMatrixOverTheLimit) {
  testing::TempDir dir;
  auto r = testing::RunSolve(
      testing::SourcePath("scenes/cornell_box.obj"), dir.path(),
      {"--max-elements", "250", "--method", "jacobi", "--max-matrix-mb", "0.01", "--quiet"});
  EXPECT_EQ(r.exit_code, kExitUsage) << r.output;
  EXPECT_NE(r.output.find("--max-matrix-mb"), std::string::npos) << r.output;
}

TEST(MatrixSolverTest, UnknownEstimatorIsRefused) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, CornellBoxWorld(250));
  SolveOptions opt;
  opt.method = "jacobi";
  opt.formfactor.method = "guesswork";
  auto solver = CreateSolver(w->scene, *w->mesh, *w->vis, opt, nullptr);
  ASSERT_FALSE(solver.ok());
  EXPECT_EQ(solver.status().code(), absl::StatusCode::kInvalidArgument);
}

// ---------------------------------------------------------------------------------------------
// All four methods on the Cornell box: they solve the same element-level system, so the
// area-weighted mean radiosity of every surface agrees between any two methods within a few
// standard errors, estimated from independent seeds; and each conserves energy.

TEST(MethodsTest, AllFourAgreeOnTheCornellBox) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, CornellBoxWorld(250));
  const size_t n = w->mesh->elements().size();
  ASSERT_GE(n, 150u);
  ASSERT_LE(n, 300u);
  const std::vector<std::string> methods = {"progressive", "jacobi", "gauss-seidel", "reflection"};
  constexpr int kSeeds = 8;
  const size_t surfaces = w->scene.surfaces.size();
  // mean[method][surface], and its standard error, per channel.
  std::map<std::string, std::vector<Rgb>> mean, se;
  for (const std::string& method : methods) {
    std::vector<std::vector<Rgb>> runs;
    for (int seed = 1; seed <= kSeeds; ++seed) {
      SolveOptions opt;
      opt.method = method;
      opt.seed = static_cast<uint64_t>(seed);
      opt.rays_per_element = 1500;
      opt.tolerance = 1e-4;
      ASSERT_OK_AND_ASSIGN(SolveRun r, testing::Solve(*w, opt));
      ASSERT_EQ(r.reason, StopReason::kConverged) << method;
      const Solution& sol = r.solution;
      for (int c = 0; c < 3; ++c) {
        // Energy: emitted = absorbed + escaped within 0.5 % (the matrix solvers and progressive
        // to their tolerance; reflection within its Monte Carlo noise)...
        EXPECT_NEAR(sol.absorbed_power[c] + sol.escaped_power[c], sol.emitted_power[c],
                    5e-3 * sol.emitted_power[c])
            << method << " seed " << seed << " channel " << c;
        // ... and with the unshot power (the residual) to rounding, but for reflection, whose
        // Russian roulette conserves power per channel only in expectation.
        if (method == "reflection") continue;
        EXPECT_NEAR(sol.absorbed_power[c] + sol.escaped_power[c] + sol.unshot_power[c],
                    sol.emitted_power[c], 1e-9 * sol.emitted_power[c])
            << method << " seed " << seed << " channel " << c;
      }
      EXPECT_GT(sol.escaped_power.Sum(), 0.0) << method;  // The box is open.
      runs.push_back(testing::SurfaceMeans(*w, sol));
    }
    mean[method].assign(surfaces, Rgb());
    se[method].assign(surfaces, Rgb());
    for (size_t s = 0; s < surfaces; ++s) {
      for (int c = 0; c < 3; ++c) {
        double m = 0, v = 0;
        for (const auto& run : runs) m += run[s][c] / kSeeds;
        for (const auto& run : runs) v += (run[s][c] - m) * (run[s][c] - m) / (kSeeds - 1);
        mean[method][s][c] = m;
        se[method][s][c] = std::sqrt(v / kSeeds);
      }
    }
  }
  // Five standard errors of the difference (Welch): with about 14 degrees of freedom a true
  // difference of zero exceeds it with probability ~2e-4 per comparison.
  for (size_t a = 0; a < methods.size(); ++a) {
    for (size_t b = a + 1; b < methods.size(); ++b) {
      for (size_t s = 0; s < surfaces; ++s) {
        for (int c = 0; c < 3; ++c) {
          const double ma = mean[methods[a]][s][c], mb = mean[methods[b]][s][c];
          const double sa = se[methods[a]][s][c], sb = se[methods[b]][s][c];
          ASSERT_GT(sa, 0.0) << methods[a];
          EXPECT_LE(std::fabs(ma - mb), 5 * std::sqrt(sa * sa + sb * sb))
              << methods[a] << " vs " << methods[b] << " on " << w->scene.surfaces[s].name
              << " channel " << c << ": " << ma << " +- " << sa << " vs " << mb << " +- " << sb;
        }
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Determinism: the same seed gives the same result whatever the thread count.

class MethodsDeterminismTest : public ::testing::TestWithParam<std::string> {};

TEST_P(MethodsDeterminismTest, SameSeedSameResultWhateverTheThreads) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, CornellBoxWorld(250));
  SolveOptions opt;
  opt.method = GetParam();
  opt.rays_per_element = 300;
  opt.seed = 42;
  opt.threads = 1;
  ASSERT_OK_AND_ASSIGN(SolveRun a, testing::Solve(*w, opt));
  opt.threads = 2;
  ASSERT_OK_AND_ASSIGN(SolveRun b, testing::Solve(*w, opt));
  ASSERT_EQ(a.solution.radiosity.size(), b.solution.radiosity.size());
  EXPECT_EQ(a.solution.rays, b.solution.rays);
  EXPECT_GT(a.solution.rays, 0);
  for (size_t i = 0; i < a.solution.radiosity.size(); ++i) {
    ASSERT_EQ(a.solution.radiosity[i], b.solution.radiosity[i]) << "slot " << i;
  }
  EXPECT_EQ(a.solution.absorbed_power, b.solution.absorbed_power);
  EXPECT_EQ(a.solution.escaped_power, b.solution.escaped_power);
  opt.seed = 43;
  ASSERT_OK_AND_ASSIGN(SolveRun c, testing::Solve(*w, opt));
  EXPECT_NE(a.solution.radiosity, c.solution.radiosity);
}

INSTANTIATE_TEST_SUITE_P(Methods, MethodsDeterminismTest, ::testing::Values("jacobi", "reflection"),
                         [](const auto& param_info) {
                           return param_info.param == "jacobi" ? "Jacobi" : "Reflection";
                         });

}  // namespace
}  // namespace radiosity
