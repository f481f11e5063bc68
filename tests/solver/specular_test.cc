// Specular and glossy surfaces (docs/guide/specular.md, transport/specular.h)
// against exact answers: the image method for a planar mirror, Lambert's formula from a mirrored
// source, a furnace of mixed glossy and diffuse walls, Fresnel's transmittance of a glass pane,
// and the view pass.
#include "solver/transport/specular.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/geometry/interpolation.h"
#include "solver/methods/registry.h"
#include "solver/results/camera.h"
#include "solver/results/render.h"
#include "solver/transport/direct_irradiance.h"
#include "solver/transport/gather.h"
#include "solver/transport/rng.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

using testing::AddRect;
using testing::MakeWorld;
using testing::MeshAndSolve;
using testing::SurfaceMeans;
using testing::World;

int AddMaterial(Scene* s, const std::string& name, double rho, double emission = 0) {
  Material m;
  m.name = name;
  m.reflectance = Rgb::Gray(rho);
  m.emission = Rgb::Gray(emission);
  s->materials.push_back(m);
  return static_cast<int>(s->materials.size()) - 1;
}

int SurfaceIndex(const Scene& s, const std::string& name) {
  for (size_t i = 0; i < s.surfaces.size(); ++i) {
    if (s.surfaces[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

// ---------------------------------------------------------------------------------------------
// The sampling pieces.

TEST(SpecularSamplingTest, ConcentricMapRoundTrips) {
  for (double a = -1; a <= 1; a += 0.125) {
    for (double b = -1; b <= 1; b += 0.125) {
      double x, y, a2, b2;
      ConcentricToDisk(a, b, &x, &y);
      EXPECT_LE(std::hypot(x, y), 1 + 1e-12);
      DiskToConcentric(x, y, &a2, &b2);
      EXPECT_NEAR(a2, a, 1e-12) << a << " " << b;
      EXPECT_NEAR(b2, b, 1e-12) << a << " " << b;
    }
  }
}

TEST(SpecularSamplingTest, FresnelAtNormalIncidenceAndTotalInternalReflection) {
  EXPECT_NEAR(FresnelDielectric(1, 1.5), 0.04, 1e-12);  // ((n - 1) / (n + 1))^2
  EXPECT_NEAR(FresnelDielectric(1, 1 / 1.5), 0.04, 1e-12);
  EXPECT_DOUBLE_EQ(FresnelDielectric(0.5, 1 / 1.5), 1);  // sin = 0.866 > 1 / 1.5
  EXPECT_DOUBLE_EQ(FresnelDielectric(0.0, 1.5), 1);      // grazing
  EXPECT_DOUBLE_EQ(FresnelDielectric(0.7, 1), 0);
}

// The glossy lobe's density in projected solid angle is symmetric in incident and outgoing
// directions (reciprocity): histogram the outgoing disk cell of many samples from the centre
// of cell A, and from cell B's centre; the mass A sends to B equals what B sends to A (cells of
// equal projected solid angle), within the counts' noise.
TEST(SpecularSamplingTest, GlossyLobeIsReciprocal) {
  const Vec3 n(0, 0, 1);
  const int kCells = 8;  // Square cells of the concentric map: equal projected solid angle.
  auto cell_of = [&](const Vec3& d) {
    double a, b;
    DiskToConcentric(d.x, d.y, &a, &b);
    const int i = std::clamp(static_cast<int>((a + 1) / 2 * kCells), 0, kCells - 1);
    const int j = std::clamp(static_cast<int>((b + 1) / 2 * kCells), 0, kCells - 1);
    return j * kCells + i;
  };
  // The direction towards which light travels when it arrives from the centre of cell (i, j).
  auto arriving = [&](int i, int j) {
    double x, y;
    ConcentricToDisk((i + 0.5) / kCells * 2 - 1, (j + 0.5) / kCells * 2 - 1, &x, &y);
    return -Vec3(x, y, std::sqrt(std::max(0.0, 1 - x * x - y * y)));
  };
  const int kSamples = 400000;
  Rng rng(7);
  auto share = [&](int from_i, int from_j, int to_cell) {
    int hits = 0;
    const Vec3 dir = arriving(from_i, from_j);
    for (int k = 0; k < kSamples; ++k) {
      hits += cell_of(GlossyDirection(dir, n, 4, rng.Uniform(), rng.Uniform())) == to_cell;
    }
    return static_cast<double>(hits) / kSamples;
  };
  // Near normal and near grazing, where an unnormalised lobe would lose most.
  const int pairs[][4] = {{3, 4, 1, 3}, {0, 0, 6, 2}, {7, 3, 2, 2}};
  for (const auto& p : pairs) {
    const double ab = share(p[0], p[1], p[3] * kCells + p[2]);
    const double ba = share(p[2], p[3], p[1] * kCells + p[0]);
    EXPECT_GT(ab, 0.002);
    EXPECT_NEAR(ab, ba, 5 * std::sqrt(ab / kSamples) + 1e-4)
        << "(" << p[0] << "," << p[1] << ") <-> (" << p[2] << "," << p[3] << ")";
  }
  // Every sample leaves above the surface.
  for (int k = 0; k < 10000; ++k) {
    const Vec3 d =
        GlossyDirection(Normalize(Vec3(0.99, 0, -0.1)), n, 2, rng.Uniform(), rng.Uniform());
    EXPECT_GE(d.z, 0);
  }
}

TEST(SpecularSamplingTest, BranchesCarryExactlyTheSpecularParts) {
  SpecularRule rule;
  rule.mirror = Rgb(0.1, 0.2, 0.0);
  rule.glossy = Rgb(0.2, 0.1, 0.3);
  rule.exponent = 50;
  rule.glass = Rgb(0.4, 0.5, 0.6);
  for (bool refracts : {false, true}) {
    for (bool front : {true, false}) {
      rule.refracts = refracts;
      rule.front = front;
      for (double c : {1.0, 0.7, 0.2}) {
        const Vec3 dir(std::sqrt(1 - c * c), 0, -c);
        SpecularBranch b[3];
        const int count = ScatterSpecular(rule, dir, Vec3(0, 0, 1), 0.3, 0.6, b);
        Rgb sum;
        for (int k = 0; k < count; ++k) sum += b[k].weight;
        for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(sum[ch], rule.Total()[ch], 1e-15);
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Zonal transport.

// A room [0,1] x [0,1] x [0,1] lit by a square lamp under its ceiling, whose wall x = 1 is an
// ideal mirror of reflectance `mirror` (when `mirror` > 0), or (mirror == 0) the room mirrored
// about x = 1 without that wall: [0,2] x [0,1] x [0,1] with the lamp and its image. Floor 0.5,
// ceiling 0.7, walls 0.4.
Scene MirrorRoom(double mirror) {
  Scene s;
  const int floor = AddMaterial(&s, "floor", 0.5);
  const int ceiling = AddMaterial(&s, "ceiling", 0.7);
  const int wall = AddMaterial(&s, "wall", 0.4);
  const int lamp = AddMaterial(&s, "lamp", 0, 10);
  const double lx = mirror > 0 ? 1 : 2;
  AddRect(&s, "floor", floor, Vec3(0, 0, 0), Vec3(lx, 0, 0), Vec3(0, 1, 0));
  AddRect(&s, "ceiling", ceiling, Vec3(0, 0, 1), Vec3(0, 1, 0), Vec3(lx, 0, 0));
  AddRect(&s, "x0", wall, Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1));
  AddRect(&s, "y0", wall, Vec3(0, 0, 0), Vec3(0, 0, 1), Vec3(lx, 0, 0));
  AddRect(&s, "y1", wall, Vec3(0, 1, 0), Vec3(lx, 0, 0), Vec3(0, 0, 1));
  // The lamp faces down just under the ceiling, off-centre so that the mirror matters.
  AddRect(&s, "lamp", lamp, Vec3(0.2, 0.4, 0.99), Vec3(0, 0.2, 0), Vec3(0.2, 0, 0));
  if (mirror > 0) {
    Material m;
    m.name = "mirror";
    m.mirror = Rgb::Gray(mirror);
    s.materials.push_back(m);
    AddRect(&s, "x1", static_cast<int>(s.materials.size()) - 1, Vec3(1, 0, 0), Vec3(0, 0, 1),
            Vec3(0, 1, 0));
  } else {
    AddRect(&s, "x1", wall, Vec3(2, 0, 0), Vec3(0, 0, 1), Vec3(0, 1, 0));
    AddRect(&s, "lamp_image", lamp, Vec3(1.6, 0.4, 0.99), Vec3(0, 0.2, 0), Vec3(0.2, 0, 0));
  }
  return s;
}

// Surface means of the mirrored room's left half: its floor, ceiling and y walls are twice as
// long, and by symmetry their means are those of the halves.
TEST(SpecularTransportTest, PlanarMirrorGivesTheImageRoom) {
  SolveOptions options = testing::Budget(4000, 1e-4);
  ASSERT_OK_AND_ASSIGN(auto mirrored, MeshAndSolve(MirrorRoom(1), 0.1, options));
  ASSERT_OK_AND_ASSIGN(auto image, MeshAndSolve(MirrorRoom(0), 0.1, options));
  const Scene& ms = mirrored.world->scene;
  const Scene& is = image.world->scene;
  const auto m_means = SurfaceMeans(*mirrored.world, mirrored.run.solution);
  const auto i_means = SurfaceMeans(*image.world, image.run.solution);
  for (const char* name : {"floor", "ceiling", "x0", "y0", "y1"}) {
    const double m = m_means[SurfaceIndex(ms, name)].g;
    const double i = i_means[SurfaceIndex(is, name)].g;
    EXPECT_NEAR(m / i, 1, 0.015) << name << ": mirror room " << m << ", image room " << i;
  }
  // The mirror keeps no diffuse radiosity, and with reflectance 1 nothing is absorbed there:
  // the books balance exactly, and nothing escapes a closed room but the difference between the
  // direct step's computed light (straight and by the lamp's image) and the rays' share of it,
  // here only the quadrature's error (every ray reaches a diffuse part by one of those paths).
  EXPECT_EQ(m_means[SurfaceIndex(ms, "x1")].g, 0);
  testing::ExpectBooksBalance(mirrored.run.solution, 1e-9);
  EXPECT_NEAR(mirrored.run.solution.escaped_power.g / mirrored.run.solution.emitted_power.g, 0,
              1e-6);
}

// Per element: the floor's elements under the lamp's side (x < 0.5) and near the mirror
// (x > 0.5) against the image room's same elements.
TEST(SpecularTransportTest, MirrorRoomMatchesTheImageRoomPerBand) {
  SolveOptions options = testing::Budget(4000, 1e-4);
  ASSERT_OK_AND_ASSIGN(auto mirrored, MeshAndSolve(MirrorRoom(1), 0.1, options));
  ASSERT_OK_AND_ASSIGN(auto image, MeshAndSolve(MirrorRoom(0), 0.1, options));
  auto bands = [](const testing::SolvedWorld& w) {
    const int floor = SurfaceIndex(w.world->scene, "floor");
    std::vector<double> sum(4, 0), area(4, 0);
    const Mesh& mesh = *w.world->mesh;
    for (size_t e = 0; e < mesh.elements().size(); ++e) {
      const Element& el = mesh.elements()[e];
      if (el.surface != floor) continue;
      const double x = el.centroid.x;
      if (x >= 1) continue;
      const int band = std::min(3, static_cast<int>(x * 4));
      sum[band] += w.run.solution.radiosity[Slot(static_cast<int>(e), 0)].g * el.area;
      area[band] += el.area;
    }
    for (int b = 0; b < 4; ++b) sum[b] /= area[b];
    return sum;
  };
  const auto m = bands(mirrored), i = bands(image);
  for (int b = 0; b < 4; ++b) EXPECT_NEAR(m[b] / i[b], 1, 0.03) << "band " << b;
}

TEST(SpecularTransportTest, BooksBalanceWithAPartialMirror) {
  for (const std::string method : {"progressive", "reflection"}) {
    SolveOptions options = testing::Budget(500, 1e-4);
    options.method = method;
    ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(MirrorRoom(0.75), 0.2, options));
    testing::ExpectBooksBalance(solved.run.solution, method == "progressive" ? 1e-9 : 0.02);
    EXPECT_GT(solved.run.solution.absorbed_power.g, 0);
  }
}

// Two closed unit rooms side by side: on the left a bright lamp (exitance 100) in a diffuse
// room; on the right a dim lamp (exitance 10) in a room whose wall x = 3 is a mirror of
// reflectance 0.9, and a mirror of 0.3 x 0.3 standing on its floor in the plane x = 2.5 (facing
// +x), which cuts the dim lamp in half (only its part in front has an image).
Scene TwoRooms() {
  Scene s;
  const int wall = AddMaterial(&s, "wall", 0.5);
  const int bright = AddMaterial(&s, "bright", 0, 100);
  const int dim = AddMaterial(&s, "dim", 0, 10);
  Material m;
  m.name = "mirror";
  m.mirror = Rgb::Gray(0.9);
  s.materials.push_back(m);
  const int mirror = static_cast<int>(s.materials.size()) - 1;
  for (int room = 0; room < 2; ++room) {
    const double x0 = 2.0 * room;
    const std::string r = absl::StrCat("room", room, "_");
    AddRect(&s, r + "floor", wall, Vec3(x0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
    AddRect(&s, r + "ceiling", wall, Vec3(x0, 0, 1), Vec3(0, 1, 0), Vec3(1, 0, 0));
    AddRect(&s, r + "x0", wall, Vec3(x0, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1));
    AddRect(&s, r + "y0", wall, Vec3(x0, 0, 0), Vec3(0, 0, 1), Vec3(1, 0, 0));
    AddRect(&s, r + "y1", wall, Vec3(x0, 1, 0), Vec3(1, 0, 0), Vec3(0, 0, 1));
    AddRect(&s, r + "x1", room == 0 ? wall : mirror, Vec3(x0 + 1, 0, 0), Vec3(0, 0, 1),
            Vec3(0, 1, 0));
    AddRect(&s, r + "lamp", room == 0 ? bright : dim, Vec3(x0 + 0.4, 0.4, 0.99), Vec3(0, 0.2, 0),
            Vec3(0.2, 0, 0));
  }
  AddRect(&s, "stand_mirror", mirror, Vec3(2.5, 0.35, 0), Vec3(0, 0.3, 0), Vec3(0, 0, 0.3));
  return s;
}

// TwoRooms is closed: whatever is not yet shot, nothing escapes but the difference between the
// hybrid direct step's computed light and the rays' share of it, after every step. Each lamp's
// credit is its own (a share of both lamps' credit in proportion to the emission shot would
// book the bright lamp's shot as the dim one's, per cent of the emission).
TEST(SpecularTransportTest, ClosedRoomsEscapeNothingAtEveryStep) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w, testing::MakeWorld(TwoRooms(), 0.1));
  SolveOptions options = testing::Budget(1000, 1e-4);
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Solver> solver,
                       CreateSolver(w->scene, *w->mesh, *w->vis, options, nullptr));
  for (int step = 0; step < 6; ++step) {
    ASSERT_OK_AND_ASSIGN(bool more, solver->Step());
    const Solution sol = solver->Final();
    testing::ExpectBooksBalance(sol, 1e-9);
    // (The difference is about 3e-5 here; one credit ratio for both lamps makes it 6e-4.)
    EXPECT_LT(std::fabs(sol.escaped_power.g), 2e-4 * sol.emitted_power.g) << "step " << step;
    EXPECT_LE(sol.absorbed_power.g, sol.emitted_power.g) << "step " << step;
    EXPECT_GE(sol.unshot_fraction, 0);
    EXPECT_LE(sol.unshot_fraction, 1 + 1e-9) << "step " << step;
    if (!more) break;
  }
}

// A unit square lamp (z = 0, facing up, exitance 1) under a ceiling mirror (z = 1, reflectance
// 0.8, facing down) beside a unit square receiver of reflectance `receiver_rho` on the floor (x
// in [2, 3]): the receiver sees the lamp only in the mirror, as a parallel square at height 2.
// The mirror is one face, or tiles x tiles.
Scene LampUnderMirror(double receiver_rho, int tiles = 1) {
  Scene s;
  const int lamp = AddMaterial(&s, "lamp", 0, 1);
  const int receiver = AddMaterial(&s, "receiver", receiver_rho);
  Material m;
  m.name = "mirror";
  m.mirror = Rgb::Gray(0.8);
  s.materials.push_back(m);
  AddRect(&s, "lamp", lamp, Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  AddRect(&s, "receiver", receiver, Vec3(2, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  for (int i = 0; i < tiles; ++i) {
    for (int j = 0; j < tiles; ++j) {
      AddRect(&s, "mirror", 2, Vec3(-1 + 5.0 * i / tiles, -1 + 3.0 * j / tiles, 1),
              Vec3(0, 3.0 / tiles, 0), Vec3(5.0 / tiles, 0, 0));
    }
  }
  return s;
}

// The factor from the point (2.5, 0.5, 0), facing up, to the lamp's image [0,1] x [0,1] at height
// 2: two corner rectangles 2.5 x 0.5 less two 1.5 x 0.5 (Lambert, the B-3 corner case).
double ImageFactorAtSensor() {
  return 2 * (testing::PointUnderCorner(2.5, 0.5, 2) - testing::PointUnderCorner(1.5, 0.5, 2));
}

// The area-mean irradiance of the surface "receiver" (SolveOptions::track_direct).
double MeanReceiverIrradiance(const testing::SolvedWorld& solved) {
  const Mesh& mesh = *solved.world->mesh;
  const int receiver = SurfaceIndex(solved.world->scene, "receiver");
  double power = 0, area = 0;
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    if (mesh.elements()[e].surface != receiver) continue;
    power +=
        solved.run.solution.irradiance[Slot(static_cast<int>(e), 0)].g * mesh.elements()[e].area;
    area += mesh.elements()[e].area;
  }
  return power / area;
}

// LampUnderMirror with a black receiver: its mean irradiance is 0.8 x F(receiver -> image)
// (Lambert's formula integrated: the parallel-rectangles closed form). The default direct step
// computes it by the image method, exactly (the whole image is seen through the mirror), with
// few rays; shot by rays instead (--direct shot), to their noise.
TEST(SpecularTransportTest, SourceSeenInAMirrorLightsByLambertFromItsImage) {
  Scene s = LampUnderMirror(0);
  const double expected = 0.8 * testing::ParallelRectangles(2, 3, 0, 1, 0, 1, 0, 1, 2);
  for (const std::string direct : {"computed", "shot"}) {
    SolveOptions options = testing::Budget(direct == "computed" ? 100 : 20000, 1e-4);
    options.track_direct = true;
    options.direct = direct;
    ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(s, 0.25, options));
    const double mean = MeanReceiverIrradiance(solved);
    EXPECT_NEAR(mean / expected, 1, direct == "computed" ? 1e-5 : 0.01)
        << direct << ": " << mean << " vs " << expected;
    // Light by way of a mirror is not straight from the emitter (what --refine re-gathers).
    double straight = 0;
    const Mesh& mesh = *solved.world->mesh;
    for (size_t e = 0; e < mesh.elements().size(); ++e) {
      if (mesh.elements()[e].surface == SurfaceIndex(solved.world->scene, "receiver")) {
        straight += solved.run.solution.direct_irradiance[Slot(static_cast<int>(e), 0)].g;
      }
    }
    EXPECT_EQ(straight, 0) << direct;
    testing::ExpectBooksBalance(solved.run.solution, 1e-9);
  }
}

// The same lamp and mirror, a sensor on the floor at (2.5, 0.5): its direct light comes from the
// lamp's image by the image method (DirectOptions::mirror_images), exactly Lambert's point-to-
// rectangle factor times 0.8, and the gathered rays that see the lamp in the mirror do not count
// it again.
TEST(SpecularTransportTest, SensorSeesTheLampsImageExactly) {
  Scene s = LampUnderMirror(0);
  ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(s, 0.25, testing::Budget(100)));
  const World& w = *solved.world;
  GatherOptions options;
  options.samples = 4096;
  const SensorIrradiance got =
      GatherIrradiance(w.scene, *w.mesh, *w.vis, solved.run.solution,
                       {SensorPoint{Vec3(2.5, 0.5, 0), Vec3(0, 0, 1), ""}}, options, StopToken());
  const double f = ImageFactorAtSensor();
  EXPECT_NEAR(got.irradiance[0].g / (0.8 * f), 1, 1e-6) << got.irradiance[0].g;
}

// LampUnderMirror with a lamp of 72 faces and a mirror of 64 facets, each of a reflectance 1e-5
// above the one before (0.8 to 0.8005), so each is a mirror plane of its own (DirectIrradiance
// groups coplanar facets of one reflectance): more emitter-plane pairs than kMaxMirrorImages,
// those left out (the last facets') among the ones the receiver sees.
Scene ManyFacedLampUnderMirror() {
  Scene s;
  const int lamp = AddMaterial(&s, "lamp", 0, 1);
  const int black = AddMaterial(&s, "receiver", 0);
  for (int i = 0; i < 9; ++i) {
    for (int j = 0; j < 8; ++j) {
      AddRect(&s, "lamp", lamp, Vec3(i / 9.0, j / 8.0, 0), Vec3(1 / 9.0, 0, 0),
              Vec3(0, 1 / 8.0, 0));
    }
  }
  AddRect(&s, "receiver", black, Vec3(2, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  // The columns x in [0.875, 2.125] (i = 3, 4), where the receiver sees the lamp, come last:
  // some of their pairs are the ones left out.
  for (int i : {0, 1, 2, 5, 6, 7, 3, 4}) {
    for (int j = 0; j < 8; ++j) {
      Material m;
      m.name = absl::StrCat("mirror", s.materials.size());
      m.mirror = Rgb::Gray(0.8 + 1e-5 * (static_cast<double>(s.materials.size()) - 2));
      s.materials.push_back(m);
      AddRect(&s, m.name, static_cast<int>(s.materials.size()) - 1,
              Vec3(-1 + 5 * i / 8.0, -1 + 3 * j / 8.0, 1), Vec3(0, 3 / 8.0, 0),
              Vec3(5 / 8.0, 0, 0));
    }
  }
  return s;
}

// ManyFacedLampUnderMirror: the images made are still found when the gathered rays see the lamp
// in the mirror (none counted twice), and the rest is gathered: the sensor stays at Lambert's
// value from the image.
TEST(SpecularTransportTest, ManyMirrorImagesAreNeverCountedTwice) {
  ASSERT_OK_AND_ASSIGN(auto solved,
                       MeshAndSolve(ManyFacedLampUnderMirror(), 0.5, testing::Budget(20)));
  const World& w = *solved.world;
  GatherOptions options;
  options.samples = 16384;
  const PointGather gather(w.scene, *w.mesh, *w.vis, solved.run.solution, options, 1);
  ASSERT_EQ(gather.direct().images().size(), static_cast<size_t>(kMaxMirrorImages));
  int64_t rays = 0;
  const Rgb h = gather.At(Vec3(2.5, 0.5, 0) - w.mesh->origin(), Vec3(0, 0, 1), 0, nullptr, &rays);
  const double f = ImageFactorAtSensor();
  EXPECT_NEAR(h.g / (0.8 * f), 1, 0.03) << h.g;
}

// The same in the solve: the direct step computes the images it has room for, the rays carry
// the light of the pairs left out (and only those): the receiver's mean irradiance is still
// Lambert's from the whole image.
TEST(SpecularTransportTest, MirrorImagesLeftOutAreShot) {
  SolveOptions options = testing::Budget(4000, 1e-4);
  options.track_direct = true;
  ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(ManyFacedLampUnderMirror(), 0.5, options));
  const World& w = *solved.world;
  DirectOptions d;
  d.mirror_images = true;
  const DirectIrradiance direct(*w.mesh, *w.vis, d,
                                static_cast<int64_t>(w.mesh->elements().size()));
  ASSERT_EQ(direct.images().size(), static_cast<size_t>(kMaxMirrorImages));
  const double mean = MeanReceiverIrradiance(solved);
  const double expected = 0.8 * testing::ParallelRectangles(2, 3, 0, 1, 0, 1, 0, 1, 2);
  // Each image seen through one small facet: the visible fractions' ratio estimates (a few
  // shadow rays each) are good to about a per cent in all (README).
  EXPECT_NEAR(mean / expected, 1, 0.03) << mean << " vs " << expected;
  testing::ExpectBooksBalance(solved.run.solution, 1e-9);
}

// A mirror modelled as many coplanar faces (8 x 8 tiles) is one mirror plane: one image of the
// lamp, seen whole through the tiles, and the receiver's irradiance is Lambert's exactly.
TEST(SpecularTransportTest, TiledMirrorIsOnePlane) {
  Scene s = LampUnderMirror(0, 8);
  SolveOptions options = testing::Budget(100, 1e-4);
  options.track_direct = true;
  ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(s, 0.5, options));
  const World& w = *solved.world;
  DirectOptions d;
  d.mirror_images = true;
  const DirectIrradiance direct(*w.mesh, *w.vis, d, 1);
  EXPECT_EQ(direct.images().size(), 1u);
  const double mean = MeanReceiverIrradiance(solved);
  const double expected = 0.8 * testing::ParallelRectangles(2, 3, 0, 1, 0, 1, 0, 1, 2);
  EXPECT_NEAR(mean / expected, 1, 1e-5) << mean << " vs " << expected;
}

// Sky light through a window: the solve passes what reaches the pane on into the room
// diffusely, and a sensor gathers it there, not also through the pane from the sky (which would
// count it twice). A unit box with a thin-glass ceiling (0.9) under a uniform sky: the floor
// sensor at the centre reads what the floor's central elements received in the solve.
TEST(SpecularTransportTest, SkyThroughGlassIsCountedOnceAtSensors) {
  Material wall;
  wall.name = "wall";
  wall.reflectance = Rgb::Gray(0.5);
  Scene s = testing::MakeClosedBox(1, 1, 1, wall);
  Material pane;
  pane.name = "pane";
  pane.glass = Rgb::Gray(0.9);
  s.materials.push_back(pane);
  s.surfaces[SurfaceIndex(s, "z1")].material = 1;
  SolveOptions options = testing::Budget(2000, 1e-4);
  options.sky.model = "uniform";
  options.sky.irradiance = Rgb::Gray(100);
  options.sky.up = Vec3(0, 0, 1);
  options.track_direct = true;
  ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(s, 0.1, options));
  const World& w = *solved.world;
  const int floor = SurfaceIndex(w.scene, "z0");
  double power = 0, area = 0;
  for (size_t e = 0; e < w.mesh->elements().size(); ++e) {
    const Element& el = w.mesh->elements()[e];
    if (el.surface != floor || std::fabs(el.centroid.x - 0.5) > 0.2 ||
        std::fabs(el.centroid.y - 0.5) > 0.2) {
      continue;
    }
    power += solved.run.solution.irradiance[Slot(static_cast<int>(e), 0)].g * el.area;
    area += el.area;
  }
  GatherOptions g;
  g.samples = 16384;
  g.sky = options.sky;
  const SensorIrradiance got =
      GatherIrradiance(w.scene, *w.mesh, *w.vis, solved.run.solution,
                       {SensorPoint{Vec3(0.5, 0.5, 0), Vec3(0, 0, 1), ""}}, g, StopToken());
  EXPECT_NEAR(got.irradiance[0].g / (power / area), 1, 0.05)
      << got.irradiance[0].g << " vs " << power / area;
}

// A closed box, every wall emitting 1, total reflectance 0.5 everywhere: two walls diffuse, two
// a diffuse 0.2 with a glossy 0.3 lobe, one a diffuse 0.1 with a mirror 0.4, one glossy alone.
// The irradiance is H = E / (1 - rho) = 2 everywhere, so each wall's diffuse radiosity is
// E + R_d H.
TEST(SpecularTransportTest, MixedGlossyFurnaceIsUniform) {
  Material diffuse;
  diffuse.name = "diffuse";
  diffuse.reflectance = Rgb::Gray(0.5);
  diffuse.emission = Rgb::Gray(1);
  Scene s = testing::MakeClosedBox(1, 1.5, 0.8, diffuse);
  Material glossy = diffuse;
  glossy.name = "glossy";
  glossy.reflectance = Rgb::Gray(0.2);
  glossy.glossy = Rgb::Gray(0.3);
  glossy.glossy_exponent = 20;
  Material mirror = diffuse;
  mirror.name = "mirror";
  mirror.reflectance = Rgb::Gray(0.1);
  mirror.mirror = Rgb::Gray(0.4);
  Material shiny = diffuse;
  shiny.name = "shiny";
  shiny.reflectance = Rgb();
  shiny.glossy = Rgb::Gray(0.5);
  shiny.glossy_exponent = 3;
  for (const Material& m : {glossy, mirror, shiny}) s.materials.push_back(m);
  s.surfaces[SurfaceIndex(s, "x0")].material = 1;
  s.surfaces[SurfaceIndex(s, "y1")].material = 1;
  s.surfaces[SurfaceIndex(s, "z0")].material = 2;
  s.surfaces[SurfaceIndex(s, "z1")].material = 3;
  SolveOptions options = testing::Budget(3000, 1e-4);
  ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(s, 0.25, options));
  const Scene& scene = solved.world->scene;
  const Mesh& mesh = *solved.world->mesh;
  const auto means = SurfaceMeans(*solved.world, solved.run.solution);
  for (size_t i = 0; i < scene.surfaces.size(); ++i) {
    const double rd = scene.materials[scene.surfaces[i].material].reflectance.g;
    const double expected = 1 + rd * 2;
    EXPECT_NEAR(means[i].g / expected, 1, 0.01) << scene.surfaces[i].name;
    for (size_t e = 0; e < mesh.elements().size(); ++e) {
      if (mesh.elements()[e].surface != static_cast<int>(i)) continue;
      EXPECT_NEAR(solved.run.solution.radiosity[Slot(static_cast<int>(e), 0)].g / expected, 1, 0.06)
          << scene.surfaces[i].name << " element " << e;
    }
  }
  testing::ExpectBooksBalance(solved.run.solution, 1e-9);
}

// A unit square lamp (z = 0, facing up) and a black unit square receiver facing it at z = 4,
// with a thin pane of glass (index 1.5) between them at z = 2. Every ray crosses the pane
// within 20 degrees of its normal, where Fresnel's F is 0.04 to 3 digits, so the receiver gets
// T = (1 - F) / (1 + F) = 0.923 of the parallel-rectangles closed form.
Scene PaneScene(bool pane, bool refracting_slab = false) {
  Scene s;
  const int lamp = AddMaterial(&s, "lamp", 0, 1);
  const int black = AddMaterial(&s, "receiver", 0);
  AddRect(&s, "lamp", lamp, Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));
  AddRect(&s, "receiver", black, Vec3(0, 0, 4), Vec3(0, 1, 0), Vec3(1, 0, 0));
  if (pane) {
    Material g;
    g.name = "glass";
    g.glass = Rgb::Gray(1);
    g.ior = 1.5;
    g.refracts = refracting_slab;
    s.materials.push_back(g);
    const int glass = static_cast<int>(s.materials.size()) - 1;
    if (!refracting_slab) {
      AddRect(&s, "pane", glass, Vec3(-1, -1, 2), Vec3(3, 0, 0), Vec3(0, 3, 0));
    } else {
      // A slab 0.1 thick: its faces face out of the glass (air on the front).
      AddRect(&s, "pane_bottom", glass, Vec3(-1, -1, 1.95), Vec3(0, 3, 0), Vec3(3, 0, 0));
      AddRect(&s, "pane_top", glass, Vec3(-1, -1, 2.05), Vec3(3, 0, 0), Vec3(0, 3, 0));
    }
  }
  return s;
}

TEST(SpecularTransportTest, ThinGlassPanePassesFresnelsTransmittance) {
  const double f0 = 0.04;
  const double t_sheet = (1 - f0) / (1 + f0);
  const double unblocked = testing::ParallelRectangles(0, 1, 0, 1, 0, 1, 0, 1, 4);
  SolveOptions options = testing::Budget(40000, 1e-4);
  options.track_direct = true;
  ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(PaneScene(true), 0.5, options));
  EXPECT_NEAR(MeanReceiverIrradiance(solved) / (t_sheet * unblocked), 1, 0.01);
  // A slab of two refracting faces passes (1 - F)^2 straight on, plus the light reflected
  // inside it twice (F^2 (1 - F)^2 ...): the sheet formula again. Refraction shifts each ray
  // sideways so that, near the normal, the receiver seems closer by d (1 - 1 / n) (the
  // apparent depth of a slab of thickness d = 0.1).
  ASSERT_OK_AND_ASSIGN(auto slab, MeshAndSolve(PaneScene(true, true), 0.5, options));
  const double closer = testing::ParallelRectangles(0, 1, 0, 1, 0, 1, 0, 1, 4 - 0.1 / 3);
  EXPECT_NEAR(MeanReceiverIrradiance(slab) / (t_sheet * closer), 1, 0.01);
  EXPECT_GT(MeanReceiverIrradiance(slab) / (t_sheet * unblocked), 1.01);
  testing::ExpectBooksBalance(slab.run.solution, 1e-9);
}

// Hostile: 40 thin panes between the lamp and the receiver split every ray into a tree of
// reflected and passed branches; each ray traces at most kMaxSpecularSegments of them, what it
// gives up is booked as absorbed, and the books still balance. The receiver gets T^40 of the
// unblocked light, less what the cut gave up: between 0.9 and 1.4 times T^40 (inter-pane
// reflections add light the sheet formula per pane does not count).
TEST(SpecularTransportTest, StackOfPanesStaysBoundedAndBalanced) {
  Scene s = PaneScene(false);
  Material g;
  g.name = "glass";
  g.glass = Rgb::Gray(1);
  s.materials.push_back(g);
  const int glass = static_cast<int>(s.materials.size()) - 1;
  for (int k = 0; k < 40; ++k) {
    AddRect(&s, "pane" + std::to_string(k), glass, Vec3(-1, -1, 0.5 + 0.075 * k), Vec3(3, 0, 0),
            Vec3(0, 3, 0));
  }
  SolveOptions options = testing::Budget(200, 1e-4);
  options.track_direct = true;
  ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(s, 1.5, options));
  testing::ExpectBooksBalance(solved.run.solution, 1e-9);
  const double t = std::pow((1 - 0.04) / (1 + 0.04), 40);
  const double ratio =
      MeanReceiverIrradiance(solved) / (t * testing::ParallelRectangles(0, 1, 0, 1, 0, 1, 0, 1, 4));
  EXPECT_GT(ratio, 0.9);
  EXPECT_LT(ratio, 1.4);
}

// ---------------------------------------------------------------------------------------------
// The view pass.

// Radiance seen straight through the pane at the lamp (B = 1 exactly, a black emitter): the
// pixel at the image centre is T / pi with T the sheet's transmittance at normal incidence.
TEST(SpecularViewTest, GlassPaneInTheViewPass) {
  Scene s = PaneScene(true);
  ASSERT_OK_AND_ASSIGN(auto world, MakeWorld(s, 0.5));
  Solution sol;
  sol.radiosity.assign(2 * world->mesh->elements().size(), Rgb());
  const int lamp = SurfaceIndex(world->scene, "lamp");
  for (size_t e = 0; e < world->mesh->elements().size(); ++e) {
    if (world->mesh->elements()[e].surface == lamp) sol.radiosity[Slot(e, 0)] = Rgb::Gray(1);
  }
  const auto corners = CornerRadiosity(*world->mesh, sol);
  ASSERT_OK_AND_ASSIGN(Camera cam, ParseCamera("eye=0.5,0.5,3.5 look=0.5,0.5,0 up=0,1,0 fov=10",
                                               DefaultCamera(*world->mesh)));
  const SpecularTable specular(world->scene);
  const Image image =
      RenderImage(*world->mesh, *world->vis, sol, corners, cam, 9, 9, 1, nullptr, &specular);
  const double f0 = 0.04;
  const float centre = image.rgb[3 * (4 * 9 + 4) + 1];
  EXPECT_NEAR(centre * kPi, (1 - f0) / (1 + f0), 1e-4);
  // Without the table the pane is an opaque black sheet.
  const Image opaque = RenderImage(*world->mesh, *world->vis, sol, corners, cam, 9, 9, 1);
  EXPECT_EQ(opaque.rgb[3 * (4 * 9 + 4) + 1], 0);
}

// A mirror of reflectance 0.6 seen at 45 degrees shows the lamp (B = 1): 0.6 / pi.
TEST(SpecularViewTest, MirrorShowsWhatItFaces) {
  Scene s;
  const int lamp = AddMaterial(&s, "lamp", 0, 1);
  Material m;
  m.name = "mirror";
  m.mirror = Rgb::Gray(0.6);
  s.materials.push_back(m);
  // Mirror in z = 0 facing up; the lamp in x = -2 facing +x; the eye at (2, 0.5, 2).
  AddRect(&s, "mirror", 1, Vec3(-1, -1, 0), Vec3(3, 0, 0), Vec3(0, 3, 0));
  AddRect(&s, "lamp", lamp, Vec3(-2, -2, 0.5), Vec3(0, 5, 0), Vec3(0, 0, 3));
  ASSERT_OK_AND_ASSIGN(auto world, MakeWorld(s, 0.5));
  Solution sol;
  sol.radiosity.assign(2 * world->mesh->elements().size(), Rgb());
  const int lamp_surface = SurfaceIndex(world->scene, "lamp");
  for (size_t e = 0; e < world->mesh->elements().size(); ++e) {
    if (world->mesh->elements()[e].surface == lamp_surface) {
      sol.radiosity[Slot(e, 0)] = Rgb::Gray(1);
    }
  }
  const auto corners = CornerRadiosity(*world->mesh, sol);
  ASSERT_OK_AND_ASSIGN(Camera cam, ParseCamera("eye=1,0.5,1 look=0,0.5,0 up=0,0,1 fov=5",
                                               DefaultCamera(*world->mesh)));
  const SpecularTable specular(world->scene);
  const Image image =
      RenderImage(*world->mesh, *world->vis, sol, corners, cam, 5, 5, 1, nullptr, &specular);
  EXPECT_NEAR(image.rgb[3 * (2 * 5 + 2)] * kPi, 0.6, 1e-5);
}

// The final gather: a dark receiver (reflectance 0.05) lit only by the lamp's image in a 0.8
// mirror. At the pixel looking straight down at (2.5, 0.5) the radiance is 0.05 H / pi with
// H = 0.8 F (Lambert from the image; what the receiver reflects back to itself through the
// mirror adds under 0.5 %), from the point itself, however coarse the elements (2 x 2 here).
TEST(SpecularViewTest, FinalGatherReadsTheLightAtThePixel) {
  Scene s = LampUnderMirror(0.05);
  ASSERT_OK_AND_ASSIGN(auto solved, MeshAndSolve(s, 0.5, testing::Budget(2000)));
  const World& w = *solved.world;
  const auto corners = CornerRadiosity(*w.mesh, solved.run.solution);
  ASSERT_OK_AND_ASSIGN(Camera cam, ParseCamera("eye=2.5,0.5,0.9 look=2.5,0.5,0 up=0,1,0 fov=2",
                                               DefaultCamera(*w.mesh)));
  const SpecularTable specular(w.scene);
  GatherOptions g;
  g.samples = 4096;
  const PointGather gather(w.scene, *w.mesh, *w.vis, solved.run.solution, g, 9);
  RenderOptions options;
  options.samples_per_pixel = 1;
  options.specular = &specular;
  options.gather = &gather;
  int progress_calls = 0;
  double last = 0;
  std::mutex progress_mutex;
  options.progress = [&](double f) {  // Once per row, from the rendering threads.
    std::lock_guard<std::mutex> lock(progress_mutex);
    ++progress_calls;
    last = std::max(last, f);
  };
  const Image image =
      RenderImage(*w.mesh, *w.vis, solved.run.solution, corners, cam, 3, 3, options);
  const double f = ImageFactorAtSensor();
  const double expected = 0.05 * 0.8 * f / kPi;
  EXPECT_NEAR(image.rgb[3 * (1 * 3 + 1) + 1] / expected, 1, 0.01);
  EXPECT_EQ(progress_calls, 3);
  EXPECT_EQ(last, 1);
}

// Without specular surfaces the view pass is today's rendering: the same image with the
// scene's (empty) table as without, and each pixel centre the interpolated radiosity / pi of
// what its primary ray hits.
TEST(SpecularViewTest, DiffuseSceneRendersAsBefore) {
  ASSERT_OK_AND_ASSIGN(auto world, testing::CornellBoxWorld(400));
  ASSERT_OK_AND_ASSIGN(auto run, testing::Solve(*world, testing::Budget(100)));
  const auto corners = CornerRadiosity(*world->mesh, run.solution);
  const Camera cam = DefaultCamera(*world->mesh);
  const SpecularTable specular(world->scene);
  ASSERT_TRUE(specular.empty());
  const Image with = RenderImage(*world->mesh, *world->vis, run.solution, corners, cam, 24, 18, 4,
                                 nullptr, &specular);
  const Image without = RenderImage(*world->mesh, *world->vis, run.solution, corners, cam, 24, 18);
  EXPECT_EQ(with.rgb, without.rgb);
}

// ---------------------------------------------------------------------------------------------
// Materials.

TEST(SpecularMaterialTest, EnergyIsChecked) {
  Material m;
  m.name = "m";
  m.reflectance = Rgb::Gray(0.5);
  m.mirror = Rgb(0.2, 0.6, 0.2);
  absl::Status st = ValidateSpecularParts(m, "x: ");
  EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("reflectance + transmittance + mirror + glossy + glass (0.7, 1.1, "
                              "0.7) is above 1"),
            std::string::npos)
      << st;
  m.mirror = Rgb::Gray(0.2);
  m.glossy = Rgb::Gray(0.2);
  st = ValidateSpecularParts(m, "x: ");
  EXPECT_NE(st.message().find("glossy exponent 0 is outside [1, "), std::string::npos) << st;
  m.glossy_exponent = 10;
  m.glass = Rgb::Gray(0.1);
  m.ior = 0.5;
  st = ValidateSpecularParts(m, "x: ");
  EXPECT_NE(st.message().find("index of refraction 0.5"), std::string::npos) << st;
  m.ior = 1.33;
  EXPECT_TRUE(ValidateSpecularParts(m, "x: ").ok());
}

}  // namespace
}  // namespace radiosity
