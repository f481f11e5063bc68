// Helpers shared by the tests: status assertions, paths, temporary directories, running the CLI,
// reading CSV, scene builders and the closed forms the tests compare with.
#ifndef RADIOSITY_TESTS_TESTING_TEST_UTIL_H_
#define RADIOSITY_TESTS_TESTING_TEST_UTIL_H_

#include <gtest/gtest.h>

#include <initializer_list>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"

// ASSERT_OK(expr) / EXPECT_OK(expr): `expr` (an absl::Status or absl::StatusOr) is OK; the failure
// message shows the expression and the status. Evaluates `expr` once.
#define ASSERT_OK(expr) ASSERT_PRED_FORMAT1(::radiosity::testing::internal::IsOk, expr)
#define EXPECT_OK(expr) EXPECT_PRED_FORMAT1(::radiosity::testing::internal::IsOk, expr)

// ASSERT_OK_AND_ASSIGN(lhs, expr): evaluates `expr` (an absl::StatusOr<T>), fails the test (and
// returns from the enclosing void function) unless it is OK, and otherwise moves its value into
// `lhs`, which may declare a variable: ASSERT_OK_AND_ASSIGN(Scene scene, LoadSceneFile(...)).
// A helper that returns a value cannot use it: let such helpers return absl::StatusOr and the
// test assert on it.
#define ASSERT_OK_AND_ASSIGN(lhs, expr)                                                          \
  RADIOSITY_ASSERT_OK_AND_ASSIGN_IMPL(RADIOSITY_TESTING_CONCAT(status_or_value_, __LINE__), lhs, \
                                      expr)
#define RADIOSITY_ASSERT_OK_AND_ASSIGN_IMPL(statusor, lhs, expr) \
  auto statusor = (expr);                                        \
  ASSERT_OK(statusor);                                           \
  lhs = std::move(statusor).value()
#define RADIOSITY_TESTING_CONCAT(a, b) RADIOSITY_TESTING_CONCAT_INNER(a, b)
#define RADIOSITY_TESTING_CONCAT_INNER(a, b) a##b

namespace radiosity::testing {

namespace internal {
inline const absl::Status& StatusOf(const absl::Status& status) { return status; }
template <typename T>
const absl::Status& StatusOf(const absl::StatusOr<T>& status_or) {
  return status_or.status();
}
template <typename T>
::testing::AssertionResult IsOk(const char* text, const T& value) {
  const absl::Status& status = StatusOf(value);
  if (status.ok()) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << text << " is not OK: " << status;
}
}  // namespace internal

// `status` has `code`, and its message contains every one of `words` (the words that name the
// field or file and the problem). EXPECT_TRUE(Refused(...)) / ASSERT_TRUE(Refused(...)).
::testing::AssertionResult Refused(const absl::Status& status, absl::StatusCode code,
                                   std::initializer_list<std::string> words = {});
template <typename T>
::testing::AssertionResult Refused(const absl::StatusOr<T>& result, absl::StatusCode code,
                                   std::initializer_list<std::string> words = {}) {
  return Refused(result.status(), code, words);
}

// Absolute path of a file in the source tree, e.g. SourcePath("scenes/cornell_box.obj").
std::string SourcePath(const std::string& relative);

// A fresh empty directory under the system temp dir, removed when the object dies.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const std::string& path() const { return path_; }
  std::string File(const std::string& name) const { return path_ + "/" + name; }
  // Writes `text` to File(name) and returns that path.
  std::string Write(const std::string& name, const std::string& text) const;

 private:
  std::string path_;
};

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

// Runs the radiosity CLI with the given arguments (shell-quoted here) and captures its output.
CommandResult RunCli(const std::vector<std::string>& args);

// Runs `radiosity solve <scene> --out <out> <flags...>`.
CommandResult RunSolve(const std::string& scene, const std::string& out,
                       const std::vector<std::string>& flags);

// Reads a whole file; empty if missing.
std::string ReadFile(const std::string& path);

// A CSV file: its header and rows, split on commas (no quoting needed for our files).
struct Csv {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  int Column(const std::string& name) const;  // -1 if absent
};
Csv ReadCsv(const std::string& path);

// The mesh of `scene` with MeshOptions::element_size = element_size (other options default).
absl::StatusOr<Mesh> BuildMesh(const Scene& scene, double element_size);

// An icosphere of unit radius (20 x 4^subdivisions triangles) facing inward: triangles whose
// centroid has z > 1 - 2 cap are the lamp (exitance 1, reflectance 0), the rest the coating
// (reflectance rho). Sets *f to the lamp's share of the area; the irradiance is then the same
// everywhere, H = f / (1 - rho (1 - f)).
Scene IntegratingSphere(int subdivisions, double cap, double rho, double* f);

// Two concentric icospheres of 20 x 4^subdivisions black triangles: "inner" of radius 1 facing
// out inside "outer" of radius 2 facing in (a convex body in an enclosure).
Scene ConcentricIcospheres(int subdivisions);

// An axis-aligned closed box [0,sx]x[0,sy]x[0,sz] of six quads facing inward, one surface per
// side ("x0", "x1", "y0", "y1", "z0", "z1"), all with one material.
Scene MakeClosedBox(double sx, double sy, double sz, const Material& material);

// Adds the parallelogram corner, corner + u, corner + u + v, corner + v (front facing u x v) as a
// face of `surface`, created with `material` if the scene has no surface of that name yet.
void AddRect(Scene* s, const std::string& surface, int material, const Vec3& corner, const Vec3& u,
             const Vec3& v);

// Adds the polygon `corners` (counter-clockwise seen from its front) as a face of a new surface
// `surface` of material `material`.
void AddPolygon(Scene* s, const std::string& surface, int material,
                const std::vector<Vec3>& corners);

// OBJ text of one regular polygon of `n` vertices on the unit circle in the plane z = 0: the n
// vertex lines, then the face on line n + 1 (no material).
std::string RegularPolygonObj(int n);

// A scene of named one-polygon surfaces, all of one black one-sided material.
Scene PolygonScene(const std::vector<std::pair<std::string, std::vector<Vec3>>>& polygons);

// "bottom" (z = 0, facing +z) and "top" (z = c, facing -z): black a x b rectangles, directly
// opposed.
Scene OpposedRectanglesScene(double a, double b, double c);

// OpposedRectanglesScene(1, 1, 1) with a black wall in the plane x = 0.5 between the squares,
// touching both (and wider than them), facing +x: each half of the bottom sees only the half of
// the top on its side, so F_bottom->top = F of opposed 0.5 x 1 rectangles (by symmetry and Howell
// C-11).
Scene HalfBlockedSquaresScene();

// A furnace room [0,4]^3 with a unit block in the corner at the origin, resting on the floor and
// against two walls, all of one material (reflectance rho, emission 1). Floor and walls have
// conforming holes where the block touches them, made of coplanar pieces that meet in
// T-junctions; the block shows only its three room-facing faces. The enclosure is closed, so every
// element has B = E / (1 - rho) unless light leaks through a contact edge or a T-junction.
Scene CornerBlockFurnace(double rho);

// ---------------------------------------------------------------------------------------------
// Closed forms (Howell, "A Catalog of Radiation Heat Transfer Configuration Factors").

// Parallel, directly opposed rectangles a x b at separation c (C-11): F_12.
double OpposedRectangles(double a, double b, double c);

// Perpendicular rectangles sharing an edge of length l; surface 1 has width w, surface 2 height h
// (C-14): F_12.
double PerpendicularRectangles(double l, double w, double h);

// Parallel rectangles in general position (Ehlert & Smith 1993, by superposition of the corner
// function): [x1,x2]x[y1,y2] in the plane z = 0 and [xi1,xi2]x[eta1,eta2] in z = c: F_12.
double ParallelRectangles(double x1, double x2, double y1, double y2, double xi1, double xi2,
                          double eta1, double eta2, double c);

// Differential area to a parallel rectangle a x b whose corner lies on its normal at distance c
// (B-3 family, the corner case).
double PointUnderCorner(double a, double b, double c);

// Coaxial parallel disks, radii r1, r2, distance h (C-41): F_12.
double CoaxialDisks(double r1, double r2, double h);

}  // namespace radiosity::testing

#endif  // RADIOSITY_TESTS_TESTING_TEST_UTIL_H_
