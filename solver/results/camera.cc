#include "solver/results/camera.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"
#include "solver/transport/sampling.h"

namespace radiosity {

namespace {

absl::Status CameraError(absl::string_view message) {
  return absl::InvalidArgumentError(absl::StrCat("camera: ", message));
}

// Parses a finite number; the error names the key and the offending text.
absl::Status ParseNumber(absl::string_view key, absl::string_view text, double* out) {
  if (!absl::SimpleAtod(text, out) || !std::isfinite(*out)) {
    return CameraError(absl::StrCat(key, ": '", text, "' is not a finite number"));
  }
  return absl::OkStatus();
}

absl::Status ParseVec3(absl::string_view key, absl::string_view text, Vec3* out) {
  std::vector<absl::string_view> parts = absl::StrSplit(text, ',');
  if (parts.size() != 3) {
    return CameraError(absl::StrCat(key, " needs three comma-separated numbers (", key,
                                    "=x,y,z), got '", text, "'"));
  }
  double c[3];
  for (int i = 0; i < 3; ++i) {
    absl::Status s = ParseNumber(key, parts[i], &c[i]);
    if (!s.ok()) return s;
  }
  *out = {c[0], c[1], c[2]};
  return absl::OkStatus();
}

}  // namespace

std::string Camera::ToString() const {
  return absl::StrFormat("eye=%.9g,%.9g,%.9g look=%.9g,%.9g,%.9g up=%.9g,%.9g,%.9g fov=%.9g", eye.x,
                         eye.y, eye.z, look.x, look.y, look.z, up.x, up.y, up.z, fov);
}

absl::StatusOr<Camera> ParseCamera(const std::string& text, const Camera& base) {
  Camera camera = base;
  std::set<std::string> seen;
  for (absl::string_view token :
       absl::StrSplit(text, absl::ByAnyChar(" \t\r\n"), absl::SkipEmpty())) {
    size_t eq = token.find('=');
    if (eq == absl::string_view::npos) {
      return CameraError(
          absl::StrCat("expected key=value, got '", token, "' (keys: eye, look, up, fov)"));
    }
    absl::string_view key = token.substr(0, eq), value = token.substr(eq + 1);
    if (key != "eye" && key != "look" && key != "up" && key != "fov") {
      return CameraError(
          absl::StrCat("unknown key '", key, "' in '", token, "' (keys: eye, look, up, fov)"));
    }
    if (!seen.insert(std::string(key)).second) {
      return CameraError(absl::StrCat("key '", key, "' is given twice"));
    }
    absl::Status st;
    if (key == "fov") {
      st = ParseNumber(key, value, &camera.fov);
      if (st.ok() && !(camera.fov > 0 && camera.fov < 180)) {
        return CameraError(absl::StrCat("fov must be in (0, 180) degrees, got '", value, "'"));
      }
    } else {
      st = ParseVec3(key, value,
                     key == "eye"    ? &camera.eye
                     : key == "look" ? &camera.look
                                     : &camera.up);
    }
    if (!st.ok()) return st;
  }
  // The view must be well defined: a direction, and an up vector not along it.
  Vec3 dir = camera.look - camera.eye;
  if (!(Length(dir) > 0)) {
    return CameraError(absl::StrCat("eye and look are the same point ", camera.eye.ToString()));
  }
  if (!(Length(camera.up) > 0)) return CameraError("up must be a nonzero vector");
  if (Length(Cross(Normalize(dir), Normalize(camera.up))) < 1e-9) {
    return CameraError(absl::StrCat("up ", camera.up.ToString(),
                                    " is parallel to the view direction look - eye ",
                                    dir.ToString()));
  }
  return camera;
}

Camera DefaultCamera(const Mesh& mesh) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  Vec3 lo{kInf, kInf, kInf}, hi{-kInf, -kInf, -kInf};
  for (const MeshFace& f : mesh.faces()) {
    for (const Vec3& p : f.p) {
      lo = Min(lo, p);
      hi = Max(hi, p);
    }
  }
  if (mesh.faces().empty()) lo = hi = Vec3{};
  const Vec3 half = (hi - lo) * 0.5;
  const Vec3 centre = (lo + hi) * 0.5 + mesh.origin();
  Camera camera;
  camera.fov = 40;
  camera.up = {0, 1, 0};
  camera.look = centre;
  // The near face of the box (half extents hx, hy at depth hz before the centre) fills a square
  // view of half-angle fov/2 at distance max(hx, hy) / tan(fov/2); the centre is hz further on.
  const double tan_half = std::tan(0.5 * camera.fov * kPi / 180);
  double distance = std::max(half.x, half.y) / tan_half + half.z;
  if (!(distance > 0)) distance = 1;
  camera.eye = centre - Vec3{0, 0, distance};
  return camera;
}

PrimaryRays::PrimaryRays(const Mesh& mesh, const Camera& camera, int width, int height)
    : eye(camera.eye - mesh.origin()), forward(Normalize(camera.look - camera.eye)) {
  right = Normalize(Cross(forward, camera.up));
  if (!(Length(right) > 0)) {
    Vec3 b;
    OrthonormalBasis(forward, &right, &b);
  }
  up = Cross(right, forward);
  tan_y = std::tan(0.5 * camera.fov * kPi / 180);
  tan_x = tan_y * width / height;
  w = width;
  h = height;
}

Vec3 PrimaryRays::Direction(double x, double y) const {
  // Normalised device coordinates in [-1, 1], +y up.
  const double px = 2 * x / w - 1;
  const double py = 1 - 2 * y / h;
  return Normalize(forward + right * (px * tan_x) + up * (py * tan_y));
}

}  // namespace radiosity
