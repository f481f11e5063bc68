#include "solver/transport/area_to_polygon.h"

#include <algorithm>
#include <cmath>

#include "solver/transport/formfactor.h"

namespace radiosity {

double SpacePolygon::Area() const {
  Vec3 sum;
  for (int k = 1; k + 1 < n; ++k) sum += Cross(v[k] - v[0], v[k + 1] - v[0]);
  return 0.5 * Length(sum);
}

void FacePolygons(const MeshFace& face, double u0, double v0, double u1, double v1, int side,
                  std::vector<SpacePolygon>* out) {
  std::array<ElementPiece, 2> pieces;
  const int count = RectPieces(u0, v0, u1, v1, face, &pieces);
  for (int k = 0; k < count; ++k) {
    const ElementPiece& pc = pieces[k];
    SpacePolygon poly;
    poly.n = pc.n;
    for (int i = 0; i < pc.n; ++i) {
      poly.v[i] = face.EvalOnHalf(pc.half, pc.uv[2 * i], pc.uv[2 * i + 1]);
    }
    poly.normal = side == 0 ? face.normal[pc.half] : -face.normal[pc.half];
    out->push_back(poly);
  }
}

void ElementPolygons(const Mesh& mesh, int element, int side, std::vector<SpacePolygon>* out) {
  const Element& e = mesh.elements()[element];
  FacePolygons(mesh.faces()[e.face], e.u0, e.v0, e.u1, e.v1, side, out);
}

namespace {

// A 7-point rule of degree 5 on a triangle (Radon 1948; Stroud T2:5-1), barycentric points and
// weights summing to 1.
struct TrianglePoint {
  double a, b, c, w;
};
const std::array<TrianglePoint, 7>& Radon7() {
  static const std::array<TrianglePoint, 7> rule = [] {
    const double s = std::sqrt(15.0);
    const double a1 = (6 - s) / 21, b1 = (9 + 2 * s) / 21, w1 = (155 - s) / 1200;
    const double a2 = (6 + s) / 21, b2 = (9 - 2 * s) / 21, w2 = (155 + s) / 1200;
    return std::array<TrianglePoint, 7>{{{1.0 / 3, 1.0 / 3, 1.0 / 3, 9.0 / 40},
                                         {a1, a1, b1, w1},
                                         {a1, b1, a1, w1},
                                         {b1, a1, a1, w1},
                                         {a2, a2, b2, w2},
                                         {a2, b2, a2, w2},
                                         {b2, a2, a2, w2}}};
  }();
  return rule;
}

struct Pair {
  double front = 0, back = 0;
  Pair operator+(const Pair& o) const { return {front + o.front, back + o.back}; }
  Pair operator*(double s) const { return {front * s, back * s}; }
};

class Integrator {
 public:
  Integrator(const SpacePolygon& polygon, const QuadratureOptions& options)
      : polygon_(polygon), options_(options) {}
  // The receiver's front normal (one per receiving piece: the halves of a non-planar quad differ).
  void set_normal(const Vec3& n) { n_ = n; }

  // F(dA(x) -> polygon) for the normal n and for -n.
  Pair Kernel(const Vec3& x) {
    ++evaluations_;
    if (Dot(x - polygon_.v[0], polygon_.normal) <= 0) return {};
    bool ahead = false, behind = false;
    // Vertices within rounding of the receiver's plane (a wall meeting it at a shared edge) are
    // in it.
    for (int k = 0; k < polygon_.n; ++k) {
      const Vec3 r = polygon_.v[k] - x;
      const double d = Dot(r, n_);
      const double tol = 1e-12 * (Length(r) + Length(x) + Length(polygon_.v[k]));
      ahead |= d > tol;
      behind |= d < -tol;
    }
    Pair f;
    if (ahead && !behind) {
      f.front = PointToPolygonFormFactor(x, n_, polygon_.v.data(), polygon_.n);
    } else if (behind && !ahead) {
      f.back = PointToPolygonFormFactor(x, -n_, polygon_.v.data(), polygon_.n);
    } else if (ahead && behind) {
      f.front = PointToPolygonFormFactorClipped(x, n_, polygon_.v.data(), polygon_.n);
      f.back = PointToPolygonFormFactorClipped(x, -n_, polygon_.v.data(), polygon_.n);
    }
    return f;
  }

  // The rule on triangle (a, b, c) of area `area`: the integral, not the mean.
  Pair Rule(const Vec3& a, const Vec3& b, const Vec3& c, double area) {
    Pair sum;
    for (const TrianglePoint& p : Radon7()) sum = sum + Kernel(a * p.a + b * p.b + c * p.c) * p.w;
    return sum * area;
  }

  // Refines triangle (a, b, c), whose rule gave `coarse`, until its four children's sum agrees
  // with it to `tol` (Cools and Haegemans 1988's scheme, simplified: local error control with
  // the tolerance shared in proportion to area).
  Pair Refine(const Vec3& a, const Vec3& b, const Vec3& c, double area, const Pair& coarse,
              double tol, int depth) {
    const Vec3 ab = (a + b) * 0.5, bc = (b + c) * 0.5, ca = (c + a) * 0.5;
    const double quarter = area / 4;
    const Pair k0 = Rule(a, ab, ca, quarter), k1 = Rule(ab, b, bc, quarter);
    const Pair k2 = Rule(ca, bc, c, quarter), k3 = Rule(ab, bc, ca, quarter);
    const Pair fine = k0 + k1 + k2 + k3;
    const double err = std::fabs(fine.front - coarse.front) + std::fabs(fine.back - coarse.back);
    if (err <= tol || depth >= options_.max_depth) return fine;
    const double t = tol / 4;
    return Refine(a, ab, ca, quarter, k0, t, depth + 1) +
           Refine(ab, b, bc, quarter, k1, t, depth + 1) +
           Refine(ca, bc, c, quarter, k2, t, depth + 1) +
           Refine(ab, bc, ca, quarter, k3, t, depth + 1);
  }

  int64_t evaluations() const { return evaluations_; }

 private:
  Vec3 n_;
  const SpacePolygon& polygon_;
  const QuadratureOptions& options_;
  int64_t evaluations_ = 0;
};

}  // namespace

AreaFormFactor AreaToPolygon(const std::vector<SpacePolygon>& receiver, double area,
                             const SpacePolygon& polygon, const QuadratureOptions& options) {
  AreaFormFactor out;
  if (receiver.empty() || polygon.n < 3 || !(area > 0)) return out;
  // Whole-receiver rejection: no receiver vertex in front of the polygon's sending side.
  bool any_in_front = false;
  for (const SpacePolygon& r : receiver) {
    for (int k = 0; k < r.n; ++k) any_in_front |= Dot(r.v[k] - polygon.v[0], polygon.normal) > 0;
  }
  if (!any_in_front) return out;
  Integrator integrator(polygon, options);
  struct Tri {
    Vec3 a, b, c;
    double area;
    Pair coarse;
    Vec3 normal;
  };
  std::vector<Tri> tris;
  double coarse_total = 0;
  for (const SpacePolygon& r : receiver) {
    for (int k = 1; k + 1 < r.n; ++k) {
      Tri t{r.v[0], r.v[k], r.v[k + 1], 0, {}, r.normal};
      t.area = 0.5 * Length(Cross(t.b - t.a, t.c - t.a));
      if (!(t.area > 0)) continue;
      integrator.set_normal(r.normal);
      t.coarse = integrator.Rule(t.a, t.b, t.c, t.area);
      coarse_total += t.coarse.front + t.coarse.back;
      tris.push_back(t);
    }
  }
  // Far away, the kernel is smooth on the receiver's scale and the rule's error, O((h / d)^6),
  // needs no estimate.
  bool far = false;
  if (options.far_ratio > 0) {
    auto bounds = [](const Vec3* v, int n, Vec3* centre) {
      Vec3 c;
      for (int k = 0; k < n; ++k) c += v[k];
      c = c / n;
      double r = 0;
      for (int k = 0; k < n; ++k) r = std::max(r, Length(v[k] - c));
      *centre = c;
      return r;
    };
    Vec3 cp, cr;
    const double rp = bounds(polygon.v.data(), polygon.n, &cp);
    std::vector<Vec3> all;
    for (const SpacePolygon& r : receiver) all.insert(all.end(), r.v.begin(), r.v.begin() + r.n);
    const double rr = bounds(all.data(), static_cast<int>(all.size()), &cr);
    far = Length(cp - cr) - rp - rr > options.far_ratio * 2 * rr;
  }
  const double tol = std::max(options.relative * coarse_total, options.absolute * area);
  Pair sum;
  for (const Tri& t : tris) {
    integrator.set_normal(t.normal);
    sum = sum + (far ? t.coarse
                     : integrator.Refine(t.a, t.b, t.c, t.area, t.coarse, tol * t.area / area, 0));
  }
  out.front = sum.front / area;
  out.back = sum.back / area;
  out.evaluations = integrator.evaluations();
  return out;
}

}  // namespace radiosity
