// Small value types used throughout the solver: 3-vectors in double precision and RGB triples.
#ifndef RADIOSITY_SOLVER_GEOMETRY_VEC_H_
#define RADIOSITY_SOLVER_GEOMETRY_VEC_H_

#include <cmath>
#include <string>

namespace radiosity {

inline constexpr double kPi = 3.14159265358979323846;

// A point or direction in 3-space, double precision (scene coordinates can be far from the origin).
struct Vec3 {
  double x = 0, y = 0, z = 0;

  constexpr Vec3() = default;
  constexpr Vec3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}

  constexpr double operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr Vec3 operator+(const Vec3& o) const { return {x + o.x, y + o.y, z + o.z}; }
  constexpr Vec3 operator-(const Vec3& o) const { return {x - o.x, y - o.y, z - o.z}; }
  constexpr Vec3 operator-() const { return {-x, -y, -z}; }
  constexpr Vec3 operator*(double s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3 operator/(double s) const { return {x / s, y / s, z / s}; }
  Vec3& operator+=(const Vec3& o) {
    x += o.x;
    y += o.y;
    z += o.z;
    return *this;
  }
  Vec3& operator-=(const Vec3& o) {
    x -= o.x;
    y -= o.y;
    z -= o.z;
    return *this;
  }
  Vec3& operator*=(double s) {
    x *= s;
    y *= s;
    z *= s;
    return *this;
  }
  constexpr bool operator==(const Vec3& o) const { return x == o.x && y == o.y && z == o.z; }

  std::string ToString() const;
};

constexpr Vec3 operator*(double s, const Vec3& v) { return v * s; }
constexpr double Dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr Vec3 Cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double Length(const Vec3& v) { return std::sqrt(Dot(v, v)); }
inline Vec3 Normalize(const Vec3& v) {
  double l = Length(v);
  return l > 0 ? v / l : Vec3{};
}
inline bool IsFinite(const Vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
inline Vec3 Min(const Vec3& a, const Vec3& b) {
  return {std::fmin(a.x, b.x), std::fmin(a.y, b.y), std::fmin(a.z, b.z)};
}
inline Vec3 Max(const Vec3& a, const Vec3& b) {
  return {std::fmax(a.x, b.x), std::fmax(a.y, b.y), std::fmax(a.z, b.z)};
}

// Builds an orthonormal basis (t, b, n) around a unit normal n (Duff et al. 2017, "Building an
// Orthonormal Basis, Revisited").
inline void OrthonormalBasis(const Vec3& n, Vec3* t, Vec3* b) {
  double sign = std::copysign(1.0, n.z);
  double a = -1.0 / (sign + n.z);
  double c = n.x * n.y * a;
  *t = {1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x};
  *b = {c, sign + n.y * n.y * a, -n.y};
}

// A linear RGB triple: reflectance, exitance (W/m^2) or power (W) per channel.
struct Rgb {
  double r = 0, g = 0, b = 0;

  constexpr Rgb() = default;
  constexpr Rgb(double r_, double g_, double b_) : r(r_), g(g_), b(b_) {}
  static constexpr Rgb Gray(double v) { return {v, v, v}; }

  constexpr double operator[](int i) const { return i == 0 ? r : (i == 1 ? g : b); }
  double& operator[](int i) { return i == 0 ? r : (i == 1 ? g : b); }
  constexpr Rgb operator+(const Rgb& o) const { return {r + o.r, g + o.g, b + o.b}; }
  constexpr Rgb operator-(const Rgb& o) const { return {r - o.r, g - o.g, b - o.b}; }
  constexpr Rgb operator*(const Rgb& o) const { return {r * o.r, g * o.g, b * o.b}; }
  constexpr Rgb operator*(double s) const { return {r * s, g * s, b * s}; }
  constexpr Rgb operator/(double s) const { return {r / s, g / s, b / s}; }
  Rgb& operator+=(const Rgb& o) {
    r += o.r;
    g += o.g;
    b += o.b;
    return *this;
  }
  Rgb& operator-=(const Rgb& o) {
    r -= o.r;
    g -= o.g;
    b -= o.b;
    return *this;
  }
  Rgb& operator*=(double s) {
    r *= s;
    g *= s;
    b *= s;
    return *this;
  }
  constexpr bool operator==(const Rgb& o) const { return r == o.r && g == o.g && b == o.b; }

  // Sum of the channels: the scalar used to rank and budget power.
  constexpr double Sum() const { return r + g + b; }
  constexpr double Max() const { return r > g ? (r > b ? r : b) : (g > b ? g : b); }
  constexpr double Min() const { return r < g ? (r < b ? r : b) : (g < b ? g : b); }
  // Rec. 709 luminance of linear RGB.
  constexpr double Luminance() const { return 0.2126 * r + 0.7152 * g + 0.0722 * b; }
  bool IsFinite() const { return std::isfinite(r) && std::isfinite(g) && std::isfinite(b); }
  constexpr bool IsZero() const { return r == 0 && g == 0 && b == 0; }

  std::string ToString() const;
};

constexpr Rgb operator*(double s, const Rgb& c) { return c * s; }

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_VEC_H_
