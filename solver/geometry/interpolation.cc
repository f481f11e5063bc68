#include "solver/geometry/interpolation.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace radiosity {

void LocalCoords(const Element& e, double u, double v, double* s, double* t) {
  double du = e.u1 - e.u0, dv = e.v1 - e.v0;
  *s = du > 0 ? std::clamp((u - e.u0) / du, 0.0, 1.0) : 0.5;
  *t = dv > 0 ? std::clamp((v - e.v0) / dv, 0.0, 1.0) : 0.5;
}

namespace {

// The normal bound within which faces of one surface blend their shading (the agglomeration's,
// and at least kCoplanarDegrees, so that a planar wall written as triangles or as slightly
// non-planar quads reads as one surface).
constexpr double kCoplanarDegrees = 1;
// At a point shared by more faces than this (a cylinder's cap, a pole of a fine UV sphere, or
// hostile input), faces blend with those of their surface within the bound of the surface's mean
// normal there rather than of their own (linear, not quadratic, in the faces).
constexpr int kMaxPairwiseFaces = 64;

// One corner to set: the value of `element`'s sides at `point` of `face`, weighted by `weight`,
// written to corners[target / 4][target % 4].
struct CornerRecord {
  std::array<int32_t, 3> point;  // Quantised position.
  int32_t face;
  int32_t element;
  float weight;
  int64_t target;
  bool operator<(const CornerRecord& o) const {
    return point != o.point ? point < o.point
                            : (face != o.face ? face < o.face : target < o.target);
  }
};

// Records of one face at one point, summed.
struct FaceSum {
  int32_t face;
  size_t first, last;  // Its records.
  double weight = 0;
  Rgb front, back;
};

// Sets the corners of records [first, last), all at one point: each face's to the mean over the
// faces there of its surface within min_cos of its normal (its own always included; beyond
// kMaxPairwiseFaces, see there); `sums` is scratch.
void BlendGroup(const Mesh& mesh, const Solution& solution, double min_cos,
                const std::vector<CornerRecord>& records, size_t first, size_t last,
                std::vector<FaceSum>* sums, std::vector<std::array<Rgb, 4>>* corners) {
  const auto& faces = mesh.faces();
  sums->clear();
  for (size_t i = first; i < last; ++i) {
    const CornerRecord& rec = records[i];
    if (sums->empty() || sums->back().face != rec.face) sums->push_back({rec.face, i, i});
    FaceSum& s = sums->back();
    s.last = i + 1;
    s.weight += rec.weight;
    s.front += SideRadiosity(solution, rec.element, 0) * rec.weight;
    s.back += SideRadiosity(solution, rec.element, 1) * rec.weight;
  }
  // Many faces: per surface, the faces within the bound of its mean normal, summed.
  std::vector<std::pair<int, Vec3>> mean_normal;  // (surface, area-weighted normal sum)
  std::vector<FaceSum> surface_sum;               // Same order; face = -1.
  auto surface_index = [&](int surface) {
    for (size_t k = 0; k < mean_normal.size(); ++k) {
      if (mean_normal[k].first == surface) return k;
    }
    mean_normal.push_back({surface, Vec3()});
    surface_sum.push_back({-1, 0, 0});
    return mean_normal.size() - 1;
  };
  const bool pairwise = static_cast<int>(sums->size()) <= kMaxPairwiseFaces;
  if (!pairwise) {
    for (const FaceSum& other : *sums) {
      const MeshFace& o = faces[other.face];
      mean_normal[surface_index(o.surface)].second += o.Normal() * other.weight;
    }
    for (auto& [surface, n] : mean_normal) n = Normalize(n);
    for (const FaceSum& other : *sums) {
      const MeshFace& o = faces[other.face];
      const size_t k = surface_index(o.surface);
      if (Dot(o.Normal(), mean_normal[k].second) < min_cos) continue;
      surface_sum[k].weight += other.weight;
      surface_sum[k].front += other.front;
      surface_sum[k].back += other.back;
    }
  }
  for (const FaceSum& own : *sums) {
    double weight = 0;
    Rgb front, back;
    const MeshFace& f = faces[own.face];
    const Vec3 n = f.Normal();
    if (pairwise) {
      for (const FaceSum& other : *sums) {
        if (&other != &own) {
          const MeshFace& o = faces[other.face];
          if (o.surface != f.surface || Dot(o.Normal(), n) < min_cos) continue;
        }
        weight += other.weight;
        front += other.front;
        back += other.back;
      }
    } else {
      const size_t k = surface_index(f.surface);
      const bool within = Dot(n, mean_normal[k].second) >= min_cos;
      const FaceSum& sum = within ? surface_sum[k] : own;
      weight = sum.weight;
      front = sum.front;
      back = sum.back;
    }
    if (!(weight > 0)) {
      // Sides of no area only (not made by Mesh::Build): a plain mean of the face's own.
      weight = static_cast<double>(own.last - own.first);
      front = back = Rgb{};
      for (size_t i = own.first; i < own.last; ++i) {
        front += SideRadiosity(solution, records[i].element, 0);
        back += SideRadiosity(solution, records[i].element, 1);
      }
    }
    for (size_t i = own.first; i < own.last; ++i) {
      const int64_t t = records[i].target;
      (*corners)[static_cast<size_t>(t / 4)][t % 4] = front / weight;
      (*corners)[static_cast<size_t>(t / 4) ^ 1][t % 4] = back / weight;
    }
  }
}

// Sets every corner listed to the area-weighted mean, over the records at its point, of the
// element sides of faces on the same surface whose normals lie within `degrees` of its face's
// (its own face always included). Targets are the front slot's (even); the back is the next.
void BlendAtPoints(const Mesh& mesh, const Solution& solution, double degrees,
                   std::vector<CornerRecord>* records, std::vector<std::array<Rgb, 4>>* corners) {
  tbb::parallel_sort(records->begin(), records->end());
  const double min_cos = std::cos(degrees * kPi / 180) - 1e-9;
  std::vector<size_t> groups;  // Starts of the runs of one point, and the end.
  for (size_t i = 0; i < records->size(); ++i) {
    if (i == 0 || (*records)[i].point != (*records)[i - 1].point) groups.push_back(i);
  }
  groups.push_back(records->size());
  tbb::parallel_for(
      tbb::blocked_range<size_t>(0, groups.size() - 1), [&](const tbb::blocked_range<size_t>& r) {
        std::vector<FaceSum> sums;
        for (size_t g = r.begin(); g != r.end(); ++g) {
          BlendGroup(mesh, solution, min_cos, *records, groups[g], groups[g + 1], &sums, corners);
        }
      });
}

}  // namespace

std::vector<std::array<Rgb, 4>> CornerRadiosity(const Mesh& mesh, const Solution& solution) {
  const auto& elements = mesh.elements();
  const int64_t n = static_cast<int64_t>(elements.size());
  std::vector<std::array<Rgb, 4>> corners(static_cast<size_t>(2 * n));
  if (n == 0) return corners;

  // One entry per element corner, keyed by (face, round(u 2^20), round(v 2^20)); sorting groups
  // the corners that coincide on the face's lattice.
  struct Entry {
    uint64_t uv;
    int32_t face;
    int32_t index;  // 4 * element + corner (corner: 0 = (u0,v0), 1 = (u1,v0), 2 = (u0,v1), 3).
    bool operator<(const Entry& o) const {
      return face != o.face ? face < o.face : (uv != o.uv ? uv < o.uv : index < o.index);
    }
  };
  auto quantise = [](double x) { return static_cast<uint64_t>(std::llround(x * 1048576.0)); };
  std::vector<Entry> entries(static_cast<size_t>(4 * n));
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, n), [&](const tbb::blocked_range<int64_t>& r) {
    for (int64_t e = r.begin(); e != r.end(); ++e) {
      const Element& el = elements[e];
      const double us[2] = {el.u0, el.u1}, vs[2] = {el.v0, el.v1};
      for (int c = 0; c < 4; ++c) {
        Entry& en = entries[static_cast<size_t>(4 * e + c)];
        en.uv = (quantise(us[c & 1]) << 32) | quantise(vs[c >> 1]);
        en.face = el.face;
        en.index = static_cast<int32_t>(4 * e + c);
      }
    }
  });
  tbb::parallel_sort(entries.begin(), entries.end());

  // Each group: B(corner) = sum(A_e B_e) / sum(A_e) over the element sides touching it, front
  // and back separately.
  const size_t total = entries.size();
  for (size_t i = 0; i < total;) {
    size_t j = i;
    double w = 0;
    Rgb front, back;
    for (; j < total && entries[j].face == entries[i].face && entries[j].uv == entries[i].uv; ++j) {
      int e = entries[j].index / 4;
      double a = elements[e].area;
      w += a;
      front += SideRadiosity(solution, e, 0) * a;
      back += SideRadiosity(solution, e, 1) * a;
    }
    if (w > 0) {
      front = front / w;
      back = back / w;
    } else {
      // Zero-area sides only (not made by Mesh::Build): a plain mean.
      front = back = Rgb{};
      for (size_t k = i; k < j; ++k) {
        front += SideRadiosity(solution, entries[k].index / 4, 0);
        back += SideRadiosity(solution, entries[k].index / 4, 1);
      }
      front = front / static_cast<double>(j - i);
      back = back / static_cast<double>(j - i);
    }
    for (size_t k = i; k < j; ++k) {
      int e = entries[k].index / 4, c = entries[k].index % 4;
      corners[Slot(e, 0)][c] = front;
      corners[Slot(e, 1)][c] = back;
    }
    i = j;
  }

  // Across faces: at every point where faces meet (a shared vertex, or element corners that
  // coincide on a shared edge), each face's corners take the mean over the faces of its surface
  // within the shading bound, so that a surface written as many faces shades as one. Whole-face
  // elements read per-face corner sets (appended after the element sides), split faces their
  // element corners; corners beyond a triangle's diagonal lie on no surface and keep the lattice's.
  const auto& faces = mesh.faces();
  const int64_t nf = static_cast<int64_t>(faces.size());
  std::vector<int32_t> whole_face_element(static_cast<size_t>(nf), -1);
  for (int64_t e = 0; e < n; ++e) {
    if (!CoversWholeFaces(elements[e])) continue;
    for (int m = 0; m < mesh.FaceCount(static_cast<int>(e)); ++m) {
      whole_face_element[mesh.FaceOf(static_cast<int>(e), m)] = static_cast<int32_t>(e);
    }
  }
  const bool any_whole = std::any_of(whole_face_element.begin(), whole_face_element.end(),
                                     [](int32_t e) { return e >= 0; });
  if (any_whole) corners.resize(static_cast<size_t>(2 * (n + nf)));
  const double cell = std::max(mesh.scale(), 1e-300) * std::ldexp(1.0, -26);
  auto point_key = [cell](const Vec3& p) {
    auto q = [cell](double x) {
      return static_cast<int32_t>(
          std::clamp<long long>(std::llround(x / cell), -2147483647LL, 2147483647LL));
    };
    return std::array<int32_t, 3>{q(p.x), q(p.y), q(p.z)};
  };
  // (u, v) corner c of the parameter square: c00, c10, c01, c11 are p0, p1, p3, p2.
  static constexpr int kCornerVertex[4] = {0, 1, 3, 2};
  std::vector<CornerRecord> records;
  records.reserve(static_cast<size_t>(4 * n));
  for (int64_t e = 0; e < n; ++e) {
    const Element& el = elements[e];
    if (CoversWholeFaces(el)) continue;
    const MeshFace& f = faces[el.face];
    const double us[2] = {el.u0, el.u1}, vs[2] = {el.v0, el.v1};
    for (int c = 0; c < 4; ++c) {
      const double u = us[c & 1], v = vs[c >> 1];
      if (f.triangle && u + v > 1 + 1e-9) continue;
      const bool vertex = (u == 0 || u == 1) && (v == 0 || v == 1);
      const Vec3 p = vertex ? f.p[kCornerVertex[(u == 1 ? 1 : 0) + (v == 1 ? 2 : 0)]]
                            : f.EvalOnHalf(f.Half(u, v), u, v);
      records.push_back({point_key(p), el.face, static_cast<int32_t>(e),
                         static_cast<float>(el.area), 4 * static_cast<int64_t>(Slot(e, 0)) + c});
    }
  }
  for (int64_t f = 0; f < nf; ++f) {
    const int32_t e = whole_face_element[f];
    if (e < 0) continue;
    const MeshFace& face = faces[f];
    for (int c = 0; c < (face.triangle ? 3 : 4); ++c) {
      records.push_back(
          {point_key(face.p[kCornerVertex[c]]), static_cast<int32_t>(f), e,
           static_cast<float>(face.Area()),
           4 * static_cast<int64_t>(FaceCornerSlot(mesh, static_cast<int>(f), 0)) + c});
    }
  }
  BlendAtPoints(mesh, solution, std::max(mesh.agglomerate_degrees(), kCoplanarDegrees), &records,
                &corners);
  records = std::vector<CornerRecord>();

  // T-vertices of an adaptively refined mesh: a corner of smaller elements lying inside the edge
  // of a larger neighbour (its midpoint, as refinement keeps neighbours within 2:1) takes the
  // value interpolated along that edge, so shading is continuous across the edge (no cracks).
  // Larger elements first, so that chains of constraints resolve from the coarsest edge down.
  std::vector<int32_t> order(static_cast<size_t>(n));
  for (int64_t e = 0; e < n; ++e) order[e] = static_cast<int32_t>(e);
  std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
    double sa = (elements[a].u1 - elements[a].u0) + (elements[a].v1 - elements[a].v0);
    double sb = (elements[b].u1 - elements[b].u0) + (elements[b].v1 - elements[b].v0);
    return sa != sb ? sa > sb : a < b;
  });
  // Edges as (corner a, corner b) in the 0=(u0,v0), 1=(u1,v0), 2=(u0,v1), 3=(u1,v1) numbering.
  static constexpr int kEdges[4][2] = {{0, 1}, {2, 3}, {0, 2}, {1, 3}};
  // A T-vertex's edge may end at another T-vertex (of a larger edge): repeat until nothing
  // changes, which takes at most as many passes as the quadtrees are deep.
  for (int pass = 0; pass < 64; ++pass) {
    bool changed = false;
    for (int32_t e : order) {
      const Element& el = elements[e];
      const double us[2] = {el.u0, el.u1}, vs[2] = {el.v0, el.v1};
      for (const auto& edge : kEdges) {
        double um = 0.5 * (us[edge[0] & 1] + us[edge[1] & 1]);
        double vm = 0.5 * (vs[edge[0] >> 1] + vs[edge[1] >> 1]);
        Entry key{(quantise(um) << 32) | quantise(vm), el.face, -1};
        auto it = std::lower_bound(entries.begin(), entries.end(), key);
        if (it == entries.end() || it->face != el.face || it->uv != key.uv) continue;
        for (int side = 0; side < 2; ++side) {
          const auto& c = corners[Slot(e, side)];
          Rgb mid = (c[edge[0]] + c[edge[1]]) * 0.5;
          for (auto k = it; k != entries.end() && k->face == el.face && k->uv == key.uv; ++k) {
            Rgb& value = corners[Slot(k->index / 4, side)][k->index % 4];
            if (!(value == mid)) {
              value = mid;
              changed = true;
            }
          }
        }
      }
    }
    if (!changed) break;
  }
  // On a triangle, c11 = c10 + c01 - c00 makes Bilinear linear: over a whole face, and over an
  // element cut by the diagonal (whose c11 lies beyond it), so that along the diagonal the reading
  // is the blend of the corners on it.
  auto make_linear = [](std::array<Rgb, 4>* c) { (*c)[3] = (*c)[1] + (*c)[2] - (*c)[0]; };
  for (int64_t e = 0; e < n; ++e) {
    const Element& el = elements[e];
    if (!faces[el.face].triangle || CoversWholeFaces(el)) continue;
    const double u0 = el.u0, v0 = el.v0, u1 = el.u1, v1 = el.v1;
    if (u1 + v1 > 1 + 1e-9 && u1 + v0 <= 1 + 1e-9 && u0 + v1 <= 1 + 1e-9) {
      make_linear(&corners[Slot(e, 0)]);
      make_linear(&corners[Slot(e, 1)]);
    }
  }
  if (any_whole) {
    for (int64_t f = 0; f < nf; ++f) {
      if (whole_face_element[f] < 0 || !faces[f].triangle) continue;
      make_linear(&corners[FaceCornerSlot(mesh, static_cast<int>(f), 0)]);
      make_linear(&corners[FaceCornerSlot(mesh, static_cast<int>(f), 1)]);
    }
  }
  return corners;
}

}  // namespace radiosity
