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

// CornerRadiosity's per-face corner sets of the faces whole-face elements hold (see the header),
// appended to `corners`.
void WholeFaceCorners(const Mesh& mesh, const Solution& solution,
                      std::vector<std::array<Rgb, 4>>* corners) {
  const auto& faces = mesh.faces();
  const int nf = static_cast<int>(faces.size());
  // The element of each face a whole-face element holds (-1 for the others).
  std::vector<int32_t> element_of(static_cast<size_t>(nf), -1);
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    if (!CoversWholeFaces(mesh.elements()[e])) continue;
    for (int m = 0; m < mesh.FaceCount(static_cast<int>(e)); ++m) {
      element_of[mesh.FaceOf(static_cast<int>(e), m)] = static_cast<int32_t>(e);
    }
  }
  // The distinct vertices of a face, in corner order p0, p1, p3, p2 (c00, c10, c01, c11).
  auto corner_vertex = [&](const MeshFace& f, int c) {
    static constexpr int kCorner[4] = {0, 1, 3, 2};
    return f.vertex[kCorner[c]];
  };
  // Vertex -> the faces of whole-face elements around it (CSR).
  int32_t max_vertex = -1;
  for (int f = 0; f < nf; ++f) {
    if (element_of[f] < 0) continue;
    for (int c = 0; c < 4; ++c) max_vertex = std::max(max_vertex, faces[f].vertex[c]);
  }
  std::vector<int64_t> start(static_cast<size_t>(max_vertex) + 2, 0);
  auto for_each_vertex = [&](int f, auto&& fn) {
    const MeshFace& face = faces[f];
    const int corners_of_face = face.triangle ? 3 : 4;
    for (int c = 0; c < corners_of_face; ++c) fn(corner_vertex(face, c));
  };
  for (int f = 0; f < nf; ++f) {
    if (element_of[f] >= 0) for_each_vertex(f, [&](int32_t v) { ++start[v + 1]; });
  }
  for (size_t v = 1; v < start.size(); ++v) start[v] += start[v - 1];
  std::vector<int32_t> around(static_cast<size_t>(start.back()));
  {
    std::vector<int64_t> next(start.begin(), start.end() - 1);
    for (int f = 0; f < nf; ++f) {
      if (element_of[f] >= 0) for_each_vertex(f, [&](int32_t v) { around[next[v]++] = f; });
    }
  }
  const double min_cos = std::cos(mesh.agglomerate_degrees() * kPi / 180) - 1e-9;
  const size_t base = 2 * mesh.elements().size();
  corners->resize(base + 2 * static_cast<size_t>(nf));
  tbb::parallel_for(tbb::blocked_range<int>(0, nf), [&](const tbb::blocked_range<int>& r) {
    for (int f = r.begin(); f != r.end(); ++f) {
      if (element_of[f] < 0) continue;
      const MeshFace& face = faces[f];
      const Vec3 n = face.Normal();
      std::array<Rgb, 4> front, back;
      for (int c = 0; c < (face.triangle ? 3 : 4); ++c) {
        const int32_t v = corner_vertex(face, c);
        double w = 0;
        for (int64_t k = start[v]; k < start[v + 1]; ++k) {
          const MeshFace& g = faces[around[k]];
          if (g.surface != face.surface || Dot(g.Normal(), n) < min_cos) continue;
          const double a = g.Area();
          w += a;
          front[c] += SideRadiosity(solution, element_of[around[k]], 0) * a;
          back[c] += SideRadiosity(solution, element_of[around[k]], 1) * a;
        }
        if (w > 0) {  // w = 0 only for a face of no area: its own element's value.
          front[c] = front[c] / w;
          back[c] = back[c] / w;
        } else {
          front[c] = SideRadiosity(solution, element_of[f], 0);
          back[c] = SideRadiosity(solution, element_of[f], 1);
        }
      }
      if (face.triangle) {
        front[3] = front[1] + front[2] - front[0];
        back[3] = back[1] + back[2] - back[0];
      }
      (*corners)[base + 2 * static_cast<size_t>(f)] = front;
      (*corners)[base + 2 * static_cast<size_t>(f) + 1] = back;
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
  if (std::any_of(elements.begin(), elements.end(), CoversWholeFaces)) {
    WholeFaceCorners(mesh, solution, &corners);
  }
  return corners;
}

}  // namespace radiosity
