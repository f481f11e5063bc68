#include "solver/geometry/vec.h"

#include <cstdio>

namespace radiosity {

std::string Vec3::ToString() const {
  char buf[96];
  std::snprintf(buf, sizeof buf, "(%.9g, %.9g, %.9g)", x, y, z);
  return buf;
}

std::string Rgb::ToString() const {
  char buf[96];
  std::snprintf(buf, sizeof buf, "[%.9g, %.9g, %.9g]", r, g, b);
  return buf;
}

}  // namespace radiosity
