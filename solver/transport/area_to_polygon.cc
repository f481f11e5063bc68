#include "solver/transport/area_to_polygon.h"

#include <algorithm>
#include <cmath>
#include <queue>

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
  for (int m = 0; m < mesh.FaceCount(element); ++m) {
    FacePolygons(mesh.faces()[mesh.FaceOf(element, m)], e.u0, e.v0, e.u1, e.v1, side, out);
  }
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

  // A triangle of the adaptive scheme: its rule's value, its four children's (midpoint
  // subdivision) and their sum, and the error estimate |fine - coarse|.
  struct Piece {
    Vec3 v[3], normal;
    double area = 0;
    Pair coarse, fine, child[4];
    double err = 0;
    int depth = 0;
    bool operator<(const Piece& o) const { return err < o.err; }
  };

  // The four children of triangle v as vertex triples.
  static void Children(const Vec3 v[3], Vec3 out[4][3]) {
    const Vec3 ab = (v[0] + v[1]) * 0.5, bc = (v[1] + v[2]) * 0.5, ca = (v[2] + v[0]) * 0.5;
    const Vec3 kids[4][3] = {{v[0], ab, ca}, {ab, v[1], bc}, {ca, bc, v[2]}, {ab, bc, ca}};
    for (int k = 0; k < 4; ++k) {
      for (int j = 0; j < 3; ++j) out[k][j] = kids[k][j];
    }
  }

  // `p` with its children's rules and error estimate filled in.
  void Expand(Piece* p) {
    set_normal(p->normal);
    Vec3 kids[4][3];
    Children(p->v, kids);
    p->fine = {};
    for (int k = 0; k < 4; ++k) {
      p->child[k] = Rule(kids[k][0], kids[k][1], kids[k][2], p->area / 4);
      p->fine = p->fine + p->child[k];
    }
    p->err = std::fabs(p->fine.front - p->coarse.front) + std::fabs(p->fine.back - p->coarse.back);
  }

  // Globally adaptive (the QUADPACK scheme on triangles; Cools and Haegemans 1988): the piece
  // with the largest error estimate is split in four until the estimates sum to `tol`, or the
  // evaluation budget is spent; pieces at max_depth are final.
  Pair Integrate(std::vector<Piece> pieces, double tol) {
    Pair sum;
    double total = 0;
    std::priority_queue<Piece> queue;
    for (Piece& p : pieces) {
      sum = sum + p.fine;
      total += p.err;
      queue.push(std::move(p));
    }
    while (total > tol && !queue.empty() && evaluations_ < options_.max_evaluations) {
      Piece p = queue.top();
      queue.pop();
      total -= p.err;
      if (p.depth >= options_.max_depth) continue;  // final: its fine sum stays in `sum`
      sum = sum + p.fine * -1.0;
      Vec3 kids[4][3];
      Children(p.v, kids);
      for (int k = 0; k < 4; ++k) {
        Piece child;
        for (int j = 0; j < 3; ++j) child.v[j] = kids[k][j];
        child.normal = p.normal;
        child.area = p.area / 4;
        child.coarse = p.child[k];
        child.depth = p.depth + 1;
        Expand(&child);
        sum = sum + child.fine;
        total += child.err;
        queue.push(std::move(child));
      }
    }
    return sum;
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
  using Piece = Integrator::Piece;
  std::vector<Piece> pieces;
  Pair coarse_sum;
  double coarse_total = 0;
  for (const SpacePolygon& r : receiver) {
    for (int k = 1; k + 1 < r.n; ++k) {
      const Vec3 &a = r.v[0], &b = r.v[k], &c = r.v[k + 1];
      const double tri_area = 0.5 * Length(Cross(b - a, c - a));
      if (!(tri_area > 0)) continue;
      Piece p;
      p.v[0] = a, p.v[1] = b, p.v[2] = c;
      p.normal = r.normal;
      p.area = tri_area;
      integrator.set_normal(p.normal);
      p.coarse = integrator.Rule(a, b, c, tri_area);
      coarse_sum = coarse_sum + p.coarse;
      coarse_total += p.coarse.front + p.coarse.back;
      pieces.push_back(p);
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
  Pair sum = coarse_sum;
  if (!far) {
    for (Piece& p : pieces) integrator.Expand(&p);
    // A quarter of the tolerance: |fine - coarse| estimates the coarse sum's error, and near the
    // kernel's steep parts (a polygon 0.1 of a width away) it is not yet asymptotic.
    const double tol = std::max(options.relative * coarse_total, options.absolute * area) / 4;
    sum = integrator.Integrate(std::move(pieces), tol);
  }
  out.front = sum.front / area;
  out.back = sum.back / area;
  out.evaluations = integrator.evaluations();
  return out;
}

}  // namespace radiosity
