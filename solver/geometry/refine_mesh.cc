#include "solver/geometry/refine_mesh.h"

#include <algorithm>
#include <array>
#include <functional>
#include <map>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace radiosity {

// Friend of Mesh: edits quadtrees in place.
class MeshRefiner {
 public:
  static Mesh Refine(const Scene& scene, const Mesh& in, const std::vector<int>& elements) {
    Mesh mesh = in;
    for (int e : elements) {
      const Element& el = in.elements()[e];
      const MeshFace& f = in.faces()[el.face];
      double su = f.len_u * (el.u1 - el.u0), sv = f.len_v * (el.v1 - el.v0);
      uint8_t split = su > 2 * sv   ? QuadNode::kSplitU
                      : sv > 2 * su ? QuadNode::kSplitV
                                    : QuadNode::kSplitBoth;
      mesh.SplitNode(el.node, split);
    }
    Balance(&mesh);
    mesh.Enumerate(scene);
    return mesh;
  }

  static absl::StatusOr<Mesh> FromRects(const Scene& scene, const Mesh& base,
                                        const std::vector<ElementRect>& rects,
                                        std::vector<int>* local) {
    Mesh mesh = base;
    const int faces = static_cast<int>(mesh.faces_.size());
    auto rect_text = [&](int i) {
      const ElementRect& r = rects[i];
      return absl::StrFormat("element %d (face %d, u %g..%g, v %g..%g)", i, r.face, r.u0, r.u1,
                             r.v0, r.v1);
    };
    // Each rectangle goes to the leaf of `base` holding its centre.
    std::map<int, std::vector<int>> by_leaf;
    for (size_t i = 0; i < rects.size(); ++i) {
      const ElementRect& r = rects[i];
      if (r.face < 0 || r.face >= faces || !(r.u0 >= 0 && r.u0 < r.u1 && r.u1 <= 1) ||
          !(r.v0 >= 0 && r.v0 < r.v1 && r.v1 <= 1)) {
        return absl::InvalidArgumentError(absl::StrCat(
            rect_text(static_cast<int>(i)), ": not a rectangle of one of the ", faces, " faces"));
      }
      by_leaf[mesh.FindLeaf(r.face, 0.5 * (double{r.u0} + r.u1), 0.5 * (double{r.v0} + r.v1))]
          .push_back(static_cast<int>(i));
    }
    // Splits node n until the rectangles `inside` it are its leaves. Splits are at midpoints, so
    // a rectangle narrower than the node in u lies in one u half: the node splits in u exactly
    // when no rectangle spans its whole width (the same leaves whichever order the server split
    // in), and likewise in v.
    std::function<absl::Status(int, const std::vector<int>&, int)> split =
        [&](int n, const std::vector<int>& inside, int depth) -> absl::Status {
      const QuadNode node = mesh.nodes_[n];
      if (inside.empty()) return absl::OkStatus();  // No element: must have no area (checked).
      if (inside.size() == 1) {
        const ElementRect& r = rects[inside[0]];
        if (node.u0 == r.u0 && node.u1 == r.u1 && node.v0 == r.v0 && node.v1 == r.v1) {
          return absl::OkStatus();
        }
      }
      bool split_u = true, split_v = true;
      for (int i : inside) {
        const ElementRect& r = rects[i];
        if (!(node.u0 <= r.u0 && r.u1 <= node.u1 && node.v0 <= r.v0 && r.v1 <= node.v1)) {
          return absl::InvalidArgumentError(
              absl::StrCat(rect_text(i), ": overlaps the edge of a quadtree node (u ", node.u0,
                           "..", node.u1, ", v ", node.v0, "..", node.v1, ")"));
        }
        split_u &= r.u1 - r.u0 < node.u1 - node.u0;
        split_v &= r.v1 - r.v0 < node.v1 - node.v0;
      }
      // Halving is exact in float down to 2^-24 of the square: 40 levels cannot be legitimate.
      if ((!split_u && !split_v) || depth >= 40) {
        return absl::InvalidArgumentError(
            absl::StrCat(rect_text(inside[0]), ": overlaps ", inside.size() - 1,
                         " other elements or is not reachable by halving the first mesh's leaves"));
      }
      const uint8_t how = split_u && split_v ? QuadNode::kSplitBoth
                          : split_u          ? QuadNode::kSplitU
                                             : QuadNode::kSplitV;
      const int first = mesh.SplitNode(n, how);
      const int nchild = how == QuadNode::kSplitBoth ? 4 : 2;
      std::vector<std::vector<int>> parts(nchild);
      for (int i : inside) {
        const ElementRect& r = rects[i];
        const int leaf = mesh.Descend(n, 0.5 * (double{r.u0} + r.u1), 0.5 * (double{r.v0} + r.v1));
        parts[leaf - first].push_back(i);
      }
      for (int c = 0; c < nchild; ++c) {
        if (absl::Status st = split(first + c, parts[c], depth + 1); !st.ok()) return st;
      }
      return absl::OkStatus();
    };
    for (const auto& [leaf, inside] : by_leaf) {
      if (absl::Status st = split(leaf, inside, 0); !st.ok()) return st;
    }
    mesh.Enumerate(scene);
    local->assign(rects.size(), -1);
    std::vector<char> taken(mesh.elements_.size(), 0);
    for (size_t i = 0; i < rects.size(); ++i) {
      const ElementRect& r = rects[i];
      const int n = mesh.FindLeaf(r.face, 0.5 * (double{r.u0} + r.u1), 0.5 * (double{r.v0} + r.v1));
      const QuadNode& leaf = mesh.nodes_[n];
      const int e = leaf.element;
      if (e < 0 || taken[e] || leaf.u0 != r.u0 || leaf.u1 != r.u1 || leaf.v0 != r.v0 ||
          leaf.v1 != r.v1) {
        return absl::InvalidArgumentError(absl::StrCat(
            rect_text(static_cast<int>(i)), e < 0 ? ": has no area" : ": overlaps another"));
      }
      taken[e] = 1;
      (*local)[i] = e;
    }
    if (mesh.elements_.size() != rects.size()) {
      return absl::InvalidArgumentError(
          absl::StrCat(rects.size(), " rectangles leave parts of the faces uncovered (",
                       mesh.elements_.size(), " elements)"));
    }
    return mesh;
  }

 private:
  // Splits leaves until every leaf's edge is at most twice as long as the edges of the leaves
  // across it (2:1 balance within each face), so T-vertices are edge midpoints.
  static void Balance(Mesh* mesh) {
    const float kOut = 1e-6f;
    for (int pass = 0; pass < 32; ++pass) {
      bool changed = false;
      const int count = static_cast<int>(mesh->nodes_.size());
      for (int n = 0; n < count; ++n) {
        const QuadNode leaf = mesh->nodes_[n];
        if (leaf.child >= 0) continue;
        const int face = leaf.face;
        const float du = leaf.u1 - leaf.u0, dv = leaf.v1 - leaf.v0;
        const float um = 0.5f * (leaf.u0 + leaf.u1), vm = 0.5f * (leaf.v0 + leaf.v1);
        // Neighbours across the edges v = v0 and v = v1 (edges along u), then u = u0 and u1.
        const struct {
          double u, v;
          bool along_u;
        } probes[4] = {{um, leaf.v0 - kOut, true},
                       {um, leaf.v1 + kOut, true},
                       {leaf.u0 - kOut, vm, false},
                       {leaf.u1 + kOut, vm, false}};
        for (const auto& probe : probes) {
          if (probe.u < 0 || probe.u > 1 || probe.v < 0 || probe.v > 1) continue;
          int other = mesh->FindLeaf(face, probe.u, probe.v);
          const QuadNode& o = mesh->nodes_[other];
          float extent = probe.along_u ? o.u1 - o.u0 : o.v1 - o.v0;
          float mine = probe.along_u ? du : dv;
          if (extent > 2.5f * mine) {
            mesh->SplitNode(other, probe.along_u ? QuadNode::kSplitU : QuadNode::kSplitV);
            changed = true;
          }
        }
      }
      // FindLeaf descends from the lattice, which still points at the (now split) nodes.
      if (!changed) break;
    }
  }
};

Mesh RefineMesh(const Scene& scene, const Mesh& mesh, const std::vector<int>& elements) {
  return MeshRefiner::Refine(scene, mesh, elements);
}

absl::StatusOr<Mesh> MeshFromElementRects(const Scene& scene, const Mesh& base,
                                          const std::vector<ElementRect>& rects,
                                          std::vector<int>* local) {
  return MeshRefiner::FromRects(scene, base, rects, local);
}

}  // namespace radiosity
