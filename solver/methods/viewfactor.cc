#include "solver/methods/viewfactor.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/geometry/box.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/solution.h"
#include "solver/methods/exchange.h"
#include "solver/methods/viewfactor_correction.h"
#include "solver/transport/formfactor.h"
#include "solver/transport/rng.h"
#include "solver/transport/visibility.h"
#include "solver/util/field_checker.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"
#include "tbb/task_arena.h"

namespace radiosity {

namespace {

// A triangle of the integration domain: one half of a mesh face (mesh coordinates).
struct Tri {
  Vec3 a, b, c;
  Vec3 n;         // Front normal.
  int face = -1;  // Mesh face (skipped by shadow rays leaving it).
  int input_face = -1;
};

// A planar polygon of the kernel side, with its front normal.
struct Poly {
  std::vector<Vec3> v;
  Vec3 n;
  int input_face = -1;
  double area = 0;
};

struct SurfaceGeom {
  std::vector<Tri> tris;    // Integration domain.
  std::vector<Poly> polys;  // Kernel polygons.
  std::vector<int> faces;   // Mesh faces, ascending.
  double area = 0;
  Box box;
  bool coplanar = true;  // All polygons in one plane, with one front normal.
  Vec3 plane_p, plane_n;
};

double TriArea(const Vec3& a, const Vec3& b, const Vec3& c) {
  return 0.5 * Length(Cross(b - a, c - a));
}

// A convex polygon that may block (exact occlusion): a planar convex mesh face, or one half of
// another.
struct Blocker {
  std::vector<Vec3> v;
  Vec3 n;  // Unit normal.
  Box box;
  int surface = -1;
};

// The part of convex polygon `in` where Dot(x - p, n) >= offset (Sutherland-Hodgman), in `out`.
void ClipHalfSpace(const std::vector<Vec3>& in, const Vec3& p, const Vec3& n, double offset,
                   std::vector<Vec3>* out) {
  out->clear();
  const size_t m = in.size();
  if (m == 0) return;
  // Each corner's distance once (the loop carries it to the next edge).
  const double first = Dot(in[0] - p, n) - offset;
  double da = first;
  for (size_t k = 0; k < m; ++k) {
    const Vec3& a = in[k];
    const bool last = k + 1 == m;
    const Vec3& b = last ? in[0] : in[k + 1];
    const double db = last ? first : Dot(b - p, n) - offset;
    if (da >= 0) out->push_back(a);
    if ((da > 0 && db < 0) || (da < 0 && db > 0)) out->push_back(a + (b - a) * (da / (da - db)));
    da = db;
  }
  if (out->size() < 3) out->clear();
}

// How a blocker's plane cuts a shaft: the convex hull of the points `hull`, whose first `near`
// points are a domain triangle and the rest a kernel polygon. For convex A and B, conv(A u B) is
// the union of the segments from A to B (Rockafellar, Convex Analysis, thm. 3.3), so this is where
// a blocker can cut a segment between them (the shaft of Haines & Wallace 1994, exact instead of
// box-bounded).
struct ShaftCut {
  double section = 0;  // Area of the hull's section by the blocker's plane.
  double pierced = 0;  // Area of the blocker inside the section moved in by eps (0 if touching).
  double open = 0;     // Area of the section outside the blocker.
  Box box;             // The section's bounding box.
  Box pierced_box;     // The bounding box of the blocker's part in the section.
  bool separates = false;  // The plane has the triangle on one side and the kernel on the other.
};

// The hull's section by the blocker's plane (its points in the plane and its edges' crossings of
// it) clips the blocker in that plane (Sutherland-Hodgman, the section's edges moved in by `eps`
// so that touching gives nothing). A plane that only supports the hull (the hull wholly on one
// side, within eps) gives nothing: the segments meet it only where they graze it. With
// `any_pairs`, the points are any finite set (not a triangle and a convex polygon): every pair of
// points is taken as a possible edge of the hull.
ShaftCut CutShaft(const std::vector<Vec3>& hull, size_t near, const std::vector<Vec3>& blocker,
                  const Vec3& n, double eps, bool any_pairs = false) {
  using P2 = std::array<double, 2>;
  ShaftCut cut;
  Vec3 u, w;
  OrthonormalBasis(n, &u, &w);
  const Vec3& o = blocker[0];
  std::vector<P2> s;  // The section, in plane coordinates.
  auto add = [&](const Vec3& p) {
    s.push_back({Dot(p - o, u), Dot(p - o, w)});
    cut.box.Add(p);
  };
  std::vector<double> dist(hull.size());
  const size_t m = hull.size();
  double below = 0, above = 0;
  double near_lo = std::numeric_limits<double>::max(), near_hi = -near_lo, far_lo = near_lo,
         far_hi = -near_lo;
  for (size_t i = 0; i < m; ++i) {
    dist[i] = Dot(hull[i] - o, n);
    below = std::min(below, dist[i]);
    above = std::max(above, dist[i]);
    if (i < near) {
      near_lo = std::min(near_lo, dist[i]), near_hi = std::max(near_hi, dist[i]);
    } else {
      far_lo = std::min(far_lo, dist[i]), far_hi = std::max(far_hi, dist[i]);
    }
    if (std::fabs(dist[i]) <= eps) add(hull[i]);
  }
  if (below >= -eps || above <= eps) return cut;
  // (Points in the plane may lie on either side: they are a set of measure zero.)
  cut.separates = (near_lo >= -eps && far_hi <= eps) || (near_hi <= eps && far_lo >= -eps);
  // The hull's edges are among the triangle's edges, the kernel polygon's edges and the segments
  // from a corner of one to a corner of the other: O(m) pairs, not all m^2.
  auto edge = [&](size_t i, size_t j) {
    if (any_pairs) return true;
    if (i < near && j < near) return j == i + 1 || (i == 0 && j == near - 1);
    if (i >= near && j >= near) return j == i + 1 || (i == near && j == m - 1);
    return true;
  };
  for (size_t i = 0; i < m; ++i) {
    for (size_t j = i + 1; j < m; ++j) {
      if (!edge(i, j)) continue;
      if ((dist[i] < -eps && dist[j] > eps) || (dist[i] > eps && dist[j] < -eps)) {
        add(hull[i] + (hull[j] - hull[i]) * (dist[i] / (dist[i] - dist[j])));
      }
    }
  }
  if (s.size() < 3) return cut;
  // The section's convex hull (Andrew's monotone chain), counter-clockwise.
  std::sort(s.begin(), s.end());
  auto turn = [](const P2& a, const P2& b, const P2& c) {
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
  };
  std::vector<P2> h(2 * s.size());
  size_t k = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    while (k >= 2 && turn(h[k - 2], h[k - 1], s[i]) <= 0) --k;
    h[k++] = s[i];
  }
  for (size_t i = s.size() - 1, lower = k + 1; i-- > 0;) {
    while (k >= lower && turn(h[k - 2], h[k - 1], s[i]) <= 0) --k;
    h[k++] = s[i];
  }
  h.resize(k - 1);
  if (h.size() < 3) return cut;
  auto area = [](const std::vector<P2>& poly) {
    double a = 0;
    for (size_t j = 0; j < poly.size(); ++j) {
      const P2& x = poly[j];
      const P2& y = poly[(j + 1) % poly.size()];
      a += x[0] * y[1] - x[1] * y[0];
    }
    return 0.5 * std::fabs(a);
  };
  cut.section = area(h);
  // The blocker clipped to the inside of every edge of the section (moved in by `in`).
  std::vector<P2> b, c;
  auto clipped_area = [&](double in) {
    b.clear();
    for (const Vec3& p : blocker) b.push_back({Dot(p - o, u), Dot(p - o, w)});
    for (size_t i = 0; i < h.size() && b.size() >= 3; ++i) {
      const P2& p = h[i];
      const P2& q = h[(i + 1) % h.size()];
      const double len = std::hypot(q[0] - p[0], q[1] - p[1]);
      if (len <= 0) continue;
      auto inside = [&](const P2& x) { return turn(p, q, x) / len - in; };
      c.clear();
      for (size_t j = 0; j < b.size(); ++j) {
        const P2& x = b[j];
        const P2& y = b[(j + 1) % b.size()];
        const double dx = inside(x), dy = inside(y);
        if (dx >= 0) c.push_back(x);
        if ((dx > 0 && dy < 0) || (dx < 0 && dy > 0)) {
          const double t = dx / (dx - dy);
          c.push_back({x[0] + (y[0] - x[0]) * t, x[1] + (y[1] - x[1]) * t});
        }
      }
      b.swap(c);
    }
    return b.size() >= 3 ? std::min(area(b), cut.section) : 0.0;
  };
  cut.pierced = clipped_area(eps);
  for (const P2& x : b) cut.pierced_box.Add(o + u * x[0] + w * x[1]);
  cut.open = cut.pierced > 0 ? std::max(0.0, cut.section - clipped_area(0)) : cut.section;
  return cut;
}

// The surfaces' geometry in mesh coordinates: domain triangles from the mesh (the same triangles
// Embree traces) and kernel polygons from the input (a planar polygon whole, a non-planar one as
// its mesh triangles).
std::vector<SurfaceGeom> BuildGeometry(const Scene& scene, const Mesh& mesh) {
  std::vector<SurfaceGeom> geom(scene.surfaces.size());
  const auto& faces = mesh.faces();
  std::vector<std::vector<int>> faces_of_input(scene.faces.size());
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    const MeshFace& mf = faces[f];
    faces_of_input[mf.input_face].push_back(f);
    SurfaceGeom& g = geom[mf.surface];
    g.faces.push_back(f);
    for (int h = 0; h < 2; ++h) {
      if (mf.jacobian[h] <= 0) continue;
      Tri t;
      if (h == 0) {
        t.a = mf.p[0], t.b = mf.p[1], t.c = mf.p[3];
      } else {
        t.a = mf.p[2], t.b = mf.p[3], t.c = mf.p[1];
      }
      t.n = mf.normal[h];
      t.face = f;
      t.input_face = mf.input_face;
      g.tris.push_back(t);
      g.area += 0.5 * mf.jacobian[h];
      g.box.Add(t.a);
      g.box.Add(t.b);
      g.box.Add(t.c);
    }
  }
  const double scale = mesh.scale();
  for (int fi = 0; fi < static_cast<int>(scene.faces.size()); ++fi) {
    const Face& face = scene.faces[fi];
    if (faces_of_input[fi].empty() || face.surface < 0) continue;
    SurfaceGeom& g = geom[face.surface];
    std::vector<Vec3> v;
    for (int i : face.vertices) v.push_back(scene.vertices[i] - mesh.origin());
    // Newell's normal; the polygon is planar when every vertex lies in its plane.
    Vec3 nn, centre;
    for (size_t k = 0; k < v.size(); ++k) {
      const Vec3& a = v[k];
      const Vec3& b = v[(k + 1) % v.size()];
      nn += Cross(a, b);
      centre += a;
    }
    centre = centre / static_cast<double>(v.size());
    const Vec3 n = Normalize(nn);
    double off = 0;
    for (const Vec3& p : v) off = std::max(off, std::fabs(Dot(p - centre, n)));
    if (off <= 1e-9 * scale) {
      Poly poly;
      poly.v = v;
      poly.n = n;
      poly.input_face = fi;
      poly.area = 0.5 * Length(nn);
      g.polys.push_back(std::move(poly));
    } else {
      for (int f : faces_of_input[fi]) {
        const MeshFace& mf = faces[f];
        for (int h = 0; h < 2; ++h) {
          if (mf.jacobian[h] <= 0) continue;
          Poly poly;
          poly.v = h == 0 ? std::vector<Vec3>{mf.p[0], mf.p[1], mf.p[3]}
                          : std::vector<Vec3>{mf.p[2], mf.p[3], mf.p[1]};
          poly.n = mf.normal[h];
          poly.input_face = fi;
          poly.area = 0.5 * mf.jacobian[h];
          g.polys.push_back(std::move(poly));
        }
      }
    }
  }
  for (SurfaceGeom& g : geom) {
    if (g.polys.empty()) continue;
    g.plane_p = g.polys[0].v[0];
    g.plane_n = g.polys[0].n;
    for (const Poly& p : g.polys) {
      if (Length(p.n - g.plane_n) > 1e-9) g.coplanar = false;
      for (const Vec3& x : p.v) {
        if (std::fabs(Dot(x - g.plane_p, g.plane_n)) > 1e-9 * scale) g.coplanar = false;
      }
    }
  }
  return geom;
}

// Radon's 7-point rule, exact for polynomials of degree 5 on a triangle (Stroud T2:5-1; the
// degree-5 Dunavant rule): barycentric points and weights (summing to 1).
struct RulePoint {
  double l0, l1, l2, w;
};
const std::array<RulePoint, 7>& Radon7() {
  static const std::array<RulePoint, 7> rule = [] {
    const double s = std::sqrt(15.0);
    const double a1 = (9 - 2 * s) / 21, b1 = (6 + s) / 21, w1 = (155 + s) / 1200;
    const double a2 = (9 + 2 * s) / 21, b2 = (6 - s) / 21, w2 = (155 - s) / 1200;
    return std::array<RulePoint, 7>{{{1.0 / 3, 1.0 / 3, 1.0 / 3, 9.0 / 40},
                                     {a1, b1, b1, w1},
                                     {b1, a1, b1, w1},
                                     {b1, b1, a1, w1},
                                     {a2, b2, b2, w2},
                                     {b2, a2, b2, w2},
                                     {b2, b2, a2, w2}}};
  }();
  return rule;
}

// The adaptive quadrature of one pair: G = integral over the domain surface d of F_{dy -> k}(y),
// which is A_d F_dk = A_k F_kd (reciprocity; Siegel & Howell eq. 4.16).
class PairIntegrator {
 public:
  // `blockers`, when given (exact occlusion), are the triangles that may cut a segment between
  // the pair; otherwise an occluded pair's visibility is sampled by shadow rays.
  PairIntegrator(const SurfaceGeom& dom, const SurfaceGeom& ker, const Visibility& vis,
                 bool occluded, int shadow_rays, uint64_t stream, double plane_eps,
                 const std::vector<const Blocker*>* blockers = nullptr)
      : dom_(dom),
        ker_(ker),
        vis_(vis),
        occluded_(occluded),
        shadow_rays_(shadow_rays),
        stream_(stream),
        plane_eps_(plane_eps),
        blockers_(occluded ? blockers : nullptr),
        shaft_eps_(1e3 * plane_eps) {
    if (blockers_ != nullptr) {
      misses_.assign(blockers_->size(), 0);
      covers_ = crosses_ = misses_;
    }
    if (occluded_ && blockers_ == nullptr) MakeTargetTriangles();
    for (const Poly& q : ker_.polys) {
      kernel_vertices_.insert(kernel_vertices_.end(), q.v.begin(), q.v.end());
    }
    surfaces_apart_ = dom_.box.Distance(ker_.box) > 0;
  }

  // The error allowed in G, given the current estimate of G: floor + relative x G, at most cap.
  struct Budget {
    double floor, relative, cap;
    double For(double g) const { return std::min(cap, floor + relative * std::fabs(g)); }
  };

  // Refines until the estimated error is within the budget for the current value. Returns false
  // if stopped.
  bool Run(const Budget& budget, int64_t max_splits, const std::atomic<bool>* stop, double* value,
           double* error) {
    // Initial nodes: domain triangles, clipped to the half-space in front of a planar kernel (the
    // kernel is 0 behind it, and a jump along that line would otherwise need deep refinement),
    // then split to a minimum depth and, near the kernel, until small compared with the gap.
    std::vector<Node> initial;
    for (int t = 0; t < static_cast<int>(dom_.tris.size()); ++t) {
      const Tri& tri = dom_.tris[t];
      std::vector<Vec3> poly{tri.a, tri.b, tri.c};
      if (ker_.coplanar) poly = ClipFront(poly, ker_.plane_p, ker_.plane_n);
      for (size_t k = 1; k + 1 < poly.size(); ++k) {
        if (TriArea(poly[0], poly[k], poly[k + 1]) <= 0) continue;
        Presplit({poly[0], poly[k], poly[k + 1], t, 0}, 1e-3 * budget.cap, &initial);
      }
    }
    heap_.clear();
    double total_error = 0, total_value = 0;
    for (const Node& node : initial) {
      // Each evaluation may clip many blockers: the stop is checked before every one.
      if (stop != nullptr && stop->load(std::memory_order_relaxed)) return false;
      Item item = MakeItem(node, Evaluate(node));
      total_error += item.err;
      total_value += item.value[0] + item.value[1];
      Push(item);
    }
    int64_t splits = 0;
    while (!heap_.empty() && total_error > budget.For(total_value) && splits < max_splits) {
      if (stop != nullptr && stop->load(std::memory_order_relaxed)) return false;
      std::pop_heap(heap_.begin(), heap_.end(), ByError);
      Item item = heap_.back();
      heap_.pop_back();
      total_error -= item.err;
      total_value -= item.value[0] + item.value[1];
      for (int c = 0; c < 2; ++c) {
        Item child = MakeItem(item.child[c], item.value[c]);
        total_error += child.err;
        total_value += child.value[0] + child.value[1];
        Push(child);
      }
      ++splits;
      if ((splits & 1023) == 0) {  // Refresh the running sums against rounding drift.
        total_error = total_value = 0;
        for (const Item& it : heap_) {
          total_error += it.err;
          total_value += it.value[0] + it.value[1];
        }
      }
    }
    double v = 0, e = 0;
    for (const Item& it : heap_) {
      v += it.value[0] + it.value[1];
      e += it.err;
    }
    if (occluded_ && blockers_ == nullptr) {
      bool stopped = false;
      v = OccludedValue(stop, &stopped);
      if (stopped) return false;
    }
    *value = v;
    *error = e;
    return true;
  }

  int64_t rays() const { return rays_; }
  int64_t evaluations() const { return evaluations_; }

 private:
  struct Node {
    Vec3 a, b, c;
    int tri;
    int depth;
  };
  struct Item {
    Node child[2];
    double value[2];
    double err;
  };
  static bool ByError(const Item& x, const Item& y) { return x.err < y.err; }
  void Push(const Item& item) {
    heap_.push_back(item);
    std::push_heap(heap_.begin(), heap_.end(), ByError);
  }

  static std::vector<Vec3> ClipFront(const std::vector<Vec3>& in, const Vec3& p, const Vec3& n) {
    std::vector<Vec3> out;
    const size_t m = in.size();
    for (size_t k = 0; k < m; ++k) {
      const Vec3& a = in[k];
      const Vec3& b = in[(k + 1) % m];
      double da = Dot(a - p, n), db = Dot(b - p, n);
      if (da >= 0) out.push_back(a);
      if ((da > 0 && db < 0) || (da < 0 && db > 0)) out.push_back(a + (b - a) * (da / (da - db)));
    }
    // Nothing strictly in front (e.g. coplanar with the kernel): nothing to integrate.
    bool front = false;
    for (const Vec3& x : out) front = front || Dot(x - p, n) > 0;
    if (!front) out.clear();
    return out;
  }

  // Bisection of edge e (0: a-b, 1: b-c, 2: c-a) at its midpoint.
  static void BisectEdge(const Node& t, int e, Node* c0, Node* c1) {
    Vec3 a = t.a, b = t.b, c = t.c;  // Rotate so that (a, b) is the edge to cut.
    if (e == 1) {
      a = t.b, b = t.c, c = t.a;
    } else if (e == 2) {
      a = t.c, b = t.a, c = t.b;
    }
    const Vec3 m = (a + b) * 0.5;
    *c0 = {a, m, c, t.tri, t.depth + 1};
    *c1 = {m, b, c, t.tri, t.depth + 1};
  }

  static int LongestEdge(const Node& t) {
    const double ab = Dot(t.b - t.a, t.b - t.a), bc = Dot(t.c - t.b, t.c - t.b),
                 ca = Dot(t.a - t.c, t.a - t.c);
    if (bc >= ab && bc >= ca) return 1;
    if (ca >= ab && ca >= bc) return 2;
    return 0;
  }

  // Longest-edge bisection: keeps slivers from staying slivers along their length.
  static void Bisect(const Node& t, Node* c0, Node* c1) { BisectEdge(t, LongestEdge(t), c0, c1); }

  // A priori refinement, before the error estimate is trusted (it cannot see a feature that falls
  // between the rule's points of both a triangle and its halves, such as the end of a long strip
  // seen from the middle of another): split to a minimum depth; while large compared with the gap
  // to the kernel's bounding box (surfaces close to touching); and while large compared with the
  // distance to the nearest kernel vertex, which grades the triangles towards the kernel's corners
  // (down to triangles too small to matter, `floor` of area, where a corner touches).
  void Presplit(const Node& node, double floor, std::vector<Node>* out) {
    // Blockers make the kernel vary in bands (a blocker's shadow reaching the kernel's edge) that
    // can lie wholly between the rule's points of a large triangle: those pairs start finer (two
    // levels; UnseenBlockerBound catches most of what a coarser start still misses, and four
    // levels cost three times as much again for a smaller gain).
    const int min_depth = blockers_ != nullptr && !blockers_->empty() ? 4 : 2;
    bool split = node.depth < min_depth;
    int edge = -1;  // Longest edge unless set.
    if (!split && node.depth < 60 && TriArea(node.a, node.b, node.c) > floor) {
      Box b;
      b.Add(node.a);
      b.Add(node.b);
      b.Add(node.c);
      const double diam = std::sqrt(
          std::max({Dot(node.b - node.a, node.b - node.a), Dot(node.c - node.b, node.c - node.b),
                    Dot(node.a - node.c, node.a - node.c)}));
      // (Only when the surfaces do not touch: beside a shared edge the kernel is smooth across
      // the edge, and this rule would grade the triangles along the whole of it.)
      const double gap = b.Distance(ker_.box);
      split = surfaces_apart_ && gap > 0 && diam > 8 * gap;
      int nearest = -1;
      double nearest_distance = std::numeric_limits<double>::max();
      for (size_t k = 0; k < kernel_vertices_.size(); ++k) {
        Box v;
        v.Add(kernel_vertices_[k]);
        const double d = b.Distance(v);
        if (d < nearest_distance) {
          nearest_distance = d;
          nearest = static_cast<int>(k);
        }
      }
      if (!split && nearest >= 0 && diam > 2 * nearest_distance) {
        split = true;
        // A triangle with the kernel vertex as a corner is cut on the longer of that corner's
        // edges, so that one child keeps the corner and shrinks geometrically (cutting the
        // opposite edge would give both children the corner, and double them at every level).
        const Vec3& v = kernel_vertices_[nearest];
        const double tiny = 1e-12 * diam;
        const Vec3* corners[3] = {&node.a, &node.b, &node.c};
        for (int k = 0; k < 3; ++k) {
          if (Length(*corners[k] - v) > tiny) continue;
          // Edges e = k (k -> k+1) and e = k + 2 (k-1 -> k) touch corner k.
          const int e1 = k, e2 = (k + 2) % 3;
          const double l1 = Length(*corners[(k + 1) % 3] - *corners[k]);
          const double l2 = Length(*corners[(k + 2) % 3] - *corners[k]);
          edge = l1 >= l2 ? e1 : e2;
          break;
        }
      }
    }
    if (!split) {
      out->push_back(node);
      return;
    }
    Node c0, c1;
    if (edge >= 0) {
      BisectEdge(node, edge, &c0, &c1);
    } else {
      Bisect(node, &c0, &c1);
    }
    Presplit(c0, floor, out);
    Presplit(c1, floor, out);
  }

  // Anisotropic refinement: the rule is applied to the halves of all three bisections; the
  // largest change from the parent is the error estimate (so a variation across a sliver is seen
  // even when the sliver is long), and the triangle is cut along the longest edge unless another
  // cut changes the estimate clearly more (a kernel varying across a long sliver, as beside a
  // shared edge, is then resolved by thinner slivers instead of ever shorter ones).
  Item MakeItem(const Node& node, double value) {
    Item item;
    ++epoch_;  // The blockers the children's points see (VisibleKernel marks them).
    const int longest = LongestEdge(node);
    double best_delta = -1, err = 0;
    double longest_delta = 0;
    Node cut[3][2];
    double v[3][2];
    double delta[3];
    for (int e = 0; e < 3; ++e) {
      BisectEdge(node, e, &cut[e][0], &cut[e][1]);
      v[e][0] = Evaluate(cut[e][0]);
      v[e][1] = Evaluate(cut[e][1]);
      delta[e] = std::fabs(v[e][0] + v[e][1] - value);
      err = std::max(err, delta[e]);
      if (e == longest) longest_delta = delta[e];
    }
    int choice = longest;
    for (int e = 0; e < 3; ++e) {
      if (e != longest && delta[e] > 2 * longest_delta && delta[e] > best_delta) {
        choice = e;
        best_delta = delta[e];
      }
    }
    item.child[0] = cut[choice][0];
    item.child[1] = cut[choice][1];
    item.value[0] = v[choice][0];
    item.value[1] = v[choice][1];
    // A blocker that can cut a segment between the node and the kernel but whose shadow edge
    // crossed the kernel from none of the 42 points of the halves acts, if at all, in a band
    // between them, where comparing the halves with the parent cannot see it: its bound is added.
    // (Down to 2^-kBoundDepth of the domain triangle's area: bands thinner than that are left
    // to the estimate, so that a blocker whose plane runs through the domain cannot drive the
    // refinement along that line to kMaxSplits.)
    if (blockers_ != nullptr && node.depth < kBoundDepth) {
      err = std::max(err, UnseenBlockerBound(node));
    }
    if (blockers_ != nullptr && !blockers_->empty()) {
      err = std::max(err, BoundaryCheck(node, v[choice][0] + v[choice][1]));
    }
    item.err = err;
    return item;
  }

  // A shadow edge can also run beside the node's boundary, between its corners and the rule's
  // points nearest to them (a blocker's edge seen past a kernel's corner: a kink a few
  // millimetres from a node's edge, the kernel smooth and nearly linear at every one of the 42
  // points, so the halves agree with the parent to 1e-16 while the value is 1 % high). The
  // closed degree-3 rule on the corners, the edges' midpoints and the centroid (Stroud T2:3-1;
  // weights 1/20, 2/15, 9/20) sees the boundary: its difference from the refined value
  // `refined`, times kBoundaryWeight (the lower-order rule errs more where the kernel is
  // smooth), joins the estimate. Not where a point lies in the plane of a kernel polygon or on a
  // blocker (a corner on an edge the surfaces share, or on the line where a wall stands on the
  // domain: the kernel there, 0 or unblocked, is the limit from neither side).
  double BoundaryCheck(const Node& node, double refined) {
    const Tri& tri = dom_.tris[node.tri];
    const Vec3 points[7] = {node.a,
                            node.b,
                            node.c,
                            (node.a + node.b) * 0.5,
                            (node.b + node.c) * 0.5,
                            (node.c + node.a) * 0.5,
                            (node.a + node.b + node.c) / 3.0};
    for (const Vec3& y : points) {
      for (const Poly& q : ker_.polys) {
        if (std::fabs(Dot(y - q.v[0], q.n)) <= plane_eps_) return 0;
      }
      for (const Blocker* b : *blockers_) {
        if (std::fabs(Dot(y - b->v[0], b->n)) > plane_eps_) continue;
        // A face of a non-planar domain surface itself (y on it is in front of or behind it,
        // never seeing it edge-on from the side).
        if (std::fabs(Dot(b->n, tri.n)) > 1 - 1e-12 &&
            std::fabs(Dot(tri.a - b->v[0], b->n)) <= plane_eps_) {
          continue;
        }
        bool on = true;  // On the blocker (its edges included), not only in its plane.
        for (size_t k = 0; k < b->v.size() && on; ++k) {
          const Vec3& p = b->v[k];
          const Vec3 e = b->v[(k + 1) % b->v.size()] - p;
          on = Dot(Cross(e, y - p), b->n) >= -plane_eps_ * Length(e);
        }
        if (on) return 0;
      }
    }
    double corners = 0, midpoints = 0;
    for (int k = 0; k < 3; ++k) {
      corners += VisibleKernel(tri, points[k]);
      midpoints += VisibleKernel(tri, points[3 + k]);
    }
    const double q3 = TriArea(node.a, node.b, node.c) *
                      (corners / 20 + midpoints * 2 / 15 + VisibleKernel(tri, points[6]) * 9 / 20);
    return kBoundaryWeight * std::fabs(q3 - refined);
  }

  // A bound on what the points since the last ++epoch_ can have missed of the blockers whose
  // shadow edge crossed the kernel from none of them (pooled over the kernel's polygons: a
  // blocker whose edge crossed one of them gets no bound for the others). Such a blocker either
  // missed the kernel from every point, and may hide some of it in a band between them, or
  // covered it from every point, and some may show past its edge in such a band: from a point y
  // of the node, at most the factor of the part of the shaft's section it covers (CutShaft), or
  // of the part it leaves open, F <= A / (pi r^2) with r the least distance from y to that part
  // (both cosines at most 1), and never more than 1; times the node's area; at most the node's
  // area for each kernel polygon. A blocker that covers the whole section and has the node and
  // the kernel on either side hides the kernel from all of the node: nothing is missed.
  double UnseenBlockerBound(const Node& node) {
    const Tri& tri = dom_.tris[node.tri];
    const double node_area = TriArea(node.a, node.b, node.c);
    Box node_box;
    node_box.Add(node.a);
    node_box.Add(node.b);
    node_box.Add(node.c);
    double bound = 0;
    for (const Poly& q : ker_.polys) {
      if (q.input_face == tri.input_face) continue;
      // Only segments from the part of the node in front of q to the part of q in front of the
      // node's plane carry anything.
      ClipHalfSpace({node.a, node.b, node.c}, q.v[0], q.n, plane_eps_, &shaft_);
      if (shaft_.empty()) continue;
      const size_t near = shaft_.size();
      ClipHalfSpace(q.v, node.a, tri.n, plane_eps_, &clip_a_);
      if (clip_a_.empty()) continue;
      shaft_.insert(shaft_.end(), clip_a_.begin(), clip_a_.end());
      Box box;
      for (const Vec3& p : shaft_) box.Add(p);
      double q_bound = 0;
      for (size_t bi = 0; bi < blockers_->size(); ++bi) {
        // A blocker whose edge crossed the kernel from some point cannot hide all of it either.
        if (crosses_[bi] == epoch_) continue;
        const Blocker& b = *(*blockers_)[bi];
        if (box.Distance(b.box) > 0) continue;
        const ShaftCut cut = CutShaft(shaft_, near, b.v, b.n, shaft_eps_);
        if (cut.pierced <= 0) continue;
        const double negligible = 1e-9 * cut.section;
        if (cut.separates && cut.open <= negligible) {
          q_bound = 0;  // Wholly hidden.
          break;
        }
        // What it hides lies in its own part of the section; what it leaves open, in the rest.
        double area = 0;
        double r = node_box.Distance(cut.box);
        if (misses_[bi] == epoch_ && covers_[bi] != epoch_) {
          area = cut.pierced;
          r = node_box.Distance(cut.pierced_box);
        } else if (covers_[bi] == epoch_ && misses_[bi] != epoch_) {
          area = cut.open;
        } else {
          area = std::max(cut.pierced, cut.open);
        }
        if (area <= negligible) continue;
        q_bound += node_area * (r > 0 ? std::min(1.0, area / (kPi * r * r)) : 1.0);
      }
      bound += std::min(q_bound, node_area);
    }
    return bound;
  }

  double Evaluate(const Node& node) {
    const double area = TriArea(node.a, node.b, node.c);
    if (area <= 0) return 0;
    const Tri& tri = dom_.tris[node.tri];
    double s = 0;
    for (const RulePoint& q : Radon7()) {
      const Vec3 y = node.a * q.l0 + node.b * q.l1 + node.c * q.l2;
      s += q.w * (blockers_ != nullptr ? VisibleKernel(tri, y) : Kernel(tri, y));
    }
    return area * s;
  }

  // F_{dy -> kernel surface}: Lambert's formula over each kernel polygon y is in front of, clipped
  // to the tangent plane at y, times the visible fraction when something may be in between.
  double Kernel(const Tri& tri, const Vec3& y) {
    ++evaluations_;
    double f = 0;
    for (const Poly& q : ker_.polys) {
      if (q.input_face == tri.input_face) continue;
      if (Dot(y - q.v[0], q.n) <= plane_eps_) continue;  // y behind (or in) q's plane.
      f += PointToPolygonFormFactorClipped(y, tri.n, q.v.data(), static_cast<int>(q.v.size()));
    }
    return f;
  }

  // Exact occlusion (as NIST's View3D does it; Walton 2002): F_{dy -> visible part of the
  // kernel}. Each kernel polygon q, clipped to the tangent plane at y, is cut into convex pieces
  // by every blocker between y and q's plane: the blocker, clipped to the slab between y's height
  // above q's plane and that plane (and to the front of y's tangent plane), casts from y the
  // pyramid of the planes through y and its edges; a piece's parts outside each of those planes
  // stay, the part inside all of them (behind the blocker) goes. Lambert's formula over the pieces
  // that remain is the exact point factor to what y sees.
  double VisibleKernel(const Tri& tri, const Vec3& y) {
    ++evaluations_;
    double f = 0;
    // The pieces: polygons of pieces_.points, piece k from pieces_.start[k] to start[k + 1].
    auto add_piece = [](const std::vector<Vec3>& poly, Pieces* to) {
      to->points.insert(to->points.end(), poly.begin(), poly.end());
      to->start.push_back(static_cast<int>(to->points.size()));
    };
    for (const Poly& q : ker_.polys) {
      if (q.input_face == tri.input_face) continue;
      const double height = Dot(y - q.v[0], q.n);  // y above q's plane.
      if (height <= plane_eps_) continue;
      ClipHalfSpace(q.v, y, tri.n, 0, &clip_a_);
      if (clip_a_.empty()) continue;
      Box seen;  // What of q y can see at most.
      for (const Vec3& v : clip_a_) seen.Add(v);
      pieces_.points.clear();
      pieces_.start.assign(1, 0);
      add_piece(clip_a_, &pieces_);
      visible_q_ = clip_a_;
      // Each blocker's shadow from y: it misses q unless found to cover or cross it.
      state_.assign(blockers_->size(), &misses_);
      for (size_t bi = 0; bi < blockers_->size(); ++bi) {
        const Blocker* b = (*blockers_)[bi];
        // Quick rejects: wholly behind y's tangent plane, or outside the slab.
        double lo = std::numeric_limits<double>::max(), hi = -lo, front = -lo, back = lo;
        for (const Vec3& v : b->v) {
          const double d = Dot(v - q.v[0], q.n);
          lo = std::min(lo, d);
          hi = std::max(hi, d);
          const double ahead = Dot(v - y, tri.n);
          front = std::max(front, ahead);
          back = std::min(back, ahead);
        }
        if (front <= plane_eps_ || hi <= plane_eps_ || lo >= height - plane_eps_) continue;
        // Seen edge-on from y: it hides nothing.
        if (std::fabs(Dot(y - b->v[0], b->n)) <= plane_eps_) continue;
        // Clipped to the slab and to the front of y's tangent plane (a blocker wholly inside them,
        // the usual case, is its own clip: the clips below would keep every corner).
        const bool inside =
            back - plane_eps_ >= 0 && lo - plane_eps_ >= 0 && -hi - (plane_eps_ - height) >= 0;
        if (inside) {
          clip_b_.assign(b->v.begin(), b->v.end());
        } else {
          ClipHalfSpace(b->v, y, tri.n, plane_eps_, &clip_b_);
          ClipHalfSpace(clip_b_, q.v[0], q.n, plane_eps_, &clip_a_);
          ClipHalfSpace(clip_a_, q.v[0], -q.n, plane_eps_ - height, &clip_b_);
        }
        const std::vector<Vec3>& shade = clip_b_;
        if (shade.empty()) continue;
        // Its shadow on q's plane (the clipped blocker projected from y) must meet what y sees.
        Box cast;
        for (const Vec3& v : shade) {
          cast.Add(y + (v - y) * (height / (height - Dot(v - q.v[0], q.n))));
        }
        if (cast.Distance(seen) > plane_eps_) continue;
        // The pyramid's planes through y, oriented with the blocker inside.
        Vec3 centre;
        for (const Vec3& v : shade) centre += v;
        centre = centre / static_cast<double>(shade.size());
        planes_.clear();
        for (size_t k = 0; k < shade.size(); ++k) {
          const Vec3 m = Cross(shade[k] - y, shade[(k + 1) % shade.size()] - y);
          if (Dot(m, m) > 0) planes_.push_back(m);
        }
        if (planes_.empty()) continue;
        const double sign = Dot(centre - y, planes_[0]) >= 0 ? 1 : -1;
        // Whether the shadow covers all of q that y sees (every corner inside the pyramid), or
        // its edge may cross q (their boxes meet).
        bool covers = true;
        for (size_t k = 0; k < visible_q_.size() && covers; ++k) {
          for (const Vec3& m : planes_) {
            if (sign * Dot(visible_q_[k] - y, m) < 0) {
              covers = false;
              break;
            }
          }
        }
        state_[bi] = covers ? &covers_ : &crosses_;
        // Nothing of q left to hide: the state is all this blocker is asked for.
        if (pieces_.start.size() < 2) continue;
        // What is left inside every plane is behind the blocker.
        next_.points.clear();
        next_.start.assign(1, 0);
        for (size_t k = 0; k + 1 < pieces_.start.size(); ++k) {
          rest_.assign(pieces_.points.begin() + pieces_.start[k],
                       pieces_.points.begin() + pieces_.start[k + 1]);
          Box piece;
          for (const Vec3& v : rest_) piece.Add(v);
          if (piece.Distance(cast) > plane_eps_) {  // Wholly outside the shadow.
            add_piece(rest_, &next_);
            continue;
          }
          for (const Vec3& m : planes_) {
            // Wholly on one side of the plane: kept whole, or left whole for the next plane.
            bool in = true, out = true;
            for (const Vec3& v : rest_) {
              const double d = sign * Dot(v - y, m);
              in = in && d > 0;
              out = out && d < 0;
            }
            if (in) continue;
            if (out) {
              add_piece(rest_, &next_);
              rest_.clear();
              break;
            }
            ClipHalfSpace(rest_, y, m * -sign, 0, &out_);
            if (!out_.empty()) add_piece(out_, &next_);
            ClipHalfSpace(rest_, y, m * sign, 0, &out_);
            rest_.swap(out_);
            if (rest_.empty()) break;
          }
        }
        std::swap(pieces_, next_);
      }
      for (size_t bi = 0; bi < blockers_->size(); ++bi) (*state_[bi])[bi] = epoch_;
      for (size_t k = 0; k + 1 < pieces_.start.size(); ++k) {
        f += PointToPolygonFormFactorClipped(y, tri.n, pieces_.points.data() + pieces_.start[k],
                                             pieces_.start[k + 1] - pieces_.start[k]);
      }
    }
    return f;
  }

  // The visible part of the kernel's factor f = F_{dy -> kernel} seen from y. Shadow rays go to
  // stratified, area-uniform points x_k of the kernel (fresh for each y, so their errors average
  // out over the quadrature points); the blocked part is estimated without bias by
  //   B = (A / n) sum_k (1 - V_k) cos_y cos_x / (pi r^2)
  // and the result is f - B (a control variate: exact when nothing blocks). When every ray with a
  // positive kernel is blocked the answer is 0, when none is, f: both exact. (A ratio of weighted
  // sums, f sum w V / sum w, is biased by O(1/n): 4 % on the Cornell box floor at 16 rays.)
  double VisiblePart(const Tri& tri, const Vec3& y, double f, Rng& rng) {
    if (target_tris_.empty()) return f;
    const int count = shadow_rays_;
    const int rows = std::max(1, static_cast<int>(std::sqrt(static_cast<double>(count))));
    auto start = [&](int r) { return static_cast<int>(static_cast<int64_t>(r) * count / rows); };
    double blocked = 0;
    int seen = 0, hidden = 0;
    for (int row = 0; row < rows; ++row) {
      // Equal-area strata of the unit square: row i holds c_i cells of width 1 / c_i and height
      // c_i / count, mapped measure-preservingly onto the kernel (s picks a triangle by area, its
      // remainder and t place the point by the square-root map of Shirley & Chiu 1997).
      const int first = start(row), cells = start(row + 1) - first;
      for (int c = 0; c < cells; ++c) {
        const double su = (c + rng.Uniform()) / cells;
        const double t = (first + cells * rng.Uniform()) / count;
        double x = su * target_area_;
        size_t k = 0;
        while (k + 1 < target_tris_.size() && x >= target_tris_[k].area)
          x -= target_tris_[k++].area;
        const TargetTri& tt = target_tris_[k];
        if (tt.input_face == tri.input_face) continue;
        const double sr = std::sqrt(std::clamp(x / tt.area, 0.0, 1.0));
        const Vec3 target = tt.a * (1 - sr) + tt.b * (sr * (1 - t)) + tt.c * (sr * t);
        const Vec3 d = target - y;
        const double r2 = Dot(d, d);
        const double cy = Dot(d, tri.n), cx = -Dot(d, tt.n);
        if (cy <= 0 || cx <= 0 || r2 <= 0) continue;
        if (SegmentVisible(vis_, y, tri.face, target, tt.face, cx / std::sqrt(r2), &rays_)) {
          ++seen;
        } else {
          ++hidden;
          blocked += cy * cx / (kPi * r2 * r2);
        }
      }
    }
    if (hidden == 0) return f;
    if (seen == 0) return 0;
    return f - target_area_ / count * blocked;
  }

  // The kernel's mesh triangles (their faces are the ones the shadow rays end on).
  void MakeTargetTriangles() {
    for (const Tri& t : ker_.tris) {
      const double a = TriArea(t.a, t.b, t.c);
      if (a <= 0) continue;
      target_area_ += a;
      target_tris_.push_back({t.a, t.b, t.c, t.n, t.face, t.input_face, a});
    }
  }

  // Occluded pairs: the leaves of the unoccluded quadrature, refined (largest contribution first)
  // to at least kOccludedLeaves, and each rule point weighted by its visible fraction. The
  // adaptive error estimate is not used for the visibility: shadows are limited by the shadow-ray
  // sampling, which refining cannot improve, and it would chase the noise.
  double OccludedValue(const std::atomic<bool>* stop, bool* stopped) {
    constexpr size_t kOccludedLeaves = 1024;
    struct Leaf {
      Node node;
      double value;
    };
    auto by_value = [](const Leaf& x, const Leaf& y) { return x.value < y.value; };
    std::vector<Leaf> leaves;
    for (const Item& it : heap_) {
      leaves.push_back({it.child[0], it.value[0]});
      leaves.push_back({it.child[1], it.value[1]});
    }
    std::make_heap(leaves.begin(), leaves.end(), by_value);
    while (!leaves.empty() && leaves.size() < kOccludedLeaves) {
      std::pop_heap(leaves.begin(), leaves.end(), by_value);
      const Leaf leaf = leaves.back();
      leaves.pop_back();
      Node c[2];
      Bisect(leaf.node, &c[0], &c[1]);
      for (const Node& n : c) {
        leaves.push_back({n, Evaluate(n)});
        std::push_heap(leaves.begin(), leaves.end(), by_value);
      }
    }
    // Leaves in a fixed order (the heap's), each with its own random stream: deterministic.
    double total = 0;
    for (size_t i = 0; i < leaves.size(); ++i) {
      if ((i & 63) == 0 && stop != nullptr && stop->load(std::memory_order_relaxed)) {
        *stopped = true;
        return 0;
      }
      const Node& node = leaves[i].node;
      if (leaves[i].value <= 0) continue;
      const double area = TriArea(node.a, node.b, node.c);
      const Tri& tri = dom_.tris[node.tri];
      Rng rng(StreamKey(stream_, static_cast<uint64_t>(i)));
      double sum = 0;
      for (const RulePoint& q : Radon7()) {
        const Vec3 y = node.a * q.l0 + node.b * q.l1 + node.c * q.l2;
        const double f = Kernel(tri, y);
        if (f > 0) sum += q.w * VisiblePart(tri, y, f, rng);
      }
      total += area * sum;
    }
    return total;
  }

  const SurfaceGeom& dom_;
  const SurfaceGeom& ker_;
  const Visibility& vis_;
  bool occluded_;
  int shadow_rays_;
  uint64_t stream_;
  double plane_eps_;
  struct TargetTri {
    Vec3 a, b, c, n;
    int face, input_face;
    double area;
  };
  std::vector<TargetTri> target_tris_;
  double target_area_ = 0;
  std::vector<Vec3> kernel_vertices_;
  bool surfaces_apart_ = false;
  std::vector<Item> heap_;
  int64_t rays_ = 0;
  int64_t evaluations_ = 0;
  const std::vector<const Blocker*>* blockers_;
  // VisibleKernel's scratch.
  struct Pieces {
    std::vector<Vec3> points;
    std::vector<int> start;
  };
  Pieces pieces_, next_;
  std::vector<Vec3> clip_a_, clip_b_, rest_, out_, planes_;
  static constexpr int kBoundDepth = 20;
  static constexpr double kBoundaryWeight = 0.1;
  // Per blocker, the epoch in which a point last saw its shadow miss the kernel, cover all the
  // kernel the point sees, or have its edge cross the kernel.
  std::vector<uint32_t> misses_, covers_, crosses_;
  std::vector<Vec3> visible_q_;
  std::vector<std::vector<uint32_t>*> state_;
  uint32_t epoch_ = 0;
  std::vector<Vec3> shaft_;
  double shaft_eps_;
};

// Whether surface j has any point strictly in front of some domain triangle of i and i any point
// strictly in front of a polygon of j (otherwise F_ij = F_ji = 0).
bool FaceEachOther(const SurfaceGeom& a, const SurfaceGeom& b, double eps) {
  auto front_of = [&](const std::vector<Poly>& polys, const Vec3& p, const Vec3& n) {
    for (const Poly& q : polys) {
      for (const Vec3& x : q.v) {
        if (Dot(x - p, n) > eps) return true;
      }
    }
    return false;
  };
  bool b_sees = false, a_sees = false;
  for (const Poly& pa : a.polys) b_sees = b_sees || front_of(b.polys, pa.v[0], pa.n);
  for (const Poly& pb : b.polys) a_sees = a_sees || front_of(a.polys, pb.v[0], pb.n);
  return a_sees && b_sees;
}

absl::Status ValidateOptions(const ViewFactorOptions& o) {
  if (!o.from.empty() && o.enforce != "none") {
    return absl::InvalidArgumentError(
        absl::StrCat("enforce ", o.enforce, " needs every row, and --from computes only some"));
  }
  if (o.enforce != "none" && o.enforce != "reciprocity" && o.enforce != "closure") {
    return absl::InvalidArgumentError(
        absl::StrCat("enforce must be none, reciprocity or closure, got '", o.enforce, "'"));
  }
  if (o.occlusion != "exact" && o.occlusion != "sampled") {
    return absl::InvalidArgumentError(
        absl::StrCat("occlusion must be exact or sampled, got '", o.occlusion, "'"));
  }
  if (o.method != "analytic" && o.method != "montecarlo" && o.method != "hemicube") {
    return absl::InvalidArgumentError(absl::StrCat(
        "unknown view-factor method '", o.method, "' (expected analytic, montecarlo or hemicube)"));
  }
  if (!(o.tolerance > 0) || !(o.tolerance <= 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat("view-factor tolerance must be in (0, 1], got ", o.tolerance));
  }
  if (o.shadow_rays < 1 || o.shadow_rays > 65536) {
    return absl::InvalidArgumentError(
        absl::StrCat("shadow rays must be in [1, 65536], got ", o.shadow_rays));
  }
  if (o.rays_per_surface < 1 || o.rays_per_surface > (int64_t{1} << 40)) {
    return absl::InvalidArgumentError(
        absl::StrCat("rays per surface must be in [1, 2^40], got ", o.rays_per_surface));
  }
  if (o.sampling != "random" && o.sampling != "stratified" && o.sampling != "halton" &&
      o.sampling != "sobol") {
    return absl::InvalidArgumentError(absl::StrCat("unknown sampling '", o.sampling,
                                                   "' (expected random, stratified or halton)"));
  }
  if (o.hemicube_resolution < 2 || o.hemicube_resolution > 16384 ||
      o.hemicube_resolution % 2 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "hemicube resolution must be even and in [2, 16384], got ", o.hemicube_resolution));
  }
  if (o.hemicube_points < 1 || o.hemicube_points > (1 << 20)) {
    return absl::InvalidArgumentError(
        absl::StrCat("hemicube points must be in [1, 1048576], got ", o.hemicube_points));
  }
  if (o.threads < 0) {
    return absl::InvalidArgumentError(absl::StrCat("threads must be >= 0, got ", o.threads));
  }
  return absl::OkStatus();
}

bool Stopped(const std::atomic<bool>* stop) {
  return stop != nullptr && stop->load(std::memory_order_relaxed);
}

absl::Status Cancelled() { return absl::CancelledError("view-factor computation cancelled"); }

// Split cap of the adaptive quadrature per pair: pairs converge long before it (it only bounds
// pathological input).
constexpr int64_t kMaxSplits = int64_t{1} << 20;

// Mesh faces binned by their boxes into a uniform grid, for the faces reaching into a box
// (occlusion candidates of a pair, near pairs) without a scan of every face per query.
class FaceGrid {
 public:
  FaceGrid(const std::vector<Box>& boxes, const Box& all) : boxes_(boxes), all_(all) {
    const Vec3 size = all.hi - all.lo;
    // About 4 n cells (a few faces per occupied cell for shells of faces), at most 128 a side.
    const double cells = 4 * std::max<double>(1, static_cast<double>(boxes.size()));
    const int side = std::clamp(static_cast<int>(std::ceil(std::cbrt(cells))), 1, 128);
    const double largest = std::max({size.x, size.y, size.z, 1e-300});
    for (int a = 0; a < 3; ++a) {
      dims_[a] = std::max(1, static_cast<int>(std::ceil(side * size[a] / largest)));
      cell_[a] = std::max(size[a] / dims_[a], 1e-300);
    }
    cells_.resize(static_cast<size_t>(dims_[0]) * dims_[1] * dims_[2]);
    for (int f = 0; f < static_cast<int>(boxes.size()); ++f) {
      int lo[3], hi[3];
      Range(boxes[f], 0, lo, hi);
      const int64_t count = int64_t{hi[0] - lo[0] + 1} * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1);
      if (count > 64) {
        big_.push_back(f);  // Large faces (a whole wall) are checked by every query.
        continue;
      }
      for (int x = lo[0]; x <= hi[0]; ++x) {
        for (int y = lo[1]; y <= hi[1]; ++y) {
          for (int z = lo[2]; z <= hi[2]; ++z) cells_[Cell(x, y, z)].push_back(f);
        }
      }
    }
  }

  // The faces whose boxes overlap `box` by more than `eps` on every axis, ascending.
  void Query(const Box& box, double eps, std::vector<int>* out) const {
    out->clear();
    auto overlaps = [&](int f) {
      const Box& b = boxes_[f];
      for (int a = 0; a < 3; ++a) {
        if (!(b.hi[a] > box.lo[a] + eps && b.lo[a] < box.hi[a] - eps)) return false;
      }
      return true;
    };
    for (int f : big_) {
      if (overlaps(f)) out->push_back(f);
    }
    int lo[3], hi[3];
    Range(box, 0, lo, hi);
    for (int x = lo[0]; x <= hi[0]; ++x) {
      for (int y = lo[1]; y <= hi[1]; ++y) {
        for (int z = lo[2]; z <= hi[2]; ++z) {
          for (int f : cells_[Cell(x, y, z)]) {
            if (overlaps(f)) out->push_back(f);
          }
        }
      }
    }
    std::sort(out->begin(), out->end());
    out->erase(std::unique(out->begin(), out->end()), out->end());
  }

 private:
  void Range(const Box& b, double pad, int lo[3], int hi[3]) const {
    // Clamped before the conversion (a query box may reach far outside the grid).
    auto index = [&](double x, int a) {
      const double cell = std::floor((x - all_.lo[a]) / cell_[a]);
      return static_cast<int>(std::clamp(cell, 0.0, static_cast<double>(dims_[a] - 1)));
    };
    for (int a = 0; a < 3; ++a) {
      lo[a] = index(b.lo[a] - pad, a);
      hi[a] = index(b.hi[a] + pad, a);
    }
  }
  size_t Cell(int x, int y, int z) const {
    return (static_cast<size_t>(z) * dims_[1] + y) * dims_[0] + x;
  }

  const std::vector<Box>& boxes_;
  Box all_;
  int dims_[3] = {1, 1, 1};
  double cell_[3] = {1, 1, 1};
  std::vector<std::vector<int>> cells_;
  std::vector<int> big_;
};

// The exact (analytic) factor of one pair of surfaces, with its occlusion: the machinery of
// --method analytic, shared by the near pairs of --method montecarlo --near.
class ExactPairs {
 public:
  ExactPairs(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
             const ViewFactorOptions& options)
      : mesh_(mesh),
        visibility_(visibility),
        options_(options),
        geom_(BuildGeometry(scene, mesh)),
        plane_eps_(1e-12 * mesh.scale()),
        box_eps_(1e-9 * mesh.scale()),
        shaft_eps_(1e-9 * mesh.scale()) {
    face_boxes_.resize(mesh.faces().size());
    Box all;
    for (size_t f = 0; f < face_boxes_.size(); ++f) {
      for (const Vec3& p : mesh.faces()[f].p) face_boxes_[f].Add(p);
      all.Add(face_boxes_[f]);
    }
    grid_ = std::make_unique<FaceGrid>(face_boxes_, all);
    // Exact occlusion: every mesh face (or each of its halves) may block.
    blocker_start_.push_back(0);
    for (const MeshFace& mf : mesh.faces()) {
      if (options.occlusion == "exact") AddBlockers(mf);
      blocker_start_.push_back(static_cast<int>(blockers_.size()));
    }
  }

  const std::vector<SurfaceGeom>& geom() const { return geom_; }
  const FaceGrid& grid() const { return *grid_; }
  double plane_eps() const { return plane_eps_; }

  // Whether i and j can exchange anything at all (see FaceEachOther; a surface sees itself only
  // if its polygons are not all in one plane).
  bool MaySee(int i, int j) const {
    if (geom_[i].area <= 0 || geom_[j].area <= 0) return false;
    if (j == i && (geom_[i].coplanar || geom_[i].polys.size() < 2)) return false;
    return FaceEachOther(geom_[i], geom_[j], plane_eps_);
  }

  // G = A_i F_ij = A_j F_ji to the tolerance; false when stopped.
  bool Integrate(int i, int j, const std::atomic<bool>* stop, double* g, int64_t* rays) const {
    // Integrate over the smaller surface; the larger is the kernel.
    int d = i, k = j;
    if (geom_[k].area < geom_[d].area) std::swap(d, k);
    Box pair_box = geom_[d].box;
    pair_box.Add(geom_[k].box);
    std::vector<int> faces;
    grid_->Query(pair_box, box_eps_, &faces);
    // May be occluded: another surface's face reaches into the pair's bounding box (which holds
    // every segment between them), or a surface of the pair is not planar (it may shade itself).
    bool occluded = (!geom_[d].coplanar && geom_[d].polys.size() > 1) ||
                    (!geom_[k].coplanar && geom_[k].polys.size() > 1);
    for (size_t q = 0; q < faces.size() && !occluded; ++q) {
      const int s = mesh_.faces()[faces[q]].surface;
      occluded = s != d && s != k;
    }
    // Exact occlusion: the blockers of those faces, those of a planar surface of the pair left
    // out.
    std::vector<const Blocker*> candidates;
    bool exact = false;
    if (occluded && !blockers_.empty()) {
      // Every segment between the pair lies in the convex hull of their corners: a blocker that
      // does not cut into it (CutShaft) hides nothing of the pair. (Surfaces of many faces keep
      // the box test alone: the hull's cost grows with the square of its points.)
      std::vector<Vec3> hull;
      for (const Tri& t : geom_[d].tris) hull.insert(hull.end(), {t.a, t.b, t.c});
      for (const Poly& q : geom_[k].polys) hull.insert(hull.end(), q.v.begin(), q.v.end());
      const bool shaft = hull.size() <= kMaxShaftPoints;
      for (int f : faces) {
        for (int b = blocker_start_[f]; b < blocker_start_[f + 1]; ++b) {
          const Blocker& blocker = blockers_[b];
          if ((blocker.surface == d && geom_[d].coplanar) ||
              (blocker.surface == k && geom_[k].coplanar)) {
            continue;
          }
          bool overlap = true;
          for (int a = 0; a < 3 && overlap; ++a) {
            overlap = blocker.box.hi[a] > pair_box.lo[a] + box_eps_ &&
                      blocker.box.lo[a] < pair_box.hi[a] - box_eps_;
          }
          if (!overlap) continue;
          if (shaft &&
              CutShaft(hull, 0, blocker.v, blocker.n, shaft_eps_, /*any_pairs=*/true).pierced <=
                  0) {
            continue;
          }
          candidates.push_back(&blocker);
        }
      }
      // Nothing in the shaft (a surface's own faces included): nothing hides any of the pair.
      if (shaft && candidates.empty()) occluded = false;
      exact = candidates.size() <= static_cast<size_t>(kMaxExactBlockers);
    }
    PairIntegrator integrator(
        geom_[d], geom_[k], visibility_, occluded, options_.shadow_rays,
        StreamKey(options_.seed, static_cast<uint64_t>(i), static_cast<uint64_t>(j)), plane_eps_,
        exact ? &candidates : nullptr);
    // The tolerance is shared out over each row: an error of 0.5 tol (F_ij + 1 / n) in F_ij,
    // with n the number of surfaces, sums to at most tol over a row that closes (sum_j F_ij = 1),
    // so rows close to tol even where every factor errs the same way (as past an obstruction,
    // where a shadow's edge missed between quadrature points makes a factor high). In G = A_i F_ij
    // that is 0.5 tol (G + A_i / n), the smaller of the two rows' budgets, and never more than
    // 0.5 tol min(A_i, A_j) (each factor within tol). The near pairs of --method montecarlo
    // keep the tolerance per factor: the rays' part of their rows errs far more.
    const double smaller = std::min(geom_[d].area, geom_[k].area);
    const double cap = 0.5 * options_.tolerance * smaller;
    const PairIntegrator::Budget budget =
        options_.method == "analytic"
            ? PairIntegrator::Budget{cap / static_cast<double>(geom_.size()),
                                     0.5 * options_.tolerance, cap}
            : PairIntegrator::Budget{cap, 0, cap};
    double error = 0;
    if (!integrator.Run(budget, kMaxSplits, stop, g, &error)) return false;
    *rays = integrator.rays();
    return true;
  }

 private:
  void AddBlockers(const MeshFace& mf) {
    // A quad whose halves are coplanar and which turns the same way at every corner is one
    // convex blocker (fewer, larger blockers cut the visible polygon into fewer pieces).
    bool convex = !mf.triangle && mf.jacobian[0] > 0 && mf.jacobian[1] > 0 &&
                  Dot(mf.normal[0], mf.normal[1]) > 1 - 1e-12;
    const Vec3 ring[4] = {mf.p[0], mf.p[1], mf.p[2], mf.p[3]};
    for (int k = 0; k < 4 && convex; ++k) {
      const Vec3 turn = Cross(ring[(k + 1) % 4] - ring[k], ring[(k + 2) % 4] - ring[(k + 1) % 4]);
      convex = Dot(turn, mf.normal[0]) > 0;
    }
    for (int h = 0; h < (convex ? 1 : 2); ++h) {
      if (!convex && mf.jacobian[h] <= 0) continue;
      Blocker b;
      if (convex) {
        b.v.assign(ring, ring + 4);
      } else {
        b.v = h == 0 ? std::vector<Vec3>{mf.p[0], mf.p[1], mf.p[3]}
                     : std::vector<Vec3>{mf.p[2], mf.p[3], mf.p[1]};
      }
      b.n = mf.normal[convex ? 0 : h];
      for (const Vec3& v : b.v) b.box.Add(v);
      b.surface = mf.surface;
      blockers_.push_back(std::move(b));
    }
  }

  const Mesh& mesh_;
  const Visibility& visibility_;
  const ViewFactorOptions& options_;
  const std::vector<SurfaceGeom> geom_;
  const double plane_eps_, box_eps_, shaft_eps_;
  // The most corners of a pair for which a blocker is tested against their hull.
  static constexpr size_t kMaxShaftPoints = 64;
  std::vector<Box> face_boxes_;
  std::unique_ptr<FaceGrid> grid_;
  std::vector<Blocker> blockers_;
  std::vector<int> blocker_start_;  // Blockers of mesh face f: [start[f], start[f + 1]).
};

struct ExactPair {
  int i, j;
  double g = 0;  // A_i F_ij.
  int64_t rays = 0;
};

// F_ij = G / A_i and F_ji = G / A_j of an integrated pair into the rows (once for i == j).
void AddExactPair(const ExactPair& p, const std::vector<double>& area,
                  std::vector<std::vector<std::pair<int32_t, double>>>* rows, int64_t* rays) {
  (*rows)[p.i].push_back({p.j, p.g / area[p.i]});
  if (p.j != p.i) (*rows)[p.j].push_back({p.i, p.g / area[p.j]});
  *rays += p.rays;
}

// Integrates `pairs` on the arena's threads; false when stopped.
bool IntegratePairs(const ExactPairs& exact, std::vector<ExactPair>* pairs, tbb::task_arena* arena,
                    const std::atomic<bool>* stop) {
  std::atomic<bool> cancelled{false};
  arena->execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, pairs->size(), 1),
                      [&](const tbb::blocked_range<size_t>& range) {
                        for (size_t p = range.begin(); p < range.end(); ++p) {
                          if (Stopped(stop) || cancelled) {
                            cancelled = true;
                            return;
                          }
                          ExactPair& pair = (*pairs)[p];
                          if (!exact.Integrate(pair.i, pair.j, stop, &pair.g, &pair.rays)) {
                            cancelled = true;
                            return;
                          }
                        }
                      });
  });
  return !cancelled && !Stopped(stop);
}

}  // namespace

absl::StatusOr<ViewFactorMatrix> ComputeViewFactors(const Scene& scene,
                                                    const ViewFactorOptions& options,
                                                    const std::atomic<bool>* stop) {
  if (absl::Status st = ValidateOptions(options); !st.ok()) return st;
  const auto start = std::chrono::steady_clock::now();

  // One element per mesh face (an input polygon, or each quad of a larger polygon's fan).
  Box all;
  for (const Face& f : scene.faces) {
    for (int v : f.vertices) {
      if (v >= 0 && v < static_cast<int>(scene.vertices.size())) all.Add(scene.vertices[v]);
    }
  }
  if (all.empty()) return absl::InvalidArgumentError("the scene has no faces");
  MeshOptions mo;
  mo.patch_depth = 0;
  mo.element_size = std::max(2 * Length(all.hi - all.lo), 1e-300);
  absl::StatusOr<Mesh> mesh = Mesh::Build(scene, mo);
  if (!mesh.ok()) return mesh.status();
  // The BVH build too runs on the job's threads only.
  tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
  absl::StatusOr<std::unique_ptr<Visibility>> vis = Visibility::Build(*mesh, &arena);
  if (!vis.ok()) return vis.status();
  const Visibility& visibility = **vis;

  const int n = static_cast<int>(scene.surfaces.size());
  ViewFactorMatrix m;
  m.method = options.method;
  m.area.assign(n, 0.0);
  m.row_start.assign(n + 1, 0);
  for (const Surface& s : scene.surfaces) m.surfaces.push_back(s.name);
  const auto& elements = mesh->elements();
  for (const Element& e : elements) m.area[e.surface] += e.area;
  // --from: the rows to compute (the pairs with one of them; the other rows dropped at the end).
  std::vector<char> wanted(n, options.from.empty() ? 1 : 0);
  if (!options.from.empty()) {
    std::map<std::string_view, int> index;
    for (int i = 0; i < n; ++i) index.emplace(m.surfaces[i], i);
    for (const std::string& name : options.from) {
      const auto it = index.find(name);
      if (it == index.end()) {
        return absl::InvalidArgumentError(
            absl::StrCat("the rows to compute (--from, view_factor.from_surfaces): no surface "
                         "named '",
                         name, "' in the scene (", n, " surfaces)"));
      }
      wanted[it->second] = 1;
    }
    for (int i = 0; i < n; ++i) {
      if (wanted[i]) m.rows_only.push_back(i);
    }
  }
  auto set_wanted_rows = [&](std::vector<std::vector<std::pair<int32_t, double>>>* rows) {
    if (!m.rows_only.empty()) {
      for (int i = 0; i < n; ++i) {
        if (!wanted[i]) std::vector<std::pair<int32_t, double>>().swap((*rows)[i]);
      }
    }
    m.SetRows(rows);
  };

  std::atomic<bool> cancelled{false};

  if (options.method == "analytic") {
    const ExactPairs exact(scene, *mesh, visibility, options);
    std::vector<ExactPair> pairs;
    for (int i = 0; i < n; ++i) {
      if (Stopped(stop)) return Cancelled();
      if (!wanted[i]) continue;
      // Every pair once: (i, j) for j >= i, and for j < i unless row j is computed too.
      for (int j = 0; j < n; ++j) {
        if (j < i && wanted[j]) continue;
        const int a = std::min(i, j), b = std::max(i, j);
        if (exact.MaySee(a, b)) pairs.push_back({a, b});
      }
    }
    if (!IntegratePairs(exact, &pairs, &arena, stop)) return Cancelled();
    std::vector<std::vector<std::pair<int32_t, double>>> rows(n);
    for (const ExactPair& p : pairs) AddExactPair(p, m.area, &rows, &m.rays);
    set_wanted_rows(&rows);
  } else {
    // Monte Carlo or hemicube: one row per element, from the estimators, weighted by the element's
    // share of its surface's area; only front-to-front entries are kept.
    FormFactorOptions fo;
    fo.method = options.method;
    fo.sampling = options.sampling;
    fo.hemicube_resolution = options.hemicube_resolution;
    const int ne = static_cast<int>(elements.size());
    std::vector<int64_t> budget(ne, 0);
    std::vector<int> points(ne, 1);
    std::map<int, std::unique_ptr<FormFactorEstimator>> estimators;
    for (int e = 0; e < ne; ++e) {
      const double share = elements[e].area / m.area[elements[e].surface];
      budget[e] = wanted[elements[e].surface]
                      ? std::max<int64_t>(1, std::llround(options.rays_per_surface * share))
                      : 0;
      points[e] = options.method == "hemicube"
                      ? std::max(1, static_cast<int>(std::lround(options.hemicube_points * share)))
                      : 1;
      if (estimators.count(points[e]) == 0) {
        fo.hemicube_points = points[e];
        auto est = CreateFormFactorEstimator(*mesh, visibility, fo);
        if (!est.ok()) return est.status();
        estimators[points[e]] = std::move(*est);
      }
    }
    // --near: pairs of surfaces closer than `near` x the larger one's diagonal are integrated
    // exactly, and the rays' estimates of them dropped.
    std::vector<std::vector<int>> near(n);  // Ascending.
    std::vector<ExactPair> near_pairs;
    if (options.near > 0 && options.method == "montecarlo") {
      const ExactPairs exact(scene, *mesh, visibility, options);
      const auto& geom = exact.geom();
      std::vector<double> diag(n, 0.0);
      for (int i = 0; i < n; ++i) {
        if (!geom[i].box.empty()) diag[i] = Length(geom[i].box.hi - geom[i].box.lo);
      }
      std::vector<int> faces;
      for (int i = 0; i < n; ++i) {
        if (Stopped(stop)) return Cancelled();
        if (geom[i].box.empty()) continue;
        const double reach = options.near * diag[i];
        Box query = geom[i].box;
        query.lo = query.lo - Vec3{reach, reach, reach};
        query.hi = query.hi + Vec3{reach, reach, reach};
        exact.grid().Query(query, 0, &faces);
        for (int f : faces) {
          const int j = mesh->faces()[f].surface;
          if (!near[i].empty() && near[i].back() == j) continue;
          if (geom[i].box.Distance(geom[j].box) < options.near * std::max(diag[i], diag[j])) {
            near[i].push_back(j);
          }
        }
        if (std::find(near[i].begin(), near[i].end(), i) == near[i].end()) near[i].push_back(i);
      }
      // Symmetric: j near i when i is near j.
      for (int i = 0; i < n; ++i) {
        for (int j : near[i]) {
          if (j != i && (near[j].empty() || near[j].back() != i)) near[j].push_back(i);
        }
      }
      for (int i = 0; i < n; ++i) {
        std::sort(near[i].begin(), near[i].end());
        near[i].erase(std::unique(near[i].begin(), near[i].end()), near[i].end());
        for (int j : near[i]) {
          if (j >= i && (wanted[i] || wanted[j]) && exact.MaySee(i, j)) {
            near_pairs.push_back({i, j});
          }
        }
      }
      if (!IntegratePairs(exact, &near_pairs, &arena, stop)) return Cancelled();
      m.near_pairs = static_cast<int64_t>(near_pairs.size());
    }
    struct RowResult {
      std::vector<std::pair<int, double>> to;  // (surface, F) of front slots, in slot order.
      int64_t rays = 0;
    };
    std::vector<RowResult> rows(ne);
    arena.execute([&] {
      tbb::parallel_for(tbb::blocked_range<int>(0, ne, 1), [&](const tbb::blocked_range<int>& r) {
        FormFactorRow row;
        for (int e = r.begin(); e < r.end(); ++e) {
          if (Stopped(stop) || cancelled) {
            cancelled = true;
            return;
          }
          if (!wanted[elements[e].surface]) continue;  // --from (the hemicube has no budget).
          FormFactorSource src;
          src.first_element = e;
          src.num_elements = 1;
          src.side = 0;
          estimators.at(points[e])->Estimate(
              src, budget[e], StreamKey(options.seed, static_cast<uint64_t>(e)), &row);
          RowResult& out = rows[e];
          for (size_t k = 0; k < row.slots.size(); ++k) {
            if (SideOfSlot(row.slots[k]) != kFront) continue;
            out.to.push_back({elements[ElementOfSlot(row.slots[k])].surface, row.f[k]});
          }
          out.rays = row.rays;
        }
      });
    });
    if (cancelled || Stopped(stop)) return Cancelled();
    std::vector<std::vector<std::pair<int32_t, double>>> surface_rows(n);
    std::vector<double> far_sum(n, 0.0);
    for (int e = 0; e < ne; ++e) {
      const int i = elements[e].surface;
      const double share = elements[e].area / m.area[i];
      for (const auto& [j, f] : rows[e].to) {
        if (std::binary_search(near[i].begin(), near[i].end(), j)) continue;
        surface_rows[i].push_back({j, share * f});
        far_sum[i] += share * f;
      }
      std::vector<std::pair<int, double>>().swap(rows[e].to);
      m.rays += rows[e].rays;
    }
    for (const ExactPair& p : near_pairs) AddExactPair(p, m.area, &surface_rows, &m.rays);
    if (options.method == "montecarlo") {
      // The standard error of a row's sum of ray-estimated factors S from R rays (binomial):
      // sqrt(S (1 - S) / R); each factor's is sqrt(F (1 - F) / R).
      for (int i = 0; i < n; ++i) {
        const double r = static_cast<double>(options.rays_per_surface);
        const double sum = std::clamp(far_sum[i], 0.0, 1.0);
        m.ray_row_error = std::max(m.ray_row_error, std::sqrt(sum * (1 - sum) / r));
      }
    }
    set_wanted_rows(&surface_rows);
  }
  if (absl::Status st = visibility.status(); !st.ok()) return st;
  absl::StatusOr<ViewFactorCorrection> corrected = EnforceViewFactors(&m, options.enforce, stop);
  if (!corrected.ok()) return corrected.status();
  m.enforced = options.enforce;
  m.max_reciprocity_error_before = corrected->before.max_reciprocity_error;
  m.max_closure_error_before = corrected->before.max_closure_error;
  m.smallest_entry = corrected->smallest_entry;
  m.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return m;
}

double ViewFactorMatrix::at(int i, int j) const {
  const auto begin = col.begin() + row_start[i], end = col.begin() + row_start[i + 1];
  const auto it = std::lower_bound(begin, end, j);
  return it != end && *it == j ? val[it - col.begin()] : 0.0;
}

void ViewFactorMatrix::SetDense(const std::vector<double>& dense) {
  const int n = size();
  row_start.assign(1, 0);
  col.clear();
  val.clear();
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const double f = dense[static_cast<size_t>(i) * n + j];
      if (f == 0) continue;
      col.push_back(j);
      val.push_back(f);
    }
    row_start.push_back(static_cast<int64_t>(val.size()));
  }
}

void ViewFactorMatrix::SetRows(std::vector<std::vector<std::pair<int32_t, double>>>* rows) {
  row_start.assign(1, 0);
  col.clear();
  val.clear();
  int64_t total = 0;
  for (const auto& r : *rows) total += static_cast<int64_t>(r.size());
  col.reserve(total);
  val.reserve(total);
  for (auto& r : *rows) {
    std::sort(r.begin(), r.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (size_t k = 0; k < r.size();) {
      const int32_t j = r[k].first;
      double f = 0;
      for (; k < r.size() && r[k].first == j; ++k) f += r[k].second;
      if (f == 0) continue;
      col.push_back(j);
      val.push_back(f);
    }
    row_start.push_back(static_cast<int64_t>(val.size()));
    std::vector<std::pair<int32_t, double>>().swap(r);
  }
  rows->clear();
}

ViewFactorCheck CheckViewFactors(const ViewFactorMatrix& matrix) {
  ViewFactorCheck check;
  const int n = matrix.size();
  check.row_sums.assign(n, 0.0);
  std::vector<char> computed(n, matrix.rows_only.empty() ? 1 : 0);
  for (int32_t i : matrix.rows_only) computed[i] = 1;
  for (int i = 0; i < n; ++i) {
    if (!computed[i]) continue;
    for (int64_t k = matrix.row_start[i]; k < matrix.row_start[i + 1]; ++k) {
      const int j = matrix.col[k];
      check.row_sums[i] += matrix.val[k];
      if (j == i || !computed[j]) continue;
      // Each stored entry against its transpose (missing: 0), so both directions are seen.
      const double a = matrix.area[i] * matrix.val[k], b = matrix.area[j] * matrix.at(j, i);
      const double big = std::max(std::fabs(a), std::fabs(b));
      if (big > 0) {
        check.max_reciprocity_error = std::max(check.max_reciprocity_error, std::fabs(a - b) / big);
      }
    }
    check.max_closure_error = std::max(check.max_closure_error, std::fabs(1 - check.row_sums[i]));
  }
  return check;
}

absl::Status Validate(const ViewFactorOptions& o, FieldNaming naming) {
  static constexpr std::pair<const char*, const char*> kFlags[] = {
      {"method", "--method"},
      {"tolerance", "--tolerance"},
      {"occlusion", "--occlusion"},
      {"shadow_rays", "--shadow-rays"},
      {"rays_per_surface", "--rays-per-surface"},
      {"sampling", "--sampling"},
      {"hemicube_resolution", "--hemicube-resolution"},
      {"hemicube_points", "--hemicube-points"},
      {"threads", "--threads"},
      {"enforce", "--enforce"},
      {"ambient_temperature", "--ambient-temperature"},
      {"near", "--near"},
      {"from_surfaces", "--from"},
  };
  FieldChecker c([naming](const std::string& key) -> std::string {
    if (naming == FieldNaming::kField) return "view_factor." + key;
    if (key.rfind("thermal[", 0) == 0) return "--thermal";
    for (const auto& [k, flag] : kFlags) {
      if (key == k) return flag;
    }
    return key;
  });
  c.OneOf("method", o.method, {"analytic", "montecarlo", "hemicube"});
  c.InBounds("tolerance", o.tolerance, kViewFactorToleranceBounds);
  c.OneOf("occlusion", o.occlusion, {"exact", "sampled"});
  c.InBounds("shadow_rays", o.shadow_rays, kShadowRaysBounds);
  c.InBounds("rays_per_surface", static_cast<double>(o.rays_per_surface), kRaysPerSurfaceBounds);
  c.OneOf("sampling", o.sampling, {"random", "stratified", "halton", "sobol"});
  c.InBounds("hemicube_resolution", o.hemicube_resolution, kHemicubeResolutionBounds);
  if (o.hemicube_resolution % 2 != 0) {
    c.Fail("hemicube_resolution", absl::StrCat(o.hemicube_resolution, " is not even"));
  }
  c.InBounds("hemicube_points", o.hemicube_points, kHemicubePointsBounds);
  c.InBounds("threads", o.threads, kThreadsBounds);
  c.OneOf("enforce", o.enforce, {"none", "reciprocity", "closure"});
  c.InBounds("near", o.near, kNearBounds);
  if (o.near > 0 && o.method != "montecarlo") {
    c.Fail("near", absl::StrCat(o.near, ": near pairs apply to the montecarlo method only"));
  }
  if (!o.from.empty() && o.enforce != "none") {
    c.Fail("enforce", absl::StrCat(o.enforce, ": enforcement needs every row, and ",
                                   c.Label("from_surfaces"), " computes only some"));
  }
  if (!o.from.empty() && !o.thermal.empty()) {
    c.Fail("thermal[0]", absl::StrCat("radiative exchange needs every row, and ",
                                      c.Label("from_surfaces"), " computes only some"));
  }
  for (size_t k = 0; k < o.from.size(); ++k) {
    if (o.from[k].empty()) c.Fail("from_surfaces", absl::StrCat("name ", k + 1, " is empty"));
  }
  if (o.thermal.ambient_temperature != 0 && o.thermal.empty()) {
    c.Fail("ambient_temperature", "needs thermal data (--thermal, view_factor.thermal)");
  }
  for (size_t k = 0; k < o.thermal.surfaces.size(); ++k) {
    const SurfaceThermal& t = o.thermal.surfaces[k];
    const std::string key = absl::StrCat("thermal[", k, "]");
    if (t.surface.empty()) c.Fail(key, "the surface name is empty");
    if (absl::Status st = CheckSurfaceThermal(t); !st.ok()) c.Fail(key, std::string(st.message()));
  }
  if (!(o.thermal.ambient_temperature >= 0) || !std::isfinite(o.thermal.ambient_temperature)) {
    c.Fail("ambient_temperature",
           absl::StrCat(o.thermal.ambient_temperature, " K is not a finite number >= 0"));
  }
  return c.status();
}

}  // namespace radiosity
