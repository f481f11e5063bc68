// Cameras for rendered results: a pinhole camera, its text form ("eye=x,y,z look=x,y,z
// up=x,y,z fov=deg", the --camera flag), a default that frames the scene, and primary rays.
#ifndef RADIOSITY_SOLVER_RESULTS_CAMERA_H_
#define RADIOSITY_SOLVER_RESULTS_CAMERA_H_

#include <string>

#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/vec.h"

namespace radiosity {

// A pinhole camera. fov is the vertical field of view in degrees.
struct Camera {
  Vec3 eye{0, 0, 1};
  Vec3 look{0, 0, 0};
  Vec3 up{0, 1, 0};
  double fov = 40;
  std::string ToString() const;
};

// Parses "eye=x,y,z look=x,y,z up=x,y,z fov=deg" (any subset, any order, separated by spaces;
// missing keys keep the values of `base`). Errors name the bad key or number.
absl::StatusOr<Camera> ParseCamera(const std::string& text, const Camera& base);

// A camera that frames the scene's bounding box, looking along +z with +y up (the Cornell box's
// published view direction), from far enough that the whole box is in view.
Camera DefaultCamera(const Mesh& mesh);

// Primary rays of a pinhole camera in the mesh's recentred coordinates: orthonormal (right, up,
// forward); the image plane at distance 1 spans tan(fov/2) vertically and tan(fov/2) x
// width/height horizontally.
struct PrimaryRays {
  PrimaryRays(const Mesh& mesh, const Camera& camera, int width, int height);
  // Unit direction through image position (x, y) (pixels from the top left).
  Vec3 Direction(double x, double y) const;
  Vec3 eye, forward, right, up;
  double tan_x = 0, tan_y = 0;
  int w = 1, h = 1;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_CAMERA_H_
