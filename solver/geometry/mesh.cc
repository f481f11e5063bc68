#include "solver/geometry/mesh.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace radiosity {

std::string MeshOptions::ToString() const {
  return absl::StrFormat("MeshOptions{element_size=%g max_elements=%d patch_depth=%d}",
                         element_size, max_elements, patch_depth);
}

Vec3 MeshFace::Eval(double u, double v) const {
  if (u + v <= 1.0) return p[0] + u * (p[1] - p[0]) + v * (p[3] - p[0]);
  return p[2] + (1.0 - u) * (p[3] - p[2]) + (1.0 - v) * (p[1] - p[2]);
}

double ElementPiece::ParamArea() const {
  // Shoelace formula.
  double a = 0;
  for (int k = 0; k < n; ++k) {
    int k1 = (k + 1) % n;
    a += uv[2 * k] * uv[2 * k1 + 1] - uv[2 * k1] * uv[2 * k + 1];
  }
  return 0.5 * std::fabs(a);
}

namespace {

// Splits of a node: which axes of a node of physical size (su, sv) to halve for target size L.
uint8_t ChooseSplit(double su, double sv, double target) {
  // A small slack keeps an edge of exactly k * L from being split once more by rounding.
  const double limit = target * (1 + 1e-5);
  bool split_u = su > limit, split_v = sv > limit;
  return static_cast<uint8_t>((split_u ? QuadNode::kSplitU : 0) |
                              (split_v ? QuadNode::kSplitV : 0));
}

// Number of halvings needed to bring `length` to at most `target`.
int Halvings(double length, double target) {
  int k = 0;
  const double limit = target * (1 + 1e-5);
  while (length > limit && k < 40) {
    length *= 0.5;
    ++k;
  }
  return k;
}

// Clips a convex polygon against the half-plane s * (u + v - 1) <= 0 (Sutherland-Hodgman).
void ClipDiagonal(const ElementPiece& in, double s, ElementPiece* out) {
  out->n = 0;
  for (int k = 0; k < in.n; ++k) {
    int k1 = (k + 1) % in.n;
    double ua = in.uv[2 * k], va = in.uv[2 * k + 1];
    double ub = in.uv[2 * k1], vb = in.uv[2 * k1 + 1];
    double da = s * (ua + va - 1.0), db = s * (ub + vb - 1.0);
    if (da <= 0) {
      out->uv[2 * out->n] = ua;
      out->uv[2 * out->n + 1] = va;
      ++out->n;
    }
    if ((da < 0 && db > 0) || (da > 0 && db < 0)) {
      double t = da / (da - db);
      out->uv[2 * out->n] = ua + t * (ub - ua);
      out->uv[2 * out->n + 1] = va + t * (vb - va);
      ++out->n;
    }
  }
}

// The traced faces of a validated polygon: a quad, a triangle, or a fan of quads (and a last
// triangle) for polygons with more vertices. Pieces with no area are skipped.
std::vector<std::array<int, 4>> SplitPolygon(const std::vector<int>& v) {
  std::vector<std::array<int, 4>> out;
  const int n = static_cast<int>(v.size());
  if (n == 3) return {{v[0], v[1], v[2], v[2]}};
  for (int k = 1; k + 1 < n; k += 2) {
    if (k + 2 < n) {
      out.push_back({v[0], v[k], v[k + 1], v[k + 2]});
    } else {
      out.push_back({v[0], v[k], v[k + 1], v[k + 1]});
    }
  }
  return out;
}

MeshFace MakeFace(const std::array<Vec3, 4>& p, int surface, int input_face) {
  MeshFace f;
  f.p = p;
  f.surface = surface;
  f.input_face = input_face;
  f.triangle = p[2] == p[3];
  Vec3 n0 = Cross(p[1] - p[0], p[3] - p[0]);
  Vec3 n1 = Cross(p[3] - p[2], p[1] - p[2]);
  f.jacobian = {Length(n0), f.triangle ? 0.0 : Length(n1)};
  f.normal[0] = Normalize(n0);
  f.normal[1] = f.jacobian[1] > 0 ? Normalize(n1) : f.normal[0];
  if (f.jacobian[0] <= 0) f.normal[0] = f.normal[1];
  f.len_u = std::max(Length(p[1] - p[0]), Length(p[2] - p[3]));
  f.len_v = std::max(Length(p[3] - p[0]), Length(p[2] - p[1]));
  return f;
}

// Patch grid and element lattice of a face for target element size L and patch depth.
void PlanFace(MeshFace* f, double target, int depth) {
  const double patch_size = target * std::ldexp(1.0, depth);
  f->pu = std::max(1, static_cast<int>(std::ceil(f->len_u / patch_size * (1 - 1e-9))));
  f->pv = std::max(1, static_cast<int>(std::ceil(f->len_v / patch_size * (1 - 1e-9))));
  f->nu = f->pu << Halvings(f->len_u / f->pu, target);
  f->nv = f->pv << Halvings(f->len_v / f->pv, target);
}

// Elements of a planned face: all lattice cells for a quad; for a triangle the cells whose
// lower-left corner lies below the diagonal (the others have no area).
int64_t FaceElementCount(const MeshFace& f) {
  if (!f.triangle) return static_cast<int64_t>(f.nu) * f.nv;
  int64_t count = 0;
  for (int i = 0; i < f.nu; ++i) {
    // Cells (i, j) with i/nu + j/nv < 1, i.e. j < nv (1 - i/nu).
    double limit = static_cast<double>(f.nv) * (f.nu - i) / f.nu;
    count += static_cast<int64_t>(std::ceil(limit - 1e-9));
  }
  return count;
}

struct Recentred {
  Vec3 origin;
  double scale = 0;
};

Recentred Recentre(const Scene& scene) {
  Vec3 lo{std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
          std::numeric_limits<double>::max()};
  Vec3 hi = -lo;
  for (const Face& face : scene.faces) {
    for (int v : face.vertices) {
      lo = Min(lo, scene.vertices[v]);
      hi = Max(hi, scene.vertices[v]);
    }
  }
  return {(lo + hi) * 0.5, Length(hi - lo)};
}

std::vector<MeshFace> MakeFaces(const Scene& scene, const Vec3& origin) {
  std::vector<MeshFace> faces;
  faces.reserve(scene.faces.size());
  for (size_t fi = 0; fi < scene.faces.size(); ++fi) {
    const Face& face = scene.faces[fi];
    for (const auto& q : SplitPolygon(face.vertices)) {
      std::array<Vec3, 4> p;
      for (int k = 0; k < 4; ++k) p[k] = scene.vertices[q[k]] - origin;
      MeshFace mf = MakeFace(p, face.surface, static_cast<int>(fi));
      for (int k = 0; k < 4; ++k) mf.vertex[k] = q[k];
      if (mf.jacobian[0] + mf.jacobian[1] > 0) faces.push_back(mf);
    }
  }
  return faces;
}

int64_t CountFaces(std::vector<MeshFace>* faces, double target, int depth) {
  int64_t total = 0;
  for (MeshFace& f : *faces) {
    PlanFace(&f, target, depth);
    total += FaceElementCount(f);
  }
  return total;
}

// Whether a planned face is one element covering its whole parameter square (it can be
// agglomerated).
bool SingleElement(const MeshFace& f) { return f.pu == 1 && f.pv == 1 && f.nu == 1 && f.nv == 1; }

Vec3 FaceCentroid(const MeshFace& f) {
  // Area-weighted centroids of the two halves (triangles p0 p1 p3 and p2 p3 p1).
  const Vec3 c0 = (f.p[0] + f.p[1] + f.p[3]) / 3.0, c1 = (f.p[2] + f.p[3] + f.p[1]) / 3.0;
  const double a = f.jacobian[0] + f.jacobian[1];
  return a > 0 ? (c0 * f.jacobian[0] + c1 * f.jacobian[1]) / a : c0;
}

// The faces of each of `count` groups as compressed rows: group g's are
// items[start[g] .. start[g + 1]), in face order (label[f] < 0: in none).
void GroupRows(const std::vector<int32_t>& label, int32_t count, std::vector<int32_t>* start,
               std::vector<int32_t>* items) {
  start->assign(static_cast<size_t>(count) + 1, 0);
  for (int32_t g : label) {
    if (g >= 0) ++(*start)[g + 1];
  }
  for (int32_t g = 0; g < count; ++g) (*start)[g + 1] += (*start)[g];
  items->resize((*start)[count]);
  std::vector<int32_t> next(static_cast<size_t>(count));
  for (int32_t g = 0; g < count; ++g) next[g] = (*start)[g];
  for (int32_t f = 0; f < static_cast<int32_t>(label.size()); ++f) {
    if (label[f] >= 0) (*items)[next[label[f]]++] = f;
  }
}

// Patches of agglomerated elements: groups (labels `group`, `count` of them) that touch, of one
// surface, whose area-weighted normals lie within `min_cos` of the normal of the group a patch
// grows from, gathered breadth first up to the area `max_area` within `reach` of the seed's
// centroid; patches under a quarter of `max_area` then join their smallest neighbour within the
// bound. Relabels the groups so that each patch's are consecutive (in their old order) and
// returns in *patch_start the first group of each patch (and the count at the end).
void GroupPatches(const std::vector<MeshFace>& faces, const std::vector<int32_t>& start,
                  const std::vector<int32_t>& neighbours, int32_t count, double min_cos,
                  double max_area, double reach, std::vector<int32_t>* group,
                  std::vector<int32_t>* patch_start) {
  std::vector<double> area(count, 0);
  std::vector<Vec3> normal(count), moment(count);
  std::vector<int32_t> surface(count, -1);
  std::vector<std::pair<int32_t, int32_t>> pairs;
  for (int32_t f = 0; f < static_cast<int32_t>(faces.size()); ++f) {
    const int32_t g = (*group)[f];
    if (g < 0) continue;
    const double a = faces[f].Area();
    area[g] += a;
    normal[g] += faces[f].Normal() * a;
    moment[g] += FaceCentroid(faces[f]) * a;
    surface[g] = faces[f].surface;
    for (int32_t k = start[f]; k < start[f + 1]; ++k) {
      const int32_t h = (*group)[neighbours[k]];
      if (h >= 0 && h != g) pairs.push_back({g, h});
    }
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  std::vector<int32_t> adj_start(static_cast<size_t>(count) + 1, 0);
  for (const auto& p : pairs) ++adj_start[p.first + 1];
  for (int32_t g = 0; g < count; ++g) adj_start[g + 1] += adj_start[g];
  const std::vector<Vec3> normal_sum = normal;  // Area-weighted sums of the faces' normals.
  for (int32_t g = 0; g < count; ++g) normal[g] = Normalize(normal[g]);
  std::vector<int32_t> patch(count, -1), queue;
  int32_t patches = 0;
  for (int32_t seed = 0; seed < count; ++seed) {
    if (patch[seed] >= 0) continue;
    const int32_t k = patches++;
    const Vec3 c0 = moment[seed] / area[seed];
    double total = area[seed];
    patch[seed] = k;
    queue.assign(1, seed);
    for (size_t head = 0; head < queue.size(); ++head) {
      const int32_t g = queue[head];
      for (int32_t j = adj_start[g]; j < adj_start[g + 1]; ++j) {
        const int32_t h = pairs[j].second;
        if (patch[h] >= 0 || surface[h] != surface[seed] || total + area[h] > max_area ||
            Dot(normal[h], normal[seed]) < min_cos || Length(moment[h] / area[h] - c0) > reach) {
          continue;
        }
        total += area[h];
        patch[h] = k;
        queue.push_back(h);
      }
    }
  }
  // Scraps (patches under a quarter of the target area, left between grown ones) join the
  // smallest neighbouring patch of their surface whose normal (area-weighted, as merged so far) is
  // within the bound, as Agglomerate's scraps do, until none can: a patch of one or two elements
  // shares its light among too few to smooth its noise.
  std::vector<double> patch_area(patches, 0);
  std::vector<Vec3> patch_sum(patches);
  std::vector<int32_t> parent(patches);
  for (int32_t g = 0; g < count; ++g) {
    patch_area[patch[g]] += area[g];
    patch_sum[patch[g]] += normal_sum[g];
  }
  for (int32_t p = 0; p < patches; ++p) parent[p] = p;
  auto find = [&](int32_t p) {
    while (parent[p] != p) p = parent[p] = parent[parent[p]];
    return p;
  };
  for (bool merged = true; merged;) {
    merged = false;
    for (int32_t g = 0; g < count; ++g) {
      const int32_t self = find(patch[g]);
      if (patch_area[self] >= 0.25 * max_area) continue;
      int32_t best = -1;
      for (int32_t j = adj_start[g]; j < adj_start[g + 1]; ++j) {
        const int32_t h = pairs[j].second;
        const int32_t other = find(patch[h]);
        if (other == self || surface[h] != surface[g] ||
            Dot(Normalize(patch_sum[other]), Normalize(patch_sum[self])) < min_cos) {
          continue;
        }
        if (best < 0 || patch_area[other] < patch_area[best]) best = other;
      }
      if (best < 0) continue;
      parent[self] = best;
      patch_area[best] += patch_area[self];
      patch_sum[best] += patch_sum[self];
      merged = true;
    }
  }
  // Patches numbered in order of their first group; each one's groups in order.
  std::vector<int32_t> label(patches, -1), order;
  int32_t labels = 0;
  for (int32_t g = 0; g < count; ++g) {
    const int32_t root = find(patch[g]);
    if (label[root] < 0) label[root] = labels++;
    patch[g] = label[root];
  }
  GroupRows(patch, labels, patch_start, &order);
  std::vector<int32_t> relabel(count);
  for (int32_t i = 0; i < count; ++i) relabel[order[i]] = i;
  for (int32_t& g : *group) {
    if (g >= 0) g = relabel[g];
  }
}

// Faces sharing an edge (a pair of scene vertices), as compressed rows.
void BuildNeighbours(const std::vector<MeshFace>& faces, std::vector<int32_t>* start,
                     std::vector<int32_t>* neighbours) {
  struct EdgeRef {
    uint64_t key;
    int32_t face;
    bool operator<(const EdgeRef& o) const { return key != o.key ? key < o.key : face < o.face; }
  };
  std::vector<EdgeRef> edges;
  edges.reserve(4 * faces.size());
  for (int32_t f = 0; f < static_cast<int32_t>(faces.size()); ++f) {
    for (int k = 0; k < 4; ++k) {
      const uint32_t a = static_cast<uint32_t>(faces[f].vertex[k]);
      const uint32_t b = static_cast<uint32_t>(faces[f].vertex[(k + 1) % 4]);
      if (a == b) continue;
      edges.push_back({(uint64_t{std::min(a, b)} << 32) | std::max(a, b), f});
    }
  }
  std::sort(edges.begin(), edges.end());
  std::vector<std::pair<int32_t, int32_t>> pairs;
  for (size_t i = 0; i < edges.size();) {
    size_t j = i;
    while (j < edges.size() && edges[j].key == edges[i].key) ++j;
    // An edge of more than two faces (a fin) joins them all.
    for (size_t a = i; a < j; ++a) {
      for (size_t b = i; b < j && b - i < 8; ++b) {
        if (edges[a].face != edges[b].face) pairs.push_back({edges[a].face, edges[b].face});
      }
    }
    i = j;
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  start->assign(faces.size() + 1, 0);
  for (const auto& p : pairs) ++(*start)[p.first + 1];
  for (size_t f = 0; f < faces.size(); ++f) (*start)[f + 1] += (*start)[f];
  neighbours->resize(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) (*neighbours)[i] = pairs[i].second;
}

}  // namespace

int RectPieces(double u0, double v0, double u1, double v1, const MeshFace& face,
               std::array<ElementPiece, 2>* pieces) {
  ElementPiece rect;
  rect.n = 4;
  rect.uv = {u0, v0, u1, v0, u1, v1, u0, v1, 0, 0, 0, 0};
  int count = 0;
  if (u1 + v1 <= 1.0) {
    rect.half = 0;
    (*pieces)[count++] = rect;
    return count;
  }
  if (u0 + v0 >= 1.0) {
    if (face.jacobian[1] > 0) {
      rect.half = 1;
      (*pieces)[count++] = rect;
    }
    return count;
  }
  for (int half = 0; half < 2; ++half) {
    if (face.jacobian[half] <= 0) continue;
    ElementPiece piece;
    ClipDiagonal(rect, half == 0 ? 1.0 : -1.0, &piece);
    piece.half = half;
    if (piece.n >= 3 && piece.ParamArea() > 0) (*pieces)[count++] = piece;
  }
  return count;
}

int64_t Mesh::Agglomerate(double target, double degrees, std::vector<int32_t>* group,
                          int64_t* grouped) const {
  const int32_t n = static_cast<int32_t>(faces_.size());
  group->assign(faces_.size(), -1);
  *grouped = 0;
  const double min_cos = std::cos(degrees * kPi / 180);
  const double max_area = target * target;
  // Every face of a group lies within this distance of the centroid of the face it started from.
  const double reach = 0.75 * target;
  std::vector<double> group_area;
  std::vector<Vec3> group_normal;
  std::vector<int32_t> queue;
  // 1. Region growing from each face not yet taken, breadth first (rings about the seed).
  for (int32_t seed = 0; seed < n; ++seed) {
    const MeshFace& sf = faces_[seed];
    if ((*group)[seed] != -1 || !SingleElement(sf)) continue;
    const int32_t g = static_cast<int32_t>(group_area.size());
    const Vec3 n0 = sf.Normal(), c0 = FaceCentroid(sf);
    double area = sf.Area();
    (*group)[seed] = g;
    queue.assign(1, seed);
    for (size_t head = 0; head < queue.size(); ++head) {
      const int32_t f = queue[head];
      for (int32_t k = face_neighbour_start_[f]; k < face_neighbour_start_[f + 1]; ++k) {
        const int32_t h = face_neighbours_[k];
        const MeshFace& hf = faces_[h];
        if ((*group)[h] != -1 || hf.surface != sf.surface || !SingleElement(hf)) continue;
        if (area + hf.Area() > max_area || Dot(hf.Normal(), n0) < min_cos) continue;
        bool near = true;
        for (const Vec3& p : hf.p) near = near && Length(p - c0) <= reach;
        if (!near) continue;
        area += hf.Area();
        (*group)[h] = g;
        queue.push_back(h);
      }
    }
    group_area.push_back(area);
    group_normal.push_back(n0);
  }
  // 2. Scraps (under a quarter of the target area, left between grown groups) join the smallest
  // neighbouring group of their surface whose normal is within the bound, so that no element is
  // much smaller, and noisier, than the rest.
  const int32_t groups = static_cast<int32_t>(group_area.size());
  std::vector<int32_t> start, faces_of;
  GroupRows(*group, groups, &start, &faces_of);
  std::vector<int32_t> parent(groups);
  for (int32_t g = 0; g < groups; ++g) parent[g] = g;
  auto find = [&](int32_t g) {
    while (parent[g] != g) g = parent[g] = parent[parent[g]];
    return g;
  };
  for (int32_t g = 0; g < groups; ++g) {
    if (group_area[g] >= 0.25 * max_area) continue;
    int32_t best = -1;
    for (int32_t k = start[g]; k < start[g + 1]; ++k) {
      const int32_t f = faces_of[k];
      for (int32_t j = face_neighbour_start_[f]; j < face_neighbour_start_[f + 1]; ++j) {
        const int32_t h = face_neighbours_[j];
        if ((*group)[h] < 0 || faces_[h].surface != faces_[f].surface) continue;
        const int32_t other = find((*group)[h]);
        if (other == find(g) || Dot(group_normal[other], group_normal[g]) < min_cos) continue;
        if (best < 0 || group_area[other] < group_area[best]) best = other;
      }
    }
    if (best < 0) continue;
    const int32_t root = find(g);
    parent[root] = best;
    group_area[best] += group_area[root];
  }
  // 3. Labels: groups of two faces or more, numbered in order of their first face; and a face
  // alone (about the element size already) where it is part of a tessellated surface, an edge
  // neighbour of its surface within the bound being grouped too, so that patches can gather it
  // with its neighbours (GroupPatches) rather than give it one of its own, whose few rays would
  // be its light's only smoothing. A face alone on its surface (a lamp of one quad) stays a face.
  std::vector<int32_t> size(groups, 0), label(groups, -1);
  for (int32_t f = 0; f < n; ++f) {
    if ((*group)[f] >= 0) ++size[find((*group)[f])];
  }
  auto tessellated = [&](int32_t f) {
    for (int32_t j = face_neighbour_start_[f]; j < face_neighbour_start_[f + 1]; ++j) {
      const int32_t h = face_neighbours_[j];
      if ((*group)[h] >= 0 && faces_[h].surface == faces_[f].surface &&
          Dot(faces_[h].Normal(), faces_[f].Normal()) >= min_cos) {
        return true;
      }
    }
    return false;
  };
  int32_t labels = 0;
  for (int32_t f = 0; f < n; ++f) {
    if ((*group)[f] < 0) continue;
    const int32_t root = find((*group)[f]);
    if (size[root] < 2 && !tessellated(f)) {
      (*group)[f] = -1;
      continue;
    }
    if (label[root] < 0) label[root] = labels++;
    (*group)[f] = label[root];
    ++*grouped;
  }
  return labels;
}

int64_t Mesh::CountElements(const Scene& scene, double element_size, int patch_depth) {
  Recentred rc = Recentre(scene);
  std::vector<MeshFace> faces = MakeFaces(scene, rc.origin);
  return CountFaces(&faces, element_size, patch_depth);
}

absl::StatusOr<Mesh> Mesh::Build(const Scene& scene, const MeshOptions& options,
                                 const StopToken* stop, const ProgressCallback& progress) {
  constexpr char kMeshing[] = "meshing";
  if (!(options.element_size >= 0) || !std::isfinite(options.element_size)) {
    return absl::InvalidArgumentError(
        absl::StrCat("element size must be a positive number, got ", options.element_size));
  }
  if (options.element_size == 0 && options.max_elements < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("max elements must be at least 1, got ", options.max_elements));
  }
  if (options.patch_depth < 0 || options.patch_depth > 8) {
    return absl::InvalidArgumentError(
        absl::StrCat("patch depth must be in [0, 8], got ", options.patch_depth));
  }
  Mesh mesh;
  Recentred rc = Recentre(scene);
  mesh.origin_ = rc.origin;
  mesh.scale_ = rc.scale;
  mesh.faces_ = MakeFaces(scene, rc.origin);
  if (mesh.faces_.empty()) return absl::InvalidArgumentError("the scene has no faces with area");
  if (absl::Status st = StopStatus(stop, kMeshing); !st.ok()) return st;

  if (!(options.agglomerate_degrees >= 0 && options.agglomerate_degrees <= 90)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "agglomeration angle must be in [0, 90] degrees, got ", options.agglomerate_degrees));
  }
  const bool agglomerate = options.agglomerate_degrees > 0;
  mesh.agglomerate_degrees_ = options.agglomerate_degrees;
  if (agglomerate)
    BuildNeighbours(mesh.faces_, &mesh.face_neighbour_start_, &mesh.face_neighbours_);
  if (absl::Status st = StopStatus(stop, kMeshing); !st.ok()) return st;
  std::vector<int32_t> group;
  // Elements at size L: each face's, less the agglomerated faces', plus one per group.
  auto count_at = [&](double size) {
    int64_t total = CountFaces(&mesh.faces_, size, options.patch_depth);
    if (agglomerate) {
      int64_t grouped = 0;
      total += mesh.Agglomerate(size, options.agglomerate_degrees, &group, &grouped) - grouped;
    }
    return total;
  };
  double target = options.element_size;
  int64_t count = 0;
  if (target > 0) {
    // Guard the count itself: an absurdly small size would make per-face loops huge.
    double longest = 0;
    for (const MeshFace& f : mesh.faces_) longest = std::max({longest, f.len_u, f.len_v});
    if (longest / target > kMaxEdgeRatio) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "element size %g is too small for a scene whose longest edge is %g (over %g "
          "elements along one edge); the limit is %d elements",
          target, longest, kMaxEdgeRatio, options.element_limit));
    }
    count = count_at(target);
  } else {
    // Smallest size (by bisection in log space) whose mesh has at most max_elements elements
    // (agglomerating, to 1 %: each count groups every face again).
    double lo = rc.scale * 1e-7, hi = rc.scale * 2;
    const double ratio = agglomerate ? 1.01 : 1 + 1e-6;
    for (int it = 0; it < 60 && hi / lo > ratio; ++it) {
      // Each count is a pass over every face (and agglomerates them again).
      if (absl::Status st = StopStatus(stop, kMeshing); !st.ok()) return st;
      double mid = std::sqrt(lo * hi);
      if (count_at(mid) <= options.max_elements) {
        hi = mid;
      } else {
        lo = mid;
      }
    }
    target = hi;
    count = count_at(target);
  }
  if (count > options.element_limit) {
    return absl::ResourceExhaustedError(absl::StrFormat(
        "the mesh would have %d elements, above the limit of %d; use a larger element size", count,
        options.element_limit));
  }
  mesh.element_size_ = target;

  // Groups (Agglomerate): one element each, gathered into patches of about the patch
  // size (GroupPatches), each made at its first face; every face of a group has a root leaf of
  // its own that holds the group's element.
  std::vector<int32_t> patch_made;
  if (agglomerate) {
    int32_t groups = 0;
    for (int32_t g : group) groups = std::max(groups, g + 1);
    const double patch_size = target * std::ldexp(1.0, options.patch_depth);
    GroupPatches(mesh.faces_, mesh.face_neighbour_start_, mesh.face_neighbours_, groups,
                 std::cos(options.agglomerate_degrees * kPi / 180), patch_size * patch_size,
                 0.75 * patch_size, &group, &mesh.patch_groups_);
    GroupRows(group, groups, &mesh.group_start_, &mesh.group_faces_);
    mesh.group_patch_.assign(groups, -1);
    for (int32_t k = 0; k + 1 < static_cast<int32_t>(mesh.patch_groups_.size()); ++k) {
      for (int32_t g = mesh.patch_groups_[k]; g < mesh.patch_groups_[k + 1]; ++g) {
        mesh.group_patch_[g] = k;
      }
    }
    if (groups > 0) {
      mesh.face_group_ = std::move(group);
      mesh.face_node_.assign(mesh.faces_.size(), -1);
    }
    patch_made.assign(mesh.patch_groups_.empty() ? 0 : mesh.patch_groups_.size() - 1, -1);
  }

  if (absl::Status st = StopStatus(stop, kMeshing); !st.ok()) return st;
  mesh.elements_.reserve(count);
  // The faces split (the first half of the progress), then the patches enumerated.
  StepReporter reporter(progress);
  const double faces = static_cast<double>(mesh.faces_.size());
  for (int fi = 0; fi < static_cast<int>(mesh.faces_.size()); ++fi) {
    if (fi % 65536 == 65535) {
      if (absl::Status st = StopStatus(stop, kMeshing); !st.ok()) return st;
    }
    reporter.Report(0.5 * fi / faces);
    MeshFace& face = mesh.faces_[fi];
    const int32_t g = mesh.face_group_.empty() ? -1 : mesh.face_group_[fi];
    if (g >= 0) {
      QuadNode root;
      root.u0 = root.v0 = 0;
      root.u1 = root.v1 = 1;
      root.face = fi;
      mesh.face_node_[fi] = static_cast<int32_t>(mesh.nodes_.size());
      mesh.nodes_.push_back(root);
      const int32_t k = mesh.group_patch_[g];
      if (patch_made[k] < 0) {
        patch_made[k] = static_cast<int32_t>(mesh.patches_.size());
        Patch patch;
        patch.face = fi;
        patch.root = mesh.face_node_[fi];
        mesh.patches_.push_back(patch);
      }
      face.first_patch = patch_made[k];
      continue;
    }
    face.first_patch = static_cast<int>(mesh.patches_.size());
    const double du = 1.0 / face.pu, dv = 1.0 / face.pv;
    for (int j = 0; j < face.pv; ++j) {
      for (int i = 0; i < face.pu; ++i) {
        Patch patch;
        patch.face = fi;
        patch.root = static_cast<int>(mesh.nodes_.size());
        QuadNode root;
        root.u0 = static_cast<float>(i * du);
        root.v0 = static_cast<float>(j * dv);
        root.u1 = i + 1 == face.pu ? 1.0f : static_cast<float>((i + 1) * du);
        root.v1 = j + 1 == face.pv ? 1.0f : static_cast<float>((j + 1) * dv);
        root.face = fi;
        mesh.nodes_.push_back(root);
        // Node sizes are tracked in double: float (u, v) differences are too coarse for slivers.
        struct Pending {
          int node;
          double su, sv;
        };
        std::vector<Pending> stack{{patch.root, face.len_u * du, face.len_v * dv}};
        while (!stack.empty()) {
          const Pending pending = stack.back();
          stack.pop_back();
          uint8_t split = ChooseSplit(pending.su, pending.sv, target);
          if (split == QuadNode::kLeaf) continue;
          int first = mesh.SplitNode(pending.node, split);
          const double csu = split & QuadNode::kSplitU ? 0.5 * pending.su : pending.su;
          const double csv = split & QuadNode::kSplitV ? 0.5 * pending.sv : pending.sv;
          int nchild = split == QuadNode::kSplitBoth ? 4 : 2;
          for (int c = 0; c < nchild; ++c) stack.push_back({first + c, csu, csv});
        }
        // Empty patches (beyond a triangle's diagonal) stay in the grid so that FindElement can
        // index patches directly; they have no elements and no area.
        mesh.patches_.push_back(patch);
      }
    }
  }
  mesh.Enumerate(scene, [&](double f) { reporter.Report(0.5 + 0.5 * f); });
  reporter.Report(1);
  return mesh;
}

int Mesh::SplitNode(int n, uint8_t split) {
  const QuadNode node = nodes_[n];
  int nchild = split == QuadNode::kSplitBoth ? 4 : 2;
  int first = static_cast<int>(nodes_.size());
  nodes_[n].child = first;
  nodes_[n].split = split;
  nodes_[n].element = -1;
  float um = 0.5f * (node.u0 + node.u1), vm = 0.5f * (node.v0 + node.v1);
  const bool su_split = split & QuadNode::kSplitU, sv_split = split & QuadNode::kSplitV;
  for (int c = 0; c < nchild; ++c) {
    // Children order: u-low before u-high, then v-low before v-high.
    bool high_u = split == QuadNode::kSplitBoth ? (c & 1) != 0 : (su_split && c == 1);
    bool high_v = split == QuadNode::kSplitBoth ? (c & 2) != 0 : (sv_split && c == 1);
    QuadNode ch;
    ch.face = node.face;
    ch.u0 = su_split && high_u ? um : node.u0;
    ch.u1 = su_split && !high_u ? um : node.u1;
    ch.v0 = sv_split && high_v ? vm : node.v0;
    ch.v1 = sv_split && !high_v ? vm : node.v1;
    nodes_.push_back(ch);
  }
  return first;
}

void Mesh::Enumerate(const Scene& scene, const ProgressCallback& progress) {
  elements_.clear();
  std::vector<int> per_surface(scene.surfaces.size(), 0);
  member_faces_.clear();
  member_cumulative_.clear();
  for (int p = 0; p < static_cast<int>(patches_.size()); ++p) {
    if (progress && p % 4096 == 0) progress(static_cast<double>(p) / patches_.size());
    Patch& patch = patches_[p];
    const MeshFace& face = faces_[patch.face];
    patch.first_element = static_cast<int>(elements_.size());
    patch.area = 0;
    if (!face_group_.empty() && face_group_[patch.face] >= 0) {
      EnumerateGroup(p, &per_surface);
      continue;
    }
    // Depth-first, children in order, so the leaves of a patch are contiguous.
    std::vector<int> stack{patch.root};
    while (!stack.empty()) {
      const int n = stack.back();
      stack.pop_back();
      QuadNode& node = nodes_[n];
      if (node.child >= 0) {
        int nchild = node.split == QuadNode::kSplitBoth ? 4 : 2;
        for (int c = nchild - 1; c >= 0; --c) stack.push_back(node.child + c);
        continue;
      }
      node.element = -1;
      std::array<ElementPiece, 2> pieces;
      int np = RectPieces(node.u0, node.v0, node.u1, node.v1, face, &pieces);
      double area = 0;
      Vec3 moment;
      for (int k = 0; k < np; ++k) {
        const ElementPiece& pc = pieces[k];
        double a = pc.ParamArea() * face.jacobian[pc.half];
        // Centroid of a convex polygon: area-weighted centroids of its fan triangles; the
        // half's map is affine, so it maps centroids to centroids.
        double cu = 0, cv = 0, tot = 0;
        for (int t = 1; t + 1 < pc.n; ++t) {
          double ax = pc.uv[0], ay = pc.uv[1];
          double bx = pc.uv[2 * t], by = pc.uv[2 * t + 1];
          double cx = pc.uv[2 * t + 2], cy = pc.uv[2 * t + 3];
          double ta = 0.5 * std::fabs((bx - ax) * (cy - ay) - (cx - ax) * (by - ay));
          cu += ta * (ax + bx + cx) / 3;
          cv += ta * (ay + by + cy) / 3;
          tot += ta;
        }
        if (tot > 0 && a > 0) {
          double uc = cu / tot, vc = cv / tot;
          // Evaluate on the piece's own half even on the diagonal.
          Vec3 pt = face.EvalOnHalf(pc.half, uc, vc);
          moment += pt * a;
          area += a;
        }
      }
      if (!(area > 0)) continue;
      Element e;
      e.face = patch.face;
      e.patch = p;
      e.node = n;
      e.surface = face.surface;
      e.index_in_surface = per_surface[face.surface]++;
      e.u0 = node.u0;
      e.v0 = node.v0;
      e.u1 = node.u1;
      e.v1 = node.v1;
      e.area = area;
      e.centroid = moment / area + origin_;
      node.element = static_cast<int>(elements_.size());
      elements_.push_back(e);
      patch.area += area;
    }
    patch.num_elements = static_cast<int>(elements_.size()) - patch.first_element;
  }
  // The lattice index: every leaf covers whole lattice cells (leaves are at least a lattice cell).
  int64_t cells = 0;
  for (MeshFace& face : faces_) {
    face.lattice = cells;
    cells += static_cast<int64_t>(face.nu) * face.nv;
  }
  lattice_.assign(cells, -1);
  face_lattice_.resize(faces_.size());
  for (size_t f = 0; f < faces_.size(); ++f) {
    face_lattice_[f] = {faces_[f].lattice, faces_[f].nu, faces_[f].nv, faces_[f].triangle};
  }
  for (const Patch& patch : patches_) {
    const MeshFace& face = faces_[patch.face];
    // Walk down to the nodes that are a single lattice cell or larger leaves.
    std::vector<int32_t> stack{patch.root};
    while (!stack.empty()) {
      int32_t n = stack.back();
      stack.pop_back();
      const QuadNode& node = nodes_[n];
      int i0 = static_cast<int>(std::lround(node.u0 * static_cast<double>(face.nu)));
      int i1 = static_cast<int>(std::lround(node.u1 * static_cast<double>(face.nu)));
      int j0 = static_cast<int>(std::lround(node.v0 * static_cast<double>(face.nv)));
      int j1 = static_cast<int>(std::lround(node.v1 * static_cast<double>(face.nv)));
      const bool one_cell = i1 - i0 <= 1 && j1 - j0 <= 1;
      if (node.child >= 0 && !one_cell) {
        int nchild = node.split == QuadNode::kSplitBoth ? 4 : 2;
        for (int c = 0; c < nchild; ++c) stack.push_back(node.child + c);
        continue;
      }
      // A leaf of exactly one cell stores its element (>= 0, or -1 for none); a larger leaf, or
      // a cell refined below the lattice, stores -(node + 2), from which FindElement descends.
      int32_t value = (node.child < 0 && one_cell) ? node.element : -(n + 2);
      for (int j = j0; j < std::max(j1, j0 + 1); ++j) {
        for (int i = i0; i < std::max(i1, i0 + 1); ++i) {
          lattice_[face.lattice + int64_t{j} * face.nu + i] = value;
        }
      }
    }
  }
  // An agglomerated face's one cell holds its element (FindLeaf finds its own root).
  for (size_t f = 0; f < face_node_.size(); ++f) {
    if (face_node_[f] >= 0) lattice_[faces_[f].lattice] = nodes_[face_node_[f]].element;
  }
  std::vector<int32_t> surfaces(elements_.size());
  for (size_t e = 0; e < elements_.size(); ++e) surfaces[e] = elements_[e].surface;
  sides_ = SideTable(scene, surfaces);
}

void Mesh::EnumerateGroup(int p, std::vector<int>* per_surface) {
  Patch& patch = patches_[p];
  const int32_t k = group_patch_[face_group_[patch.face]];
  for (int32_t g = patch_groups_[k]; g < patch_groups_[k + 1]; ++g) {
    Element e;
    e.face = group_faces_[group_start_[g]];
    e.patch = p;
    e.node = face_node_[e.face];
    e.surface = faces_[e.face].surface;
    e.index_in_surface = (*per_surface)[e.surface]++;
    e.u0 = e.v0 = 0;
    e.u1 = e.v1 = 1;
    e.first_member = static_cast<int>(member_faces_.size());
    e.num_members = group_start_[g + 1] - group_start_[g];
    const int element = static_cast<int>(elements_.size());
    Vec3 moment;
    for (int32_t j = group_start_[g]; j < group_start_[g + 1]; ++j) {
      const int32_t f = group_faces_[j];
      const double a = faces_[f].Area();
      moment += FaceCentroid(faces_[f]) * a;
      e.area += a;
      member_faces_.push_back(f);
      member_cumulative_.push_back(e.area);
      nodes_[face_node_[f]].element = element;
    }
    for (int j = 0; j < e.num_members; ++j) member_cumulative_[e.first_member + j] /= e.area;
    member_cumulative_.back() = 1.0;
    e.centroid = moment / e.area + origin_;
    elements_.push_back(e);
    patch.area += e.area;
  }
  patch.num_elements = static_cast<int>(elements_.size()) - patch.first_element;
}

ElementMembers Mesh::Members(int element) const {
  const Element& e = elements_[element];
  if (e.num_members == 0) return {};
  return {&member_faces_[e.first_member], &member_cumulative_[e.first_member], e.num_members};
}

int Mesh::FindLeaf(int face, double u, double v) const {
  if (!face_node_.empty() && face_node_[face] >= 0) return face_node_[face];
  const MeshFace& f = faces_[face];
  u = std::clamp(u, 0.0, 1.0);
  v = std::clamp(v, 0.0, 1.0);
  int i = std::min(f.nu - 1, static_cast<int>(u * f.nu));
  int j = std::min(f.nv - 1, static_cast<int>(v * f.nv));
  const int32_t cell = lattice_[f.lattice + int64_t{j} * f.nu + i];
  int n;
  if (cell >= -1) {
    // A single-cell leaf: find its node through the patch tree.
    n = patches_[f.first_patch + std::min(f.pv - 1, static_cast<int>(v * f.pv)) * f.pu +
                 std::min(f.pu - 1, static_cast<int>(u * f.pu))]
            .root;
  } else {
    n = -cell - 2;
  }
  return Descend(n, u, v);
}

int Mesh::Descend(int n, double u, double v) const {
  while (nodes_[n].child >= 0) {
    const QuadNode& node = nodes_[n];
    bool high_u = u >= 0.5f * (node.u0 + node.u1);
    bool high_v = v >= 0.5f * (node.v0 + node.v1);
    int c;
    switch (node.split) {
      case QuadNode::kSplitBoth:
        c = (high_u ? 1 : 0) + (high_v ? 2 : 0);
        break;
      case QuadNode::kSplitU:
        c = high_u ? 1 : 0;
        break;
      default:
        c = high_v ? 1 : 0;
        break;
    }
    n = node.child + c;
  }
  return n;
}

int Mesh::FindElement(int face, double u, double v) const {
  const FaceLattice& f = face_lattice_[face];
  u = std::clamp(u, 0.0, 1.0);
  v = std::clamp(v, 0.0, 1.0);
  if (f.triangle && u + v >= 1.0) {
    // Rounding can put a hit a hair beyond a triangle's diagonal, where there are no elements.
    double s = (1.0 - 1e-7) / (u + v);
    u *= s;
    v *= s;
  }
  int i = std::min(f.nu - 1, static_cast<int>(u * f.nu));
  int j = std::min(f.nv - 1, static_cast<int>(v * f.nv));
  const int32_t cell = lattice_[f.offset + int64_t{j} * f.nu + i];
  if (cell >= -1) return cell;
  return nodes_[Descend(-cell - 2, u, v)].element;
}

int Mesh::Pieces(int element, std::array<ElementPiece, 2>* pieces, int member) const {
  const Element& e = elements_[element];
  return RectPieces(e.u0, e.v0, e.u1, e.v1, faces_[FaceOf(element, member)], pieces);
}

Vec3 Mesh::SampleElement(int element, double r1, double r2, double r3, int* half, int* face) const {
  const Element& e = elements_[element];
  *face = e.face;
  if (e.num_members > 0) {
    // A member face by its share of the area, r1 rescaled to choose within it.
    const double* cum = &member_cumulative_[e.first_member];
    const int k = std::min<int>(
        e.num_members - 1, static_cast<int>(std::upper_bound(cum, cum + e.num_members, r1) - cum));
    const double lo = k > 0 ? cum[k - 1] : 0.0;
    r1 = cum[k] > lo ? std::clamp((r1 - lo) / (cum[k] - lo), 0.0, 1.0) : 0.0;
    *face = member_faces_[e.first_member + k];
  }
  const MeshFace& f = faces_[*face];
  // Same test as RectPieces, in double.
  const bool low_half = static_cast<double>(e.u1) + e.v1 <= 1.0;
  if (low_half || (static_cast<double>(e.u0) + e.v0 >= 1.0 && !f.triangle)) {
    // Whole rectangle on one half: the map is affine there, so uniform (u, v) is uniform in area.
    double u = e.u0 + r2 * (e.u1 - e.u0), v = e.v0 + r3 * (e.v1 - e.v0);
    *half = f.Half(u, v);
    if (low_half) *half = 0;
    return *half == 0 ? f.p[0] + u * (f.p[1] - f.p[0]) + v * (f.p[3] - f.p[0])
                      : f.p[2] + (1 - u) * (f.p[3] - f.p[2]) + (1 - v) * (f.p[1] - f.p[2]);
  }
  std::array<ElementPiece, 2> pieces;
  int np = RectPieces(e.u0, e.v0, e.u1, e.v1, f, &pieces);
  // Pick a piece by its area, then a fan triangle by its area, then a uniform point in it.
  double w[2] = {0, 0}, total = 0;
  for (int k = 0; k < np; ++k) {
    w[k] = pieces[k].ParamArea() * f.jacobian[pieces[k].half];
    total += w[k];
  }
  int k = 0;
  double x = r1 * total;
  if (np == 2 && x >= w[0]) {
    x -= w[0];
    k = 1;
  }
  const ElementPiece& pc = pieces[k];
  double piece_area = pc.ParamArea();
  double y = (w[k] > 0 ? x / w[k] : 0) * piece_area;
  int t = 1;
  double ta = 0;
  for (; t + 1 < pc.n; ++t) {
    double ax = pc.uv[0], ay = pc.uv[1];
    double bx = pc.uv[2 * t], by = pc.uv[2 * t + 1];
    double cx = pc.uv[2 * t + 2], cy = pc.uv[2 * t + 3];
    ta = 0.5 * std::fabs((bx - ax) * (cy - ay) - (cx - ax) * (by - ay));
    if (y < ta || t + 2 >= pc.n) break;
    y -= ta;
  }
  // Uniform point in triangle (a, b, c): sqrt parameterisation (Shirley & Chiu).
  double s = std::sqrt(r2);
  double ba = 1 - s, bb = s * (1 - r3), bc = s * r3;
  double u = ba * pc.uv[0] + bb * pc.uv[2 * t] + bc * pc.uv[2 * t + 2];
  double v = ba * pc.uv[1] + bb * pc.uv[2 * t + 1] + bc * pc.uv[2 * t + 3];
  *half = pc.half;
  return pc.half == 0 ? f.p[0] + u * (f.p[1] - f.p[0]) + v * (f.p[3] - f.p[0])
                      : f.p[2] + (1 - u) * (f.p[3] - f.p[2]) + (1 - v) * (f.p[1] - f.p[2]);
}

std::string Mesh::ToString() const {
  return absl::StrFormat("Mesh{%d faces, %d patches, %d elements, element size %g}", faces_.size(),
                         patches_.size(), elements_.size(), element_size_);
}

}  // namespace radiosity
