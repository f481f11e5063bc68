// The matrix solvers (jacobi, gauss-seidel) and reflection simulation against independent truth:
// the furnace's closed form (with and without transmission), the residual of the returned solution
// recomputed here from the stored matrix (and the error bound it implies against this test's own
// solve of that matrix), the matrix size limit, agreement of all four methods on the Cornell box
// within their Monte Carlo standard errors, conservation of energy, and determinism.
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

namespace radiosity {
namespace {

constexpr double kMiB = 1024.0 * 1024.0;

// A scene with its mesh and visibility, built in place (the solvers keep references).
struct World {
  Scene scene;
  std::unique_ptr<Mesh> mesh;
  std::unique_ptr<Visibility> vis;
};

std::unique_ptr<World> MakeWorld(Scene scene, const MeshOptions& mo) {
  auto w = std::make_unique<World>();
  w->scene = std::move(scene);
  auto mesh = Mesh::Build(w->scene, mo);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  if (!mesh.ok()) return nullptr;
  w->mesh = std::make_unique<Mesh>(*std::move(mesh));
  auto vis = Visibility::Build(*w->mesh);
  EXPECT_TRUE(vis.ok()) << vis.status();
  if (!vis.ok()) return nullptr;
  w->vis = *std::move(vis);
  return w;
}

// The Cornell box at coarse resolution (about 220 elements).
std::unique_ptr<World> CoarseCornellBox() {
  auto scene = LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr);
  EXPECT_TRUE(scene.ok()) << scene.status();
  if (!scene.ok()) return nullptr;
  MeshOptions mo;
  mo.max_elements = 250;
  return MakeWorld(*std::move(scene), mo);
}

struct Result {
  Solution solution;
  StopReason reason = StopReason::kCancelled;
  std::vector<double> fractions;  // progress().unshot_fraction after every step.
};

Result Solve(const World& w, const SolveOptions& options) {
  Result r;
  auto solver = CreateSolver(w.scene, *w.mesh, *w.vis, options, nullptr);
  EXPECT_TRUE(solver.ok()) << solver.status();
  if (!solver.ok()) return r;
  auto reason = RunSolver(**solver, options, nullptr,
                          [&](const Progress& p) { r.fractions.push_back(p.unshot_fraction); });
  EXPECT_TRUE(reason.ok()) << reason.status();
  if (reason.ok()) r.reason = *reason;
  r.solution = (*solver)->Final();
  return r;
}

// Per-slot coefficients from the scene, by the rules of README "Scene input" (front emits and
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
// The furnace: a closed box, every wall with reflectance R and emission E. Whatever the mesh, the
// power arriving at a wall's front equals what leaves it (rows of the form-factor matrix sum to
// 1), so B = E / (1 - R) on every element (Shirley 6.2). With transmittance T the back side of
// every wall passes T of what arrives at the front out of the box: B_back = T E / (1 - R).

struct MethodsFurnaceCase {
  std::string method;
  double transmittance;
};

class MethodsFurnaceTest : public ::testing::TestWithParam<MethodsFurnaceCase> {};

TEST_P(MethodsFurnaceTest, EveryElementReachesTheClosedForm) {
  const MethodsFurnaceCase& fc = GetParam();
  const double rho = fc.transmittance > 0 ? 0.3 : 0.5, e = 1.0, tau = fc.transmittance;
  Material m{"furnace", Rgb::Gray(rho), Rgb::Gray(e), Rgb::Gray(tau), false, 0};
  MeshOptions mo;
  mo.element_size = 0.5;  // 40 elements
  auto w = MakeWorld(testing::MakeClosedBox(1, 1.5, 0.8, m), mo);
  ASSERT_NE(w, nullptr);
  SolveOptions opt;
  opt.method = fc.method;
  opt.tolerance = 1e-5;
  // Each element's incident power is estimated from about rays_per_element (matrix rows) or twice
  // as many (packets bounce about 1 / (1 - R) times) Monte Carlo samples.
  opt.rays_per_element = fc.method == "reflection" ? 40000 : 100000;
  opt.seed = 11;
  Result r = Solve(*w, opt);
  EXPECT_EQ(r.reason, StopReason::kConverged);
  const Solution& sol = r.solution;
  EXPECT_EQ(sol.method, fc.method);
  const double front = e / (1 - rho), back = tau * e / (1 - rho);
  double worst_front = 0, worst_back = 0;
  const size_t n = w->mesh->elements().size();
  for (size_t el = 0; el < n; ++el) {
    const Rgb& bf = sol.radiosity[Slot(static_cast<int>(el), 0)];
    const Rgb& bb = sol.radiosity[Slot(static_cast<int>(el), 1)];
    for (int c = 0; c < 3; ++c) {
      worst_front = std::max(worst_front, std::fabs(bf[c] / front - 1));
      worst_back = tau > 0 ? std::max(worst_back, std::fabs(bb[c] / back - 1))
                           : std::max(worst_back, std::fabs(bb[c]));
    }
  }
  EXPECT_LT(worst_front, 0.01) << n << " elements";
  // The back passes T of the incident power, with its Monte Carlo noise undamped (the front adds
  // E to R times it): 2 %; or exactly nothing when opaque.
  if (tau > 0) {
    EXPECT_LT(worst_back, 0.02);
  } else {
    EXPECT_EQ(worst_back, 0.0);
  }
  // Books: what is emitted is absorbed, or escapes through the walls: T / (1 - R) of it.
  const double emitted = sol.emitted_power.Sum();
  EXPECT_NEAR(sol.escaped_power.Sum() / emitted, tau / (1 - rho), 0.005);
  EXPECT_NEAR((sol.absorbed_power + sol.escaped_power).Sum() / emitted, 1, 0.005);
}

INSTANTIATE_TEST_SUITE_P(Methods, MethodsFurnaceTest,
                         ::testing::Values(MethodsFurnaceCase{"jacobi", 0},
                                           MethodsFurnaceCase{"gauss-seidel", 0},
                                           MethodsFurnaceCase{"reflection", 0},
                                           MethodsFurnaceCase{"jacobi", 0.2},
                                           MethodsFurnaceCase{"reflection", 0.2}),
                         [](const auto& param_info) {
                           std::string name = param_info.param.method == "gauss-seidel"
                                                  ? "GaussSeidel"
                                              : param_info.param.method == "jacobi" ? "Jacobi"
                                                                                    : "Reflection";
                           return name + (param_info.param.transmittance > 0 ? "Transmitting" : "");
                         });

// ---------------------------------------------------------------------------------------------
// Stopping on the residual: the returned solution's residual, recomputed here from the stored
// matrix and the scene's coefficients, is below the tolerance, and was above it one sweep earlier.
// Against this test's own solve of the same matrix, the error obeys the bound the residual gives
// (e = K e + u, so |e| <= |u| / (1 - |K|), |K| the largest power fraction a source passes on).

class MatrixResidualTest : public ::testing::TestWithParam<std::string> {};

TEST_P(MatrixResidualTest, ReturnedSolutionHasResidualBelowTolerance) {
  auto w = CoarseCornellBox();
  ASSERT_NE(w, nullptr);
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
  auto w = CoarseCornellBox();
  ASSERT_NE(w, nullptr);
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
  auto w = CoarseCornellBox();
  ASSERT_NE(w, nullptr);
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
  auto r = testing::RunCli({"solve", testing::SourcePath("scenes/cornell_box.obj"), "--out",
                            dir.path(), "--max-elements", "250", "--method", "jacobi",
                            "--max-matrix-mb", "0.01", "--quiet"});
  EXPECT_EQ(r.exit_code, kExitUsage) << r.output;
  EXPECT_NE(r.output.find("--max-matrix-mb"), std::string::npos) << r.output;
}

TEST(MatrixSolverTest, UnknownEstimatorIsRefused) {
  auto w = CoarseCornellBox();
  ASSERT_NE(w, nullptr);
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

// Area-weighted mean front radiosity of every surface.
std::vector<Rgb> SurfaceMeans(const World& w, const Solution& sol) {
  std::vector<Rgb> sum(w.scene.surfaces.size());
  std::vector<double> area(w.scene.surfaces.size());
  for (size_t e = 0; e < w.mesh->elements().size(); ++e) {
    const Element& el = w.mesh->elements()[e];
    sum[el.surface] += sol.radiosity[Slot(static_cast<int>(e), 0)] * el.area;
    area[el.surface] += el.area;
  }
  for (size_t s = 0; s < sum.size(); ++s) sum[s] = sum[s] / area[s];
  return sum;
}

TEST(MethodsTest, AllFourAgreeOnTheCornellBox) {
  auto w = CoarseCornellBox();
  ASSERT_NE(w, nullptr);
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
      Result r = Solve(*w, opt);
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
      runs.push_back(SurfaceMeans(*w, sol));
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
  auto w = CoarseCornellBox();
  ASSERT_NE(w, nullptr);
  SolveOptions opt;
  opt.method = GetParam();
  opt.rays_per_element = 300;
  opt.seed = 42;
  opt.threads = 1;
  Result a = Solve(*w, opt);
  opt.threads = 2;
  Result b = Solve(*w, opt);
  ASSERT_EQ(a.solution.radiosity.size(), b.solution.radiosity.size());
  EXPECT_EQ(a.solution.rays, b.solution.rays);
  EXPECT_GT(a.solution.rays, 0);
  for (size_t i = 0; i < a.solution.radiosity.size(); ++i) {
    ASSERT_EQ(a.solution.radiosity[i], b.solution.radiosity[i]) << "slot " << i;
  }
  EXPECT_EQ(a.solution.absorbed_power, b.solution.absorbed_power);
  EXPECT_EQ(a.solution.escaped_power, b.solution.escaped_power);
  opt.seed = 43;
  Result c = Solve(*w, opt);
  EXPECT_NE(a.solution.radiosity, c.solution.radiosity);
}

INSTANTIATE_TEST_SUITE_P(Methods, MethodsDeterminismTest, ::testing::Values("jacobi", "reflection"),
                         [](const auto& param_info) {
                           return param_info.param == "jacobi" ? "Jacobi" : "Reflection";
                         });

}  // namespace
}  // namespace radiosity
