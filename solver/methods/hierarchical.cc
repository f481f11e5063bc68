#include "solver/methods/hierarchical.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <iterator>
#include <limits>
#include <tuple>
#include <utility>

#include "absl/strings/str_format.h"
#include "solver/geometry/rect_sampler.h"
#include "solver/methods/checkpoint.h"
#include "solver/transport/openness.h"
#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace radiosity {

namespace {

// Distinguishes the pair estimates' random streams from every other stream of a seed.
constexpr uint64_t kHierarchicalStream = 0x4849455241524348ULL;  // "HIERARCH"
// Normals within this angle (radians) count as parallel, and points within this fraction of a
// piece's radius of its plane as on it, for the test of coplanar pieces.
constexpr double kPlanarAngle = 1e-6;
// A cluster receives as a whole only if its faces' normals lie within this angle (radians) of
// their mean.
constexpr double kMaxReceiverSpread = 0.5;
// Distinguishes the cluster links' random streams.
constexpr uint64_t kClusterStream = 0x434c555354455253ULL;  // "CLUSTERS"
// Refinement passes run once the residual is below this fraction of the emitted power (or the
// tolerance, if larger): B then needs to be right only roughly for the oracle.
constexpr double kRefineResidual = 0.05;
// Where a shadow boundary crosses a pair that cannot be refined, its visibility is estimated from
// this many times more receiver points.
constexpr int kPartialPointFactor = 15;
// The oracle's source term (B varying over a source gathered with fewer values) counts this many
// times: its errors have the same sign on every link of a kind (where the kernel favours the
// brighter part of a source, it does so for all the receivers near it), so they add up over many
// links, unlike the receiver term's quadrature errors. Measured on the closed Cornell box: the
// leak of power at epsilon 1e-4 drops from 1 % to 0.3 % of the emitted power.
constexpr double kSourceWeight = 3;
// A pair whose probe rays were all blocked counts this fraction of its unoccluded power as
// uncertain (a partly hidden one, all of it).
constexpr double kHiddenWeight = 0.5;
// A leaf averages the unoccluded factor over this many times more receiver points.
constexpr int kLeafPointFactor = 4;
// Pairs examined per batch (bounds the memory of the results between merges).
constexpr size_t kBatch = size_t{1} << 16;
constexpr double kMiB = 1024.0 * 1024.0;

// A piece of a face in space: its polygons (one per half of the diagonal it covers), and an
// area-uniform sampler of the unit square onto it that keeps strata (RectSampler).
struct PieceGeometry {
  struct Polygon {
    std::array<Vec3, 6> v;
    int n = 0;
    Vec3 normal;  // Front normal of its half.
  };
  std::array<Polygon, 2> polygons;
  int count = 0;
  RectSampler sampler;

  PieceGeometry(const MeshFace& f, double u0, double v0, double u1, double v1)
      : sampler(f, u0, v0, u1, v1) {
    for (int p = 0; p < sampler.num_pieces(); ++p) {
      const ElementPiece& pc = sampler.pieces()[p];
      Polygon& poly = polygons[count++];
      poly.n = pc.n;
      for (int i = 0; i < pc.n; ++i) {
        poly.v[i] = f.EvalOnHalf(pc.half, pc.uv[2 * i], pc.uv[2 * i + 1]);
      }
      poly.normal = f.normal[pc.half];
    }
  }

  Vec3 Sample(double s, double t, int* half) const { return sampler.Sample(s, t, half); }
};

Rgb Abs(const Rgb& c) { return {std::fabs(c.r), std::fabs(c.g), std::fabs(c.b)}; }

}  // namespace

absl::StatusOr<std::unique_ptr<HierarchicalSolver>> HierarchicalSolver::Create(
    const Scene& scene, const Mesh& mesh, const Visibility& visibility, const SolveOptions& options,
    const std::atomic<bool>* stop, const HierarchicalParams& params) {
  if (options.method != "hierarchical") {
    return absl::InvalidArgumentError(
        absl::StrFormat("hierarchical solver: method is '%s', not 'hierarchical'", options.method));
  }
  const FormFactorOptions& ff = options.formfactor;
  if (!kAnalyticPointsBounds.Contains(ff.analytic_points)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("hierarchical: receiver points per link must be in %s, got %d",
                        kAnalyticPointsBounds.text, ff.analytic_points));
  }
  if (!kShadowRaysBounds.Contains(ff.shadow_rays)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("hierarchical: shadow rays per point must be in %s, got %d",
                        kShadowRaysBounds.text, ff.shadow_rays));
  }
  if (!(params.epsilon >= 0) || !std::isfinite(params.epsilon)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("hierarchical: epsilon must be >= 0, got %g", params.epsilon));
  }
  if (params.max_refine_passes < 0) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "hierarchical: refinement passes must be >= 0, got %d", params.max_refine_passes));
  }
  if (!(options.max_matrix_mb > 0) || !std::isfinite(options.max_matrix_mb)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("max matrix MiB must be > 0, got %g", options.max_matrix_mb));
  }
  // Without clusters, the links between face roots alone (before any refinement) must fit.
  const double faces = static_cast<double>(mesh.faces().size());
  const double root_bytes = faces * (faces - 1) * (sizeof(Link) + sizeof(Pair));
  const bool clustered = params.cluster_above_faces >= 0 && faces > params.cluster_above_faces;
  if (!clustered && root_bytes > options.max_matrix_mb * kMiB) {
    return absl::ResourceExhaustedError(absl::StrFormat(
        "hierarchical radiosity starts from links between every pair of the %d faces, which "
        "could need %.1f MiB, over the limit of --max-matrix-mb %g; raise --max-matrix-mb or use "
        "--method progressive for scenes of many small polygons",
        mesh.faces().size(), root_bytes / kMiB, options.max_matrix_mb));
  }
  return std::unique_ptr<HierarchicalSolver>(
      new HierarchicalSolver(scene, mesh, visibility, options, stop, params));
}

HierarchicalSolver::HierarchicalSolver(const Scene& scene, const Mesh& mesh,
                                       const Visibility& visibility, const SolveOptions& options,
                                       const std::atomic<bool>* stop,
                                       const HierarchicalParams& params)
    : SolverBase(scene, mesh, visibility, options, stop, "hierarchical"), params_(params) {
  points_ = options.formfactor.analytic_points;
  shadow_rays_ = options.formfactor.shadow_rays;
  const auto& faces = mesh.faces();
  face_info_.resize(faces.size());
  for (size_t f = 0; f < faces.size(); ++f) {
    for (int side : {kFront, kBack})
      face_info_[f][side] = sides().OfSurface(faces[f].surface, side);
  }

  // The hierarchy, face by face (children before parents).
  leaf_of_element_.assign(mesh.elements().size(), -1);
  roots_.assign(faces.size(), -1);
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    roots_[f] = BuildPatchRange(f, 0, 0, faces[f].pu, faces[f].pv);
  }
  if (params.cluster_above_faces >= 0 &&
      static_cast<int64_t>(faces.size()) > params.cluster_above_faces) {
    BuildClusters();
  }
  const size_t n = nodes_.size();
  links_.resize(n);
  b_.assign(2 * n, Rgb());
  g_.assign(2 * n, Rgb());
  b_lo_.assign(2 * n, 0.0f);
  b_hi_.assign(2 * n, 0.0f);
  for (size_t k = 0; k < n; ++k) {
    if (IsCluster(static_cast<int>(k))) continue;  // Pulled below.
    const FaceSides& info = face_info_[nodes_[k].face];
    for (int side = 0; side < 2; ++side) {
      b_[2 * k + side] = info[side].exitance;
      b_lo_[2 * k + side] = b_hi_[2 * k + side] = static_cast<float>(info[side].exitance.Sum());
    }
  }
  PullClusters();
  const double eps = params.epsilon > 0
                         ? params.epsilon
                         : HierarchicalParams::kEpsilonPerTolerance * options.tolerance;
  epsilon_power_ = eps * emitted_.Sum();
  unshot_ = emitted_;
  residual_ = emitted_.Sum();
  progress_.unshot_fraction = 1;
}

HierarchicalSolver::~HierarchicalSolver() = default;

bool HierarchicalSolver::MeasureOpenness() {
  // Per element side (openness.h), then per leaf.
  int64_t rays = 0, escaped = 0;
  std::vector<float> per_slot;
  arena().execute([&] {
    per_slot = radiosity::MeasureOpenness(mesh_, visibility_, options_.seed, stop_token(), &rays,
                                          OpennessProbes{}, &escaped);
  });
  progress_.rays += rays;
  if (per_slot.empty()) return false;
  closed_ = escaped == 0;
  openness_.assign(2 * nodes_.size(), 1.0f);
  for (size_t e = 0; e < mesh_.elements().size(); ++e) {
    const int leaf = leaf_of_element_[e];
    if (leaf < 0) continue;
    for (int side = 0; side < 2; ++side) {
      openness_[2 * leaf + side] = per_slot[Slot(static_cast<int>(e), side)];
    }
  }
  // Inner pieces: the area-weighted mean of their children (children come before parents).
  for (size_t k = 0; k < nodes_.size(); ++k) {
    const Node& nd = nodes_[k];
    if (nd.num_children == 0) continue;
    for (int side = 0; side < 2; ++side) {
      double sum = 0;
      for (int c = 0; c < nd.num_children; ++c) {
        const int child = children_[nd.first_child + c];
        sum += nodes_[child].area * openness_[2 * child + side];
      }
      openness_[2 * k + side] = nd.area > 0 ? static_cast<float>(sum / nd.area) : 0.0f;
    }
  }
  return true;
}

int HierarchicalSolver::MakeNode(int face, double u0, double v0, double u1, double v1, int element,
                                 const std::vector<int>& children) {
  Node node;
  node.face = face;
  node.u0 = u0;
  node.v0 = v0;
  node.u1 = u1;
  node.v1 = v1;
  node.element = element;
  if (element >= 0) {
    node.area = mesh_.elements()[element].area;
  } else {
    node.first_child = static_cast<int32_t>(children_.size());
    node.num_children = static_cast<int32_t>(children.size());
    for (int c : children) {
      children_.push_back(c);
      node.area += nodes_[c].area;
    }
  }
  nodes_.push_back(node);
  const int index = static_cast<int>(nodes_.size()) - 1;
  if (element >= 0) leaf_of_element_[element] = index;
  return index;
}

int HierarchicalSolver::BuildMeshNode(int face, int quad_node) {
  const QuadNode& q = mesh_.nodes()[quad_node];
  if (q.child < 0) {
    if (q.element < 0) return -1;  // No area (beyond a triangle's diagonal).
    return MakeNode(face, q.u0, q.v0, q.u1, q.v1, q.element, {});
  }
  const int nchild = q.split == QuadNode::kSplitBoth ? 4 : 2;
  std::vector<int> children;
  for (int c = 0; c < nchild; ++c) {
    const int child = BuildMeshNode(face, q.child + c);
    if (child >= 0) children.push_back(child);
  }
  if (children.empty()) return -1;
  if (children.size() == 1) return children[0];  // Collapse single-child chains.
  return MakeNode(face, q.u0, q.v0, q.u1, q.v1, -1, children);
}

int HierarchicalSolver::BuildPatchRange(int face, int i0, int j0, int i1, int j1) {
  const MeshFace& f = mesh_.faces()[face];
  auto patch_root = [&](int i, int j) {
    return mesh_.patches()[f.first_patch + j * f.pu + i].root;
  };
  if (i1 - i0 == 1 && j1 - j0 == 1) return BuildMeshNode(face, patch_root(i0, j0));
  const QuadNode& lo = mesh_.nodes()[patch_root(i0, j0)];
  const QuadNode& hi = mesh_.nodes()[patch_root(i1 - 1, j1 - 1)];
  // Halve the patch range along the longer physical extent(s), as the mesh's own quadtrees do.
  const double eu = f.len_u * (hi.u1 - lo.u0), ev = f.len_v * (hi.v1 - lo.v0);
  bool split_u = i1 - i0 > 1 && 2 * eu >= ev;
  bool split_v = j1 - j0 > 1 && 2 * ev >= eu;
  if (!split_u && !split_v) {
    split_u = i1 - i0 > 1;
    split_v = !split_u;
  }
  const int im = split_u ? (i0 + i1) / 2 : i1, jm = split_v ? (j0 + j1) / 2 : j1;
  std::vector<int> children;
  for (int b = 0; b < (split_v ? 2 : 1); ++b) {
    for (int a = 0; a < (split_u ? 2 : 1); ++a) {
      const int ci0 = a == 0 ? i0 : im, ci1 = a == 0 ? im : i1;
      const int cj0 = b == 0 ? j0 : jm, cj1 = b == 0 ? jm : j1;
      const int child = BuildPatchRange(face, ci0, cj0, ci1, cj1);
      if (child >= 0) children.push_back(child);
    }
  }
  if (children.empty()) return -1;
  if (children.size() == 1) return children[0];
  return MakeNode(face, lo.u0, lo.v0, hi.u1, hi.v1, -1, children);
}

void HierarchicalSolver::BuildClusters() {
  const auto& faces = mesh_.faces();
  face_centroid_.resize(faces.size());
  face_normal_.resize(faces.size());
  for (size_t f = 0; f < faces.size(); ++f) {
    const MeshFace& mf = faces[f];
    // Half 0 is the triangle (p0, p1, p3), half 1 (p2, p3, p1); weights: their areas.
    const Vec3 c0 = (mf.p[0] + mf.p[1] + mf.p[3]) / 3.0, c1 = (mf.p[2] + mf.p[3] + mf.p[1]) / 3.0;
    const double w = mf.jacobian[0] + mf.jacobian[1];
    face_centroid_[f] = w > 0 ? (c0 * mf.jacobian[0] + c1 * mf.jacobian[1]) / w : c0;
    face_normal_[f] = mf.Normal();
    if (roots_[f] >= 0) cluster_faces_.push_back(static_cast<int32_t>(f));
  }
  if (cluster_faces_.size() < 2) return;
  first_cluster_ = static_cast<int>(nodes_.size());
  BuildCluster(0, static_cast<int>(cluster_faces_.size()));
  cluster_face_area_.assign(cluster_faces_.size() + 1, 0.0);
  for (size_t i = 0; i < cluster_faces_.size(); ++i) {
    cluster_face_area_[i + 1] = cluster_face_area_[i] + nodes_[roots_[cluster_faces_[i]]].area;
  }
  parent_cluster_.assign(nodes_.size(), -1);
  for (int c = first_cluster_; c < static_cast<int>(nodes_.size()); ++c) {
    const Node& nd = nodes_[c];
    for (int k = 0; k < nd.num_children; ++k) parent_cluster_[children_[nd.first_child + k]] = c;
  }
  cluster_links_.resize(clusters_.size());
}

int HierarchicalSolver::BuildCluster(int first, int count) {
  if (count == 1) return roots_[cluster_faces_[first]];
  // Median split of the face centroids along the longest axis of their box (Smits, Arvo &
  // Greenberg 1994 build their clusters from the scene's geometry in the same spirit).
  Vec3 lo(1e300, 1e300, 1e300), hi(-1e300, -1e300, -1e300);
  for (int i = first; i < first + count; ++i) {
    const Vec3& c = face_centroid_[cluster_faces_[i]];
    lo = Vec3(std::min(lo.x, c.x), std::min(lo.y, c.y), std::min(lo.z, c.z));
    hi = Vec3(std::max(hi.x, c.x), std::max(hi.y, c.y), std::max(hi.z, c.z));
  }
  const Vec3 ext = hi - lo;
  const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : ext.y >= ext.z ? 1 : 2;
  auto key = [&](int32_t f) {
    const Vec3& c = face_centroid_[f];
    return std::pair(axis == 0 ? c.x : axis == 1 ? c.y : c.z, f);
  };
  const int mid = count / 2;
  std::nth_element(cluster_faces_.begin() + first, cluster_faces_.begin() + first + mid,
                   cluster_faces_.begin() + first + count,
                   [&](int32_t a, int32_t b) { return key(a) < key(b); });
  const int left = BuildCluster(first, mid);
  const int right = BuildCluster(first + mid, count - mid);

  Cluster cl;
  cl.first = first;
  cl.count = count;
  double area = 0;
  Vec3 normal_sum;
  for (int i = first; i < first + count; ++i) {
    const int f = cluster_faces_[i];
    const double a = nodes_[roots_[f]].area;
    area += a;
    cl.centroid += face_centroid_[f] * a;
    normal_sum += face_normal_[f] * a;
    cl.sends |= face_info_[f][0].Sends() || face_info_[f][1].Sends();
  }
  cl.centroid = area > 0 ? cl.centroid / area : face_centroid_[cluster_faces_[first]];
  for (int i = first; i < first + count; ++i) {
    const MeshFace& mf = mesh_.faces()[cluster_faces_[i]];
    for (const Vec3& p : mf.p) cl.radius = std::max(cl.radius, Length(p - cl.centroid));
  }
  // Faces that agree in orientation (the mean of their unit normals at least 0.9 long) give the
  // cluster a normal, used to share out what it sends (ShareWeight).
  if (area > 0 && Length(normal_sum) >= 0.9 * area) {
    cl.normal[0] = Normalize(normal_sum);
    cl.normal[1] = -cl.normal[0];
  }
  if (Length(normal_sum) > 1e-9 * area) {
    cl.axis = Normalize(normal_sum);
    cl.spread = 0;
    for (int i = first; i < first + count; ++i) {
      const MeshFace& mf = mesh_.faces()[cluster_faces_[i]];
      for (int h = 0; h < 2; ++h) {
        if (mf.jacobian[h] > 0) {
          cl.spread =
              std::max(cl.spread, std::acos(std::clamp(Dot(mf.normal[h], cl.axis), -1.0, 1.0)));
        }
      }
    }
    if (cl.spread <= kPlanarAngle) {
      cl.planar = true;
      const double tol = kPlanarAngle * std::max(cl.radius, 1e-300);
      for (int i = first; i < first + count && cl.planar; ++i) {
        for (const Vec3& p : mesh_.faces()[cluster_faces_[i]].p) {
          if (std::fabs(Dot(p - cl.centroid, cl.axis)) > tol) cl.planar = false;
        }
      }
    }
  }
  Node node;
  node.face = -1;
  node.first_child = static_cast<int32_t>(children_.size());
  node.num_children = 2;
  node.area = nodes_[left].area + nodes_[right].area;
  children_.push_back(left);
  children_.push_back(right);
  nodes_.push_back(node);
  clusters_.push_back(cl);
  return static_cast<int>(nodes_.size()) - 1;
}

void HierarchicalSolver::PullClusters() {
  for (int c = first_cluster_; c < static_cast<int>(nodes_.size()); ++c) {
    const Node& nd = nodes_[c];
    for (int side = 0; side < 2; ++side) {
      Rgb pulled;
      float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();
      for (int k = 0; k < nd.num_children; ++k) {
        const int child = children_[nd.first_child + k];
        pulled += b_[2 * child + side] * (nd.area > 0 ? nodes_[child].area / nd.area : 0.0);
        lo = std::min(lo, b_lo_[2 * child + side]);
        hi = std::max(hi, b_hi_[2 * child + side]);
      }
      b_[2 * c + side] = pulled;
      b_lo_[2 * c + side] = lo;
      b_hi_[2 * c + side] = hi;
    }
  }
}

HierarchicalSolver::Bound HierarchicalSolver::BoundOf(int node) const {
  if (IsCluster(node)) {
    const Cluster& cl = clusters_[node - first_cluster_];
    return {cl.centroid, cl.radius, cl.axis, cl.spread, cl.planar};
  }
  const Node& nd = nodes_[node];
  const MeshFace& mf = mesh_.faces()[nd.face];
  const PieceGeometry g(mf, nd.u0, nd.v0, nd.u1, nd.v1);
  Bound b;
  b.axis = mf.Normal();
  b.spread = 0;
  for (int h = 0; h < 2; ++h) {
    if (mf.jacobian[h] > 0) {
      b.spread = std::max(b.spread, std::acos(std::clamp(Dot(mf.normal[h], b.axis), -1.0, 1.0)));
    }
  }
  b.planar = b.spread <= kPlanarAngle;
  int count = 0;
  for (int k = 0; k < g.count; ++k) {
    for (int i = 0; i < g.polygons[k].n; ++i, ++count) b.centre += g.polygons[k].v[i];
  }
  b.centre = b.centre / std::max(1, count);
  for (int k = 0; k < g.count; ++k) {
    for (int i = 0; i < g.polygons[k].n; ++i) {
      b.radius = std::max(b.radius, Length(g.polygons[k].v[i] - b.centre));
    }
  }
  return b;
}

Vec3 HierarchicalSolver::SamplePoint(int node, double a, double b, double c, int* face,
                                     Vec3* normal) const {
  int half = 0;
  Vec3 p;
  if (IsCluster(node)) {
    // A face by area, then a point of it.
    const Cluster& cl = clusters_[node - first_cluster_];
    const double* prefix = cluster_face_area_.data();
    const double target = prefix[cl.first] + a * (prefix[cl.first + cl.count] - prefix[cl.first]);
    int i = static_cast<int>(
        std::upper_bound(prefix + cl.first + 1, prefix + cl.first + cl.count + 1, target) -
        (prefix + 1));
    i = std::clamp(i, cl.first, cl.first + cl.count - 1);
    *face = cluster_faces_[i];
    p = RectSampler(mesh_.faces()[*face], 0, 0, 1, 1).Sample(b, c, &half);
  } else {
    const Node& nd = nodes_[node];
    *face = nd.face;
    p = RectSampler(mesh_.faces()[nd.face], nd.u0, nd.v0, nd.u1, nd.v1).Sample(b, c, &half);
  }
  *normal = mesh_.faces()[*face].normal[half];
  return p;
}

bool HierarchicalSolver::ClusterPairFits(const Pair& pair, double f_hi) const {
  // Smits, Arvo & Greenberg 1994: a link is kept while the power it could carry, B_s F_hi A_r
  // with F_hi bounded from the pieces' distance, is below epsilon (with the source term of
  // ExaminePair's oracle for B varying over the source).
  double db[2];
  SourceVariation(pair.s, db);
  double t = 0;
  for (int ss = 0; ss < 2; ++ss) t += b_[2 * pair.s + ss].Sum() + kSourceWeight * db[ss];
  t *= f_hi * nodes_[pair.r].area;
  return !(t > epsilon_power_);
}

HierarchicalSolver::Split HierarchicalSolver::ClusterSplit(const Pair& pair) const {
  const bool r_can = nodes_[pair.r].num_children > 0, s_can = nodes_[pair.s].num_children > 0;
  if (!r_can) return s_can ? Split::kSource : Split::kNone;
  if (!s_can) return Split::kReceiver;
  return BoundOf(pair.r).radius >= BoundOf(pair.s).radius ? Split::kReceiver : Split::kSource;
}

double HierarchicalSolver::ShareWeight(int face, const ClusterLink& l, int* side) const {
  const Vec3 to = Vec3(l.source_at[0], l.source_at[1], l.source_at[2]) - face_centroid_[face];
  const double d2 = Dot(to, to);
  if (!(d2 > 0)) return 0;
  const Vec3 dir = to / std::sqrt(d2);
  const double c = Dot(face_normal_[face], dir);
  *side = c > 0 ? 0 : 1;
  if (!face_info_[face][*side].exists) return 0;
  const Vec3 sn(l.source_dir[0], l.source_dir[1], l.source_dir[2]);
  const double src = Dot(sn, sn) > 0 ? std::max(0.0, -Dot(sn, dir)) : 1.0;
  // An enclosed side (openness 0: inside a closed object, or pressed against another) takes no
  // share: what it would receive is the open sides'. (Openness is a gate here, not a weight: a
  // face whose probe rays partly met a back would lose that fraction, a step of 1/20.)
  if (!openness_.empty() && !(openness_[2 * roots_[face] + *side] > 0)) return 0;
  return std::fabs(c) * src / d2;
}

void HierarchicalSolver::ClusterIrradiance(int face, Rgb out[2]) const {
  out[0] = out[1] = Rgb();
  if (parent_cluster_.empty()) return;
  for (int c = parent_cluster_[roots_[face]]; c >= 0; c = parent_cluster_[c]) {
    for (const ClusterLink& l : cluster_links_[c - first_cluster_]) {
      if (!(l.f > 0)) continue;
      int side = 0;
      const double w = ShareWeight(face, l, &side);
      if (w > 0) out[side] += l.e * (w * l.norm);
    }
  }
}

void HierarchicalSolver::ExamineClusterPair(const Pair& pair, PairResult* out) const {
  const Node& nr = nodes_[pair.r];
  const Node& ns = nodes_[pair.s];
  const bool r_cluster = IsCluster(pair.r), s_cluster = IsCluster(pair.s);
  const bool sends = s_cluster ? clusters_[pair.s - first_cluster_].sends
                               : face_info_[ns.face][0].Sends() || face_info_[ns.face][1].Sends();
  if (!sends) return;
  const Bound br = BoundOf(pair.r), bs = BoundOf(pair.s);
  // Pieces in one plane see nothing of each other (the rule between face pieces, too).
  if (br.planar && bs.planar && std::fabs(Dot(br.axis, bs.axis)) >= std::cos(kPlanarAngle) &&
      std::fabs(Dot(bs.centre - br.centre, br.axis)) <=
          kPlanarAngle * std::max(br.radius + bs.radius, 1e-300)) {
    return;
  }
  const double dist = Length(br.centre - bs.centre);
  const double gap = dist - br.radius - bs.radius;
  // The factor's bound: A_s |cos_r| |cos_s| / (pi gap^2), the cosines bounded by the normal cones
  // against the cone of directions between the bounding spheres.
  double f_hi = 1;
  if (gap > 0) {
    const Vec3 d = (bs.centre - br.centre) / dist;
    const double spread = std::asin(std::min(1.0, (br.radius + bs.radius) / dist));
    auto cos_bound = [&](const Bound& b) {
      if (!(b.spread < kPi / 2)) return 1.0;
      const double angle = std::acos(std::min(1.0, std::fabs(Dot(b.axis, d))));
      return std::cos(std::max(0.0, angle - b.spread - spread));
    };
    f_hi = std::min(1.0, ns.area * cos_bound(br) * cos_bound(bs) / (kPi * gap * gap));
  }
  if (!(gap > 0) || !ClusterPairFits(pair, f_hi)) {
    const Split split = ClusterSplit(pair);
    if (split != Split::kNone) SplitPair(pair, split, &out->children);
    return;
  }
  // A cluster receives as a whole only where its faces agree in orientation (a patch of a wall or
  // of a curved surface): what it gathers is shared out without visibility inside it, which
  // would light the legs under a chair's seat. Others receive face by face.
  if (r_cluster && !(clusters_[pair.r - first_cluster_].spread <= kMaxReceiverSpread)) {
    SplitPair(pair, Split::kReceiver, &out->children);
    return;
  }
  // The factor from the receiver (area mean) to each source side, by Monte Carlo over pairs of
  // area-uniform points (x on s, y on r), each with a shadow ray:
  //   F_rs = (1 / A_r) integral_r integral_s cos_y cos_x V / (pi |x - y|^2) = A_s E[G V],
  // unbiased whatever the pieces' shapes (a centroid-to-centroid kernel is not: over concave
  // clusters it overestimated the factors, bench/REPORT.md "Clustering"). A cluster receiver
  // counts only samples that land on a side that exists (the back of a one-sided surface absorbs
  // what reaches it).
  const int samples = points_ * shadow_rays_;
  Rng rng(StreamKey(options_.seed, kClusterStream, static_cast<uint64_t>(pair.r),
                    static_cast<uint64_t>(pair.s)));
  double acc[2][2] = {{0, 0}, {0, 0}};  // [receiver side][source side]
  int seen = 0;
  int64_t rays = 0;
  for (int k = 0; k < samples; ++k) {
    const Stratum cell = StratumCell(samples, k);
    int fy = 0, fx = 0;
    Vec3 ny, nx;
    const Vec3 y = SamplePoint(pair.r, rng.Uniform(), cell.u0 + cell.du * rng.Uniform(),
                               cell.v0 + cell.dv * rng.Uniform(), &fy, &ny);
    const Vec3 x = SamplePoint(pair.s, rng.Uniform(), rng.Uniform(), rng.Uniform(), &fx, &nx);
    if (fx == fy) continue;
    const Vec3 d = x - y;
    const double r2 = Dot(d, d);
    if (!(r2 > 0)) continue;
    const double len = std::sqrt(r2);
    const double cy = Dot(d, ny) / len, cx = -Dot(d, nx) / len;
    if (cy == 0 || cx == 0) continue;
    const int rs = cy > 0 ? 0 : 1, ss = cx > 0 ? 0 : 1;
    if (r_cluster && !face_info_[fy][rs].exists) continue;
    // A face piece's side that sends nothing has B = 0 (no link needed); a cluster's B per side is
    // the mean over all its faces' sides, those that send nothing included, so its factor must
    // count them too.
    if (!s_cluster && !face_info_[fx][ss].Sends()) continue;
    if (!SegmentVisible(visibility_, y, fy, x, fx, std::fabs(cx), &rays)) continue;
    ++seen;
    acc[r_cluster ? 0 : rs][ss] += std::fabs(cy) * std::fabs(cx) / (kPi * r2);
  }
  out->rays = rays;
  const double scale = ns.area / samples;
  if (r_cluster) {
    const Cluster& cl = clusters_[pair.r - first_cluster_];
    std::vector<ClusterLink> made;
    for (int ss = 0; ss < 2; ++ss) {
      const double f = acc[0][ss] * scale;
      // Nothing seen: one link of F = 0 kept, so that a later pass tests the pair again.
      if (!(f > 0) && !(seen == 0 && ss == 0)) continue;
      // Zeroed bytes, padding too (ClusterLink holds only numbers): checkpoints are compared
      // byte for byte.
      ClusterLink l;
      std::memset(static_cast<void*>(&l), 0, sizeof(l));
      l.source = pair.s;
      l.source_side = static_cast<uint8_t>(ss);
      l.hidden = seen == 0;
      l.f = static_cast<float>(f);
      l.f_hi = static_cast<float>(f_hi);
      const Vec3 at = s_cluster ? clusters_[pair.s - first_cluster_].centroid : bs.centre;
      const Vec3 dir = s_cluster ? clusters_[pair.s - first_cluster_].normal[ss]
                                 : face_normal_[ns.face] * (ss == 0 ? 1.0 : -1.0);
      for (int i = 0; i < 3; ++i) {
        l.source_at[i] = static_cast<float>(i == 0 ? at.x : i == 1 ? at.y : at.z);
        l.source_dir[i] = static_cast<float>(i == 0 ? dir.x : i == 1 ? dir.y : dir.z);
      }
      // What the cluster gathers is shared out among its faces' sides by the point kernel from
      // the source's centroid, normalised so that the sides together receive f x A_r exactly;
      // without the source's cosine if that leaves no side (the centroid behind the source).
      auto share_total = [&] {
        double total = 0;
        for (int i = cl.first; i < cl.first + cl.count; ++i) {
          const int face = cluster_faces_[i];
          int side = 0;
          total += nodes_[roots_[face]].area * ShareWeight(face, l, &side);
        }
        return total;
      };
      double total = share_total();
      if (!(total > 0)) {
        std::fill(std::begin(l.source_dir), std::end(l.source_dir), 0.0f);
        total = share_total();
      }
      if (!(total > 0)) {
        if (l.hidden) {
          total = nr.area;  // Carries nothing: kept only to be tested again.
        } else {
          // Light arrives but no side could take it: receive face by face instead.
          out->rays = rays;
          SplitPair(pair, Split::kReceiver, &out->children);
          return;
        }
      }
      l.norm = static_cast<float>(nr.area / total);
      made.push_back(l);
    }
    out->cluster_links.insert(out->cluster_links.end(), made.begin(), made.end());
    return;
  }
  for (int rs = 0; rs < 2; ++rs) {
    for (int ss = 0; ss < 2; ++ss) {
      const double f = acc[rs][ss] * scale;
      if (!(f > 0) && !(seen == 0 && rs == 0 && ss == 0)) continue;
      Link link;
      link.source = pair.s;
      link.f = static_cast<float>(f);
      link.f_hi = static_cast<float>(f_hi);
      link.f_range = static_cast<float>(f_hi);
      link.receiver_side = static_cast<uint8_t>(rs);
      link.source_side = static_cast<uint8_t>(ss);
      link.partial = seen == 0 ? kLinkHidden : kLinkVisible;
      out->links.push_back(link);
    }
  }
}

void HierarchicalSolver::SplitPair(const Pair& pair, Split split, std::vector<Pair>* out) const {
  if (split == Split::kReceiver) {
    const Node& r = nodes_[pair.r];
    for (int c = 0; c < r.num_children; ++c) out->push_back({children_[r.first_child + c], pair.s});
  } else {
    const Node& s = nodes_[pair.s];
    for (int c = 0; c < s.num_children; ++c) out->push_back({pair.r, children_[s.first_child + c]});
  }
}

HierarchicalSolver::Split HierarchicalSolver::Decide(const Pair& pair, const Oracle& oracle) const {
  const double total = oracle.receiver + oracle.source + oracle.visibility;
  if (!(total > epsilon_power_)) return Split::kNone;
  const Node& r = nodes_[pair.r];
  const Node& s = nodes_[pair.s];
  const bool r_can = r.num_children > 0, s_can = s.num_children > 0;
  if (oracle.visibility >= std::max(oracle.receiver, oracle.source)) {
    // A shadow boundary crosses the pair: split the larger piece (HSA 1991, Refine).
    if (r_can && (!s_can || r.area >= s.area)) return Split::kReceiver;
    return s_can ? Split::kSource : Split::kNone;
  }
  if (oracle.receiver >= oracle.source) {
    // F varies over the receiver: only splitting it helps (the factor to the source is exact
    // over the source, whatever its size). A leaf keeps its mean.
    if (r_can) return Split::kReceiver;
    return s_can && oracle.source + oracle.visibility > epsilon_power_ ? Split::kSource
                                                                       : Split::kNone;
  }
  // B varies over the source: split it.
  if (s_can) return Split::kSource;
  return r_can && oracle.receiver + oracle.visibility > epsilon_power_ ? Split::kReceiver
                                                                       : Split::kNone;
}

void HierarchicalSolver::SourceVariation(int s, double db[2]) const {
  // How far B within the source departs from the mean it is gathered with: the largest deviation
  // of a leaf's B (channel sum) over the source's subtree, per side (kept by the pull).
  for (int side = 0; side < 2; ++side) {
    const double mean = b_[2 * s + side].Sum();
    db[side] = std::max(static_cast<double>(b_hi_[2 * s + side]) - mean,
                        mean - static_cast<double>(b_lo_[2 * s + side]));
    db[side] = std::max(db[side], 0.0);
  }
}

void HierarchicalSolver::ExaminePair(const Pair& pair, PairResult* out) const {
  if (IsCluster(pair.r) || IsCluster(pair.s)) {
    ExamineClusterPair(pair, out);
    return;
  }
  if (nodes_[pair.r].face == nodes_[pair.s].face) return;  // Pieces of one face never link.
  const Node& nr = nodes_[pair.r];
  const Node& ns = nodes_[pair.s];
  const FaceSides& ir = face_info_[nr.face];
  const FaceSides& is = face_info_[ns.face];
  const MeshFace& fr = mesh_.faces()[nr.face];
  const MeshFace& fs = mesh_.faces()[ns.face];
  const PieceGeometry gr(fr, nr.u0, nr.v0, nr.u1, nr.v1);
  const PieceGeometry gs(fs, ns.u0, ns.v0, ns.u1, ns.v1);
  const double eps = visibility_.epsilon();
  // Bounding spheres: the mean of the corners, and the farthest corner.
  Vec3 gr_centroid, gs_centroid;
  double gr_radius = 0, gs_radius = 0;
  for (auto [g, c, radius] :
       {std::tuple{&gr, &gr_centroid, &gr_radius}, std::tuple{&gs, &gs_centroid, &gs_radius}}) {
    int count = 0;
    for (int b = 0; b < g->count; ++b) {
      for (int k = 0; k < g->polygons[b].n; ++k, ++count) *c += g->polygons[b].v[k];
    }
    *c = *c / std::max(1, count);
    for (int b = 0; b < g->count; ++b) {
      for (int k = 0; k < g->polygons[b].n; ++k) {
        *radius = std::max(*radius, Length(g->polygons[b].v[k] - *c));
      }
    }
  }

  // Which sides can exchange light at all: a receiver side needs part of the source in front of
  // it, a source side part of the receiver in front of it (coplanar pieces have neither).
  bool rec_sees[2] = {false, false}, src_sees[2] = {false, false};
  for (int a = 0; a < gs.count; ++a) {
    const auto& sp = gs.polygons[a];
    for (int b = 0; b < gr.count; ++b) {
      const auto& rp = gr.polygons[b];
      for (int k = 0; k < rp.n; ++k) {
        const double d = Dot(rp.v[k] - sp.v[0], sp.normal);
        if (d > eps) src_sees[0] = true;
        if (d < -eps) src_sees[1] = true;
      }
      for (int k = 0; k < sp.n; ++k) {
        const double d = Dot(sp.v[k] - rp.v[0], rp.normal);
        if (d > eps) rec_sees[0] = true;
        if (d < -eps) rec_sees[1] = true;
      }
    }
  }
  // Every receiver side counts (the back of a one-sided surface absorbs what it receives, for
  // the books); only sources that can have B > 0 matter.
  const bool ss_ok[2] = {is[0].Sends() && src_sees[0], is[1].Sends() && src_sees[1]};
  if (!(rec_sees[0] || rec_sees[1]) || !(ss_ok[0] || ss_ok[1])) return;

  // Unoccluded factors F(y -> s) by Lambert's formula at stratified points y of r, per
  // (receiver side, source side); which source side y sees follows from its side of s's plane.
  // The receiver's points depend on the receiver alone: every link of r is evaluated at the same
  // points, where the factors to all sources sum to exactly 1 in a closed scene (Lambert's formula
  // is exact), so no light is lost or created between the links of one piece.
  struct Point {
    Vec3 y, n;
    double f[2][2];
    double w = 1;  // Quadrature weight (area element) for the mean over r.
  };
  // Points of r and their unoccluded factors: `count` area-uniform points, jittered in strata by
  // stream `set`; or (set < 0) the midpoint rule: the midpoints of `count` cells of r's (u, v)
  // rectangle, each weighted by its half's area element (0 beyond a triangle's diagonal).
  auto make_points = [&](int set, int count, std::vector<Point>* out_points) {
    Rng rng(StreamKey(options_.seed, kHierarchicalStream + static_cast<uint64_t>(std::max(set, 0)),
                      static_cast<uint64_t>(pair.r)));
    out_points->resize(static_cast<size_t>(count));
    for (int k = 0; k < count; ++k) {
      Point& p = (*out_points)[k];
      const Stratum cell = StratumCell(count, k);
      int half = 0;
      if (set < 0) {
        const double u = nr.u0 + (cell.u0 + 0.5 * cell.du) * (nr.u1 - nr.u0);
        const double v = nr.v0 + (cell.v0 + 0.5 * cell.dv) * (nr.v1 - nr.v0);
        half = fr.Half(u, v);
        p.w = fr.jacobian[half];
        p.y = fr.EvalOnHalf(half, u, v);
      } else {
        p.y =
            gr.Sample(cell.u0 + cell.du * rng.Uniform(), cell.v0 + cell.dv * rng.Uniform(), &half);
      }
      p.n = fr.normal[half];
      for (auto& row : p.f) row[0] = row[1] = 0;
      for (int rs = 0; rs < 2; ++rs) {
        if (!rec_sees[rs]) continue;
        const Vec3 n = rs == 0 ? p.n : -p.n;
        for (int a = 0; a < gs.count; ++a) {
          const auto& sp = gs.polygons[a];
          const double d = Dot(p.y - sp.v[0], sp.normal);
          if (std::fabs(d) <= eps) continue;
          const int ss = d > 0 ? 0 : 1;
          if (!ss_ok[ss]) continue;
          p.f[rs][ss] += PointToPolygonFormFactorClipped(p.y, n, sp.v.data(), sp.n);
        }
      }
    }
  };
  // `points` carry the visibility estimate; the unoccluded factor is the mean over `dense`: the
  // same points for an inner piece, and for a leaf, which cannot be split when F varies over it,
  // the midpoints of kLeafPointFactor times as many cells (the midpoint rule, exact where F is
  // linear over each cell; Lambert's formula is cheap and needs no rays).
  std::vector<Point> points, dense_leaf;
  make_points(0, points_, &points);
  if (nr.num_children == 0 && kLeafPointFactor > 1) {
    make_points(-1, kLeafPointFactor * points_, &dense_leaf);
  }
  const std::vector<Point>& dense = dense_leaf.empty() ? points : dense_leaf;
  // The range of the factor over the receiver, [lo, hi], from its sample points and its corners
  // (where the factor to a neighbouring face peaks).
  double hi[2][2] = {{0, 0}, {0, 0}}, lo[2][2];
  for (int rs = 0; rs < 2; ++rs) lo[rs][0] = lo[rs][1] = 1e300;
  auto extend = [&](int rs, int ss, double f) {
    hi[rs][ss] = std::max(hi[rs][ss], f);
    lo[rs][ss] = std::min(lo[rs][ss], f);
  };
  for (const std::vector<Point>* set : {&points, &dense_leaf}) {
    for (const Point& p : *set) {
      for (int rs = 0; rs < 2; ++rs) {
        for (int ss = 0; ss < 2; ++ss) extend(rs, ss, p.f[rs][ss]);
      }
    }
  }
  double mean[2][2] = {{0, 0}, {0, 0}}, weight = 0;
  for (const Point& p : dense) {
    weight += p.w;
    for (int rs = 0; rs < 2; ++rs) {
      for (int ss = 0; ss < 2; ++ss) mean[rs][ss] += p.w * p.f[rs][ss];
    }
  }
  for (auto& row : mean) {
    row[0] /= weight;
    row[1] /= weight;
  }
  // The corners, pulled in by 1e-3 of the way to the centre (off the edges they may share with
  // the source or an occluder); also the probe's extra origins below.
  std::vector<Point> corners;
  for (int b = 0; b < gr.count; ++b) {
    const auto& rp = gr.polygons[b];
    Vec3 centre;
    for (int k = 0; k < rp.n; ++k) centre += rp.v[k] / rp.n;
    for (int k = 0; k < rp.n; ++k) {
      Point c;
      c.y = rp.v[k] + (centre - rp.v[k]) * 1e-3;
      c.n = rp.normal;
      for (auto& row : c.f) row[0] = row[1] = 0;
      for (int rs = 0; rs < 2; ++rs) {
        if (!rec_sees[rs] || !ir[rs].Receives()) continue;
        const Vec3 n = rs == 0 ? c.n : -c.n;
        for (int a = 0; a < gs.count; ++a) {
          const auto& sp = gs.polygons[a];
          // A corner on the source's plane (a shared edge) takes the side the piece is on.
          double d = Dot(c.y - sp.v[0], sp.normal);
          if (std::fabs(d) <= eps) d = Dot(gr_centroid - sp.v[0], sp.normal);
          if (std::fabs(d) <= eps) continue;
          const int ss = d > 0 ? 0 : 1;
          if (!ss_ok[ss]) continue;
          c.f[rs][ss] += PointToPolygonFormFactorClipped(c.y, n, sp.v.data(), sp.n);
        }
        extend(rs, 0, c.f[rs][0]);
        extend(rs, 1, c.f[rs][1]);
      }
      corners.push_back(c);
    }
  }
  // Where the source comes within the receiver's size the factor can peak between the samples:
  // bound it by HSA's disk estimate A_s / (pi d^2 + A_s) at the least distance d between the
  // pieces' bounding spheres (1 when they touch).
  const double gap = std::max(0.0, Length(gr_centroid - gs_centroid) - gr_radius - gs_radius);
  const bool close = gap < gr_radius;
  const double f_disk = ns.area / (kPi * gap * gap + ns.area);
  double db[2];
  SourceVariation(pair.s, db);
  Oracle oracle;
  for (int rs = 0; rs < 2; ++rs) {
    for (int ss = 0; ss < 2; ++ss) {
      if (!(hi[rs][ss] > 0)) {
        lo[rs][ss] = 0;
        continue;
      }
      if (close) hi[rs][ss] = std::max(hi[rs][ss], f_disk);
      if (!ir[rs].Receives()) continue;
      oracle.receiver += b_[2 * pair.s + ss].Sum() * (hi[rs][ss] - lo[rs][ss]);
      oracle.source += db[ss] * hi[rs][ss] * kSourceWeight;
    }
  }
  oracle.receiver *= nr.area;
  oracle.source *= nr.area;
  Split split = Decide(pair, oracle);
  if (split != Split::kNone) {
    SplitPair(pair, split, &out->children);
    return;
  }

  // Visibility: shadow rays from each point y to stratified points x of s, the visible fraction
  // weighted by the kernel cos_y cos_x / r^2 (a ratio estimator of F_visible / F). A probe (from
  // the points and the corners) decides whether a shadow boundary crosses the pair. A unanimous
  // probe is the estimate (V = 1 or 0: keeping it selects on its outcome, but a truly partial
  // pair passes as unanimous with probability V^n or (1 - V)^n, so the bias is below
  // max V^n (1 - V) ~ 1 / (e n) of the link for n probe rays, and none for the usual fully visible
  // or hidden pairs). A mixed probe that cannot be refined is estimated from a fresh, independent
  // set: deciding on the estimate's own rays would bias penumbrae, whose mixed outcomes would be
  // sampled again while the all-hidden ones kept 0.
  struct Shadows {
    double fv[2][2] = {{0, 0}, {0, 0}};    // sum over origins of F(y) V(y)
    double fsum[2][2] = {{0, 0}, {0, 0}};  // sum over origins of F(y)
    bool seen[2][2] = {{false, false}, {false, false}};
    bool hidden[2][2] = {{false, false}, {false, false}};
  };
  int64_t rays = 0;
  auto trace = [&](uint64_t set, const std::vector<Point>& origins, Shadows* sh) {
    Rng shadow_rng(StreamKey(options_.seed, kHierarchicalStream, static_cast<uint64_t>(pair.r),
                             (static_cast<uint64_t>(pair.s) << 1 | set) + 1));
    for (const Point& p : origins) {
      double w[2][2] = {{0, 0}, {0, 0}}, wv[2][2] = {{0, 0}, {0, 0}};
      for (int j = 0; j < shadow_rays_; ++j) {
        const Stratum cell = StratumCell(shadow_rays_, j);
        int half = 0;
        const Vec3 x = gs.Sample(cell.u0 + cell.du * shadow_rng.Uniform(),
                                 cell.v0 + cell.dv * shadow_rng.Uniform(), &half);
        const Vec3 mx = fs.normal[half];
        const Vec3 d = x - p.y;
        const double r2 = Dot(d, d);
        if (!(r2 > 0)) continue;
        int visible = -1;  // Traced once, only if some side pair needs it.
        for (int rs = 0; rs < 2; ++rs) {
          const double cy = rs == 0 ? Dot(d, p.n) : -Dot(d, p.n);
          if (cy <= 0) continue;
          for (int ss = 0; ss < 2; ++ss) {
            if (!(p.f[rs][ss] > 0)) continue;
            const double cx = ss == 0 ? -Dot(d, mx) : Dot(d, mx);
            if (cx <= 0) continue;
            if (visible < 0) {
              visible =
                  SegmentVisible(visibility_, p.y, nr.face, x, ns.face, cx / std::sqrt(r2), &rays)
                      ? 1
                      : 0;
            }
            const double kernel = cy * cx / (r2 * r2);
            w[rs][ss] += kernel;
            wv[rs][ss] += visible * kernel;
            (visible ? sh->seen : sh->hidden)[rs][ss] = true;
          }
        }
      }
      for (int rs = 0; rs < 2; ++rs) {
        for (int ss = 0; ss < 2; ++ss) {
          if (!(p.f[rs][ss] > 0)) continue;
          // No sample with a positive kernel (pieces that barely see each other): count it seen.
          sh->fv[rs][ss] += p.f[rs][ss] * (w[rs][ss] > 0 ? wv[rs][ss] / w[rs][ss] : 1.0);
          sh->fsum[rs][ss] += p.f[rs][ss];
        }
      }
    }
  };
  // The probe also shoots from the corners: a shadow boundary crossing the receiver almost always
  // separates some of them, even when it misses the few random points.
  Shadows probe;
  corners.insert(corners.begin(), points.begin(), points.end());
  trace(0, corners, &probe);
  bool partial[2][2] = {{false, false}, {false, false}};
  for (int rs = 0; rs < 2; ++rs) {
    for (int ss = 0; ss < 2; ++ss) {
      partial[rs][ss] = probe.seen[rs][ss] && probe.hidden[rs][ss];
      if (!ir[rs].Receives()) continue;
      // A partly hidden pair is as uncertain as all it could carry; a wholly hidden one less so,
      // but a few probe rays cannot tell hidden from mostly hidden: a pair dropped as hidden is
      // never looked at again.
      const double w = partial[rs][ss] ? 1.0 : probe.seen[rs][ss] ? 0.0 : kHiddenWeight;
      oracle.visibility += w * b_[2 * pair.s + ss].Sum() * hi[rs][ss];
    }
  }
  oracle.visibility *= nr.area;
  split = Decide(pair, oracle);
  if (split != Split::kNone) {
    out->rays = rays;
    SplitPair(pair, split, &out->children);
    return;
  }
  // The visible factor is the unoccluded mean times the F-weighted visible fraction,
  //   F_visible = mean F(y) x sum_y F(y) V(y) / sum_y F(y),
  // exact in the limit (the integral of F V over r is F's mean times its F-weighted mean V). Where
  // a shadow boundary crosses a pair that cannot be split, the fraction comes from
  // kPartialPointFactor times more points of r (shared by all of r's links).
  bool any_partial = false;
  for (int rs = 0; rs < 2; ++rs) any_partial |= partial[rs][0] || partial[rs][1];
  Shadows estimate;
  if (any_partial) {
    std::vector<Point> more;
    make_points(1, kPartialPointFactor * points_, &more);
    more.insert(more.begin(), points.begin(), points.end());
    trace(1, more, &estimate);
  } else {
    // Unanimous: seen (V = 1) or hidden (V = 0) for each side pair, from the probe.
    for (int rs = 0; rs < 2; ++rs) {
      for (int ss = 0; ss < 2; ++ss) {
        estimate.fsum[rs][ss] = 1;
        estimate.fv[rs][ss] = probe.hidden[rs][ss] ? 0.0 : 1.0;
      }
    }
  }
  out->rays = rays;
  // Look-ahead into the source's children: the share of the unoccluded factor each child takes,
  // from the same receiver points. The gather weights the children's B by it instead of using
  // the source's area mean, so a gradient of B across the source (brighter near the receiver,
  // say) is carried without more links; the area mean alone errs the same way on every link of a
  // kind, and such errors add up over many links although each is below epsilon.
  double child_f[2][2][4] = {};
  const int nc = std::min<int>(ns.num_children, 4);
  for (int c = 0; c < nc; ++c) {
    const Node& child = nodes_[children_[ns.first_child + c]];
    const PieceGeometry gc(fs, child.u0, child.v0, child.u1, child.v1);
    for (const Point& p : dense) {
      for (int rs = 0; rs < 2; ++rs) {
        if (!rec_sees[rs]) continue;
        const Vec3 n = rs == 0 ? p.n : -p.n;
        for (int a = 0; a < gc.count; ++a) {
          const auto& sp = gc.polygons[a];
          const double d = Dot(p.y - sp.v[0], sp.normal);
          if (std::fabs(d) <= eps) continue;
          const int ss = d > 0 ? 0 : 1;
          if (!ss_ok[ss]) continue;
          child_f[rs][ss][c] += p.w * PointToPolygonFormFactorClipped(p.y, n, sp.v.data(), sp.n);
        }
      }
    }
  }
  const bool splittable = nr.num_children > 0 || ns.num_children > 0;
  for (int rs = 0; rs < 2; ++rs) {
    for (int ss = 0; ss < 2; ++ss) {
      const float f =
          estimate.fsum[rs][ss] > 0
              ? static_cast<float>(mean[rs][ss] * estimate.fv[rs][ss] / estimate.fsum[rs][ss])
              : 0.0f;
      // F = 0 with exchange possible somewhere over the receiver (F_hi > 0): hidden from the
      // probe, or missed by the few points of a large piece. Between leaves that is dropped;
      // where the pair can be split it is kept with F = 0, so that a later pass, knowing the
      // source's B (which may still be 0 now), looks at it again in finer pieces.
      const bool hidden = !(f > 0) && mean[rs][ss] > 0;
      if (!(f > 0) && !(splittable && ir[rs].Receives() && hi[rs][ss] > 0)) continue;
      Link link;
      double total = 0;
      for (int c = 0; c < nc; ++c) total += child_f[rs][ss][c];
      for (int c = 0; c < 4; ++c) {
        link.child_share[c] =
            c < nc && total > 0
                ? static_cast<uint8_t>(std::lround(255.0 * child_f[rs][ss][c] / total))
                : 0;
      }
      link.source = pair.s;
      link.f = f;
      link.f_hi = static_cast<float>(hi[rs][ss]);
      link.f_range = static_cast<float>(hi[rs][ss] - lo[rs][ss]);
      link.receiver_side = static_cast<uint8_t>(rs);
      link.source_side = static_cast<uint8_t>(ss);
      link.partial = hidden ? kLinkHidden : partial[rs][ss] ? kLinkPartial : kLinkVisible;
      out->links.push_back(link);
    }
  }
}

int64_t HierarchicalSolver::LinkBytes(int64_t links) const {
  return links * static_cast<int64_t>(sizeof(Link));
}

absl::StatusOr<bool> HierarchicalSolver::Expand(std::vector<Pair> pairs, Staged* staged) {
  int64_t staged_links = 0, staged_bytes = 0;
  for (const auto& list : staged->links) staged_links += static_cast<int64_t>(list.size());
  staged_bytes = LinkBytes(staged_links);
  for (const auto& list : staged->cluster_links) {
    staged_links += static_cast<int64_t>(list.size());
    staged_bytes += static_cast<int64_t>(list.size() * sizeof(ClusterLink));
  }
  const double limit = options_.max_matrix_mb * kMiB;
  std::vector<PairResult> results;
  while (!pairs.empty()) {
    std::vector<Pair> next;
    for (size_t begin = 0; begin < pairs.size(); begin += kBatch) {
      if (ShouldStop()) return false;
      const size_t count = std::min(kBatch, pairs.size() - begin);
      results.assign(count, PairResult());
      std::atomic<bool> expired{false};
      arena().execute([&] {
        tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 4),
                          [&](const tbb::blocked_range<size_t>& range) {
                            if (expired.load(std::memory_order_relaxed)) return;
                            if (ShouldStop()) {
                              expired = true;
                              return;
                            }
                            for (size_t i = range.begin(); i < range.end(); ++i) {
                              ExaminePair(pairs[begin + i], &results[i]);
                            }
                          });
      });
      if (absl::Status s = visibility_.status(); !s.ok()) return s;
      if (expired) return false;
      // Merge in pair order: the links and the next level do not depend on the threads.
      for (size_t i = 0; i < count; ++i) {
        PairResult& res = results[i];
        progress_.rays += res.rays;
        const int r = pairs[begin + i].r;
        if (!res.cluster_links.empty()) {
          auto& list = staged->cluster_links[r - first_cluster_];
          list.insert(list.end(), res.cluster_links.begin(), res.cluster_links.end());
          staged_links += static_cast<int64_t>(res.cluster_links.size());
          staged_bytes += static_cast<int64_t>(res.cluster_links.size() * sizeof(ClusterLink));
        }
        auto& list = staged->links[r];
        list.insert(list.end(), res.links.begin(), res.links.end());
        staged_links += static_cast<int64_t>(res.links.size());
        staged_bytes += LinkBytes(static_cast<int64_t>(res.links.size()));
        next.insert(next.end(), res.children.begin(), res.children.end());
      }
      const double bytes = static_cast<double>(staged_bytes) +
                           static_cast<double>(next.size() + pairs.size()) * sizeof(Pair);
      if (bytes > limit) {
        return absl::ResourceExhaustedError(absl::StrFormat(
            "hierarchical radiosity: the links grew past --max-matrix-mb %g (%d links, %.1f "
            "MiB with the pairs still to refine); raise --max-matrix-mb, a larger --tolerance "
            "(coarser links) or a larger element size",
            options_.max_matrix_mb, staged_links, bytes / kMiB));
      }
    }
    pairs.swap(next);
  }
  return true;
}

absl::Status HierarchicalSolver::InitialLinks() {
  // Every ordered pair of face roots (receiver, source) on different faces; with clusters, the
  // whole scene with itself.
  std::vector<Pair> pairs;
  if (!clusters_.empty()) {
    const int top = static_cast<int>(nodes_.size()) - 1;
    pairs.push_back({top, top});
  }
  for (size_t r = 0; r < roots_.size() && clusters_.empty(); ++r) {
    if (roots_[r] < 0) continue;
    for (size_t s = 0; s < roots_.size(); ++s) {
      if (s == r || roots_[s] < 0 || !(face_info_[s][0].Sends() || face_info_[s][1].Sends()))
        continue;
      pairs.push_back({roots_[r], roots_[s]});
    }
  }
  Staged staged;
  staged.links.resize(nodes_.size());
  staged.cluster_links.resize(clusters_.size());
  absl::StatusOr<bool> complete = Expand(std::move(pairs), &staged);
  if (!complete.ok()) return complete.status();
  if (!*complete) return absl::CancelledError("hierarchical: linking interrupted");
  links_.swap(staged.links);
  cluster_links_.swap(staged.cluster_links);
  return absl::OkStatus();
}

absl::StatusOr<bool> HierarchicalSolver::RefinePass(bool* completed) {
  *completed = false;
  const int n = static_cast<int>(nodes_.size());
  Staged staged;
  staged.links.resize(n);
  staged.cluster_links.resize(clusters_.size());
  std::vector<std::vector<Pair>> splits(n);
  arena().execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, n, 64), [&](const tbb::blocked_range<int>& range) {
      if (ShouldStop()) return;
      for (int r = range.begin(); r < range.end(); ++r) {
        if (IsCluster(r)) {
          // A cluster's links, pair by pair (adjacent), against the bound they were made with.
          const auto& list = cluster_links_[r - first_cluster_];
          auto& keep = staged.cluster_links[r - first_cluster_];
          for (size_t i = 0; i < list.size();) {
            size_t j = i;
            while (j < list.size() && list[j].source == list[i].source) ++j;
            const Pair pair{r, list[i].source};
            // At full weight whatever the samples saw: a decision that followed the estimate's own
            // outcome (keeping zeros more readily) would bias the light low.
            const Split split =
                ClusterPairFits(pair, list[i].f_hi) ? Split::kNone : ClusterSplit(pair);
            if (split != Split::kNone) {
              SplitPair(pair, split, &splits[r]);
            } else {
              keep.insert(keep.end(), list.begin() + static_cast<std::ptrdiff_t>(i),
                          list.begin() + static_cast<std::ptrdiff_t>(j));
            }
            i = j;
          }
          continue;
        }
        const auto& list = links_[r];
        if (list.empty()) continue;
        const Node& nr = nodes_[r];
        const FaceSides& ir = face_info_[nr.face];
        // The links of one pair are adjacent (created together); test each pair as a whole with
        // the current B (the BF oracle of ExaminePair, from the stored unoccluded factors).
        for (size_t i = 0; i < list.size();) {
          size_t j = i;
          const int source = list[i].source;
          if (IsCluster(source)) {
            // A face piece's links to a cluster: as the cluster links above.
            while (j < list.size() && list[j].source == source) ++j;
            const Pair pair{r, source};
            const Split split =
                ClusterPairFits(pair, list[i].f_hi) ? Split::kNone : ClusterSplit(pair);
            if (split != Split::kNone) {
              SplitPair(pair, split, &splits[r]);
            } else {
              staged.links[r].insert(staged.links[r].end(),
                                     list.begin() + static_cast<std::ptrdiff_t>(i),
                                     list.begin() + static_cast<std::ptrdiff_t>(j));
            }
            i = j;
            continue;
          }
          double db[2];
          SourceVariation(source, db);
          Oracle oracle;
          while (j < list.size() && list[j].source == source) {
            const Link& l = list[j];
            if (ir[l.receiver_side].Receives()) {
              const double b = b_[2 * source + l.source_side].Sum();
              oracle.receiver += b * l.f_range;
              oracle.source += db[l.source_side] * l.f_hi * kSourceWeight;
              if (l.partial == kLinkPartial) oracle.visibility += b * l.f_hi;
              if (l.partial == kLinkHidden) oracle.visibility += kHiddenWeight * b * l.f_hi;
            }
            ++j;
          }
          oracle.receiver *= nr.area;
          oracle.source *= nr.area;
          oracle.visibility *= nr.area;
          const Split split = Decide({r, source}, oracle);
          if (split != Split::kNone) {
            SplitPair({r, source}, split, &splits[r]);
          } else {
            staged.links[r].insert(staged.links[r].end(),
                                   list.begin() + static_cast<std::ptrdiff_t>(i),
                                   list.begin() + static_cast<std::ptrdiff_t>(j));
          }
          i = j;
        }
      }
    });
  });
  std::vector<Pair> pairs;
  for (int r = 0; r < n; ++r) pairs.insert(pairs.end(), splits[r].begin(), splits[r].end());
  std::vector<std::vector<Pair>>().swap(splits);
  if (pairs.empty()) {
    *completed = true;
    return false;
  }
  absl::StatusOr<bool> complete = Expand(std::move(pairs), &staged);
  if (!complete.ok()) return complete.status();
  if (!*complete) return false;  // Interrupted: the links stay as they were.
  links_.swap(staged.links);
  cluster_links_.swap(staged.cluster_links);
  *completed = true;
  return true;
}

Rgb HierarchicalSolver::SourceRadiosity(const Link& l) const {
  const Node& s = nodes_[l.source];
  int shares = 0;
  Rgb b;
  for (int c = 0; c < s.num_children && c < 4; ++c) {
    if (l.child_share[c] == 0) continue;
    shares += l.child_share[c];
    b += b_[2 * children_[s.first_child + c] + l.source_side] *
         static_cast<double>(l.child_share[c]);
  }
  // A leaf source, or no look-ahead: the source's own (area-mean) radiosity.
  return shares > 0 ? b / shares : b_[2 * l.source + l.source_side];
}

bool HierarchicalSolver::Gather() {
  const int n = static_cast<int>(nodes_.size());
  arena().execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, n, 256),
                      [&](const tbb::blocked_range<int>& range) {
                        if (ShouldStop()) return;
                        for (int r = range.begin(); r < range.end(); ++r) {
                          if (IsCluster(r)) {
                            for (ClusterLink& l : cluster_links_[r - first_cluster_]) {
                              l.e = b_[2 * l.source + l.source_side] * static_cast<double>(l.f);
                            }
                            continue;
                          }
                          Rgb g[2];
                          for (const Link& l : links_[r]) {
                            if (l.f > 0)
                              g[l.receiver_side] += SourceRadiosity(l) * static_cast<double>(l.f);
                          }
                          g_[2 * r] = g[0];
                          g_[2 * r + 1] = g[1];
                        }
                      });
  });
  return !ShouldStop();
}

bool HierarchicalSolver::PushPull(bool update, bool row_sums) {
  struct Books {
    Rgb absorbed, unshot, leaving, arriving;
    double residual = 0;
  };
  const int faces = static_cast<int>(roots_.size());
  std::vector<Books> books(faces);
  const Rgb one = Rgb::Gray(1);
  arena().execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<int>(0, faces, 1), [&](const tbb::blocked_range<int>& range) {
          for (int f = range.begin(); f < range.end(); ++f) {
            if (roots_[f] < 0 || ShouldStop()) continue;
            const FaceSides& info = face_info_[f];
            Books& bk = books[f];
            // Depth-first: G is pushed down (each piece adds its ancestors'), B pulled up.
            auto visit = [&](auto&& self, int node, const Rgb& down0, const Rgb& down1) -> void {
              const Node& nd = nodes_[node];
              Rgb tot[2] = {down0 + g_[2 * node], down1 + g_[2 * node + 1]};
              if (nd.num_children == 0) {
                if (row_sums) {  // B = 1 everywhere: what arrives is the sum of the factors.
                  for (int side = 0; side < 2; ++side) {
                    row_sum_[2 * node + side] = tot[side].g;
                  }
                  return;
                }
                // An enclosed side receives nothing (what a coarser link pushed down to it is
                // counted with the escaped power, as the estimated factors' other errors are).
                for (int side = 0; side < 2; ++side) {
                  if (openness_[2 * node + side] == 0) tot[side] = Rgb();
                  if (!closure_.empty()) tot[side] *= closure_[2 * node + side];
                }
                for (int side = 0; side < 2; ++side) {
                  const Rgb h = tot[side] * nd.area;  // Power arriving at this side.
                  bk.arriving += h;
                  bk.absorbed += (one - info[side].reflectance - info[side].transmittance) * h;
                  if (!info[side].exists) continue;
                  // B = E + R G + T G' (the other side's G passes T through).
                  const Rgb target = info[side].exitance + info[side].reflectance * tot[side] +
                                     info[side ^ 1].transmittance * tot[side ^ 1];
                  Rgb& b = b_[2 * node + side];
                  if (update) {
                    b = target;
                    b_lo_[2 * node + side] = b_hi_[2 * node + side] = static_cast<float>(b.Sum());
                  } else {
                    const Rgb u = (target - b) * nd.area;
                    bk.unshot += u;
                    bk.residual += Abs(u).Sum();
                    bk.leaving += b * nd.area;
                  }
                }
                return;
              }
              Rgb pulled[2];
              float lo[2] = {std::numeric_limits<float>::max(), std::numeric_limits<float>::max()};
              float hi[2] = {std::numeric_limits<float>::lowest(),
                             std::numeric_limits<float>::lowest()};
              for (int c = 0; c < nd.num_children; ++c) {
                const int child = children_[nd.first_child + c];
                // What reaches this piece goes to its children in proportion to their openness
                // (the same power in all: sum over children of A_c o_c = A o).
                double ratio[2];
                for (int side = 0; side < 2; ++side) {
                  const float o = openness_[2 * node + side];
                  ratio[side] = o > 0 ? openness_[2 * child + side] / o : 0.0;
                }
                self(self, child, tot[0] * ratio[0], tot[1] * ratio[1]);
                if (update) {
                  const double w = nodes_[child].area / nd.area;
                  for (int side = 0; side < 2; ++side) {
                    pulled[side] += b_[2 * child + side] * w;
                    lo[side] = std::min(lo[side], b_lo_[2 * child + side]);
                    hi[side] = std::max(hi[side], b_hi_[2 * child + side]);
                  }
                }
              }
              if (update) {
                for (int side = 0; side < 2; ++side) {
                  b_[2 * node + side] = pulled[side];
                  b_lo_[2 * node + side] = lo[side];
                  b_hi_[2 * node + side] = hi[side];
                }
              }
            };
            Rgb from_clusters[2];
            ClusterIrradiance(f, from_clusters);
            visit(visit, roots_[f], from_clusters[0], from_clusters[1]);
          }
        });
  });
  if (ShouldStop()) return false;
  if (row_sums) return true;
  if (update) {
    PullClusters();
    return true;
  }
  Books total;
  for (const Books& bk : books) {
    total.absorbed += bk.absorbed;
    total.unshot += bk.unshot;
    total.leaving += bk.leaving;
    total.arriving += bk.arriving;
    total.residual += bk.residual;
  }
  absorbed_ = CompensatedRgb();
  absorbed_ += total.absorbed;
  unshot_ = total.unshot;
  // What left the surfaces and arrived nowhere (with the estimated factors' error).
  escaped_ = CompensatedRgb();
  escaped_ += total.leaving - total.arriving;
  residual_ = total.residual;
  progress_.unshot_fraction = residual_ / emitted_.Sum();
  return true;
}

bool HierarchicalSolver::MeasureClosure() {
  const std::vector<Rgb> b = b_;
  std::fill(b_.begin(), b_.end(), Rgb::Gray(1));
  row_sum_.assign(b_.size(), 0.0);
  const bool measured = Gather() && PushPull(/*update=*/false, /*row_sums=*/true);
  b_ = b;
  if (!measured) return false;
  closure_.assign(b_.size(), 1.0);
  // Links come only from sides that send light: the sums are whole only when every side does.
  bool all_send = closed_;
  for (int slot = 0; all_send && slot < static_cast<int>(2 * mesh_.elements().size()); ++slot) {
    all_send = !sides().exists(slot) || sides()[slot].Sends();
  }
  for (size_t k = 0; k < nodes_.size(); ++k) {
    if (nodes_[k].num_children != 0 || IsCluster(static_cast<int>(k))) continue;
    for (int side = 0; side < 2; ++side) {
      const size_t i = 2 * k + side;
      const double sum = row_sum_[i];
      if (!(sum > 0)) continue;
      // A closed scene of sides that all send: every side open all round sees them all round,
      // its factors sum to 1; anywhere they never exceed it.
      const bool open_side = openness_[i] >= 1.0f;
      if ((all_send && open_side && sum > 0.5) || sum > 1) closure_[i] = 1 / sum;
    }
  }
  return true;
}

bool HierarchicalSolver::UpdateBooks() {
  books_current_ = MeasureClosure() && Gather() && PushPull(false);
  return books_current_;
}

bool HierarchicalSolver::ApplySweepMap() { return Gather() && PushPull(/*update=*/true); }

bool HierarchicalSolver::KrylovCycle() {
  // The unknowns are the leaves' B (inner pieces and clusters are their area means, which every
  // linear combination keeps); the inner product weighs each leaf side by its area.
  const size_t n = b_.size();
  std::vector<double> weight(n, 0.0);
  for (size_t k = 0; k < nodes_.size(); ++k) {
    if (nodes_[k].num_children == 0 && !IsCluster(static_cast<int>(k))) {
      weight[2 * k] = weight[2 * k + 1] = nodes_[k].area;
    }
  }
  auto dot = [&](const std::vector<Rgb>& u, const std::vector<Rgb>& v) {
    double s = 0;
    for (size_t i = 0; i < n; ++i) {
      if (weight[i] > 0) s += weight[i] * (u[i].r * v[i].r + u[i].g * v[i].g + u[i].b * v[i].b);
    }
    return s;
  };
  const std::vector<Rgb> x0 = b_, g0 = g_;
  auto undo = [&] {
    b_ = x0;
    g_ = g0;
    return false;
  };
  // S(0) = E, and r0 = E - (x0 - K x0) = S(x0) - x0.
  std::fill(b_.begin(), b_.end(), Rgb());
  if (!ApplySweepMap()) return undo();
  const std::vector<Rgb> e = b_;
  b_ = x0;
  if (!ApplySweepMap()) return undo();
  std::vector<std::vector<Rgb>> v(1, std::vector<Rgb>(n));
  for (size_t i = 0; i < n; ++i) v[0][i] = b_[i] - x0[i];
  const double beta = std::sqrt(dot(v[0], v[0]));
  if (!(beta > 0)) {
    undo();
    return true;
  }
  for (Rgb& c : v[0]) c *= 1 / beta;
  // Arnoldi with modified Gram-Schmidt, the Hessenberg matrix reduced by Givens rotations as it
  // grows; stops early once the residual is a tenth of the tolerance (in power).
  const int m = kKrylovDimension;
  std::vector<std::vector<double>> h(m + 1, std::vector<double>(m, 0.0));
  std::vector<double> cs(m), sn(m), g(m + 1, 0.0);
  g[0] = beta;
  double area = 0;
  for (double w : weight) area += w;
  const double stop_at = 0.1 * options_.tolerance * emitted_.Sum() / std::sqrt(std::max(area, 1e-300));
  int used = 0;
  for (int j = 0; j < m; ++j) {
    // w = A v_j = v_j - K v_j = v_j - (S(v_j) - E).
    b_ = v[j];
    if (!ApplySweepMap()) return undo();
    std::vector<Rgb> w(n);
    for (size_t i = 0; i < n; ++i) w[i] = v[j][i] - (b_[i] - e[i]);
    for (int i = 0; i <= j; ++i) {
      h[i][j] = dot(w, v[i]);
      for (size_t k = 0; k < n; ++k) w[k] -= v[i][k] * h[i][j];
    }
    h[j + 1][j] = std::sqrt(dot(w, w));
    for (int i = 0; i < j; ++i) {
      const double t = cs[i] * h[i][j] + sn[i] * h[i + 1][j];
      h[i + 1][j] = -sn[i] * h[i][j] + cs[i] * h[i + 1][j];
      h[i][j] = t;
    }
    const double r = std::hypot(h[j][j], h[j + 1][j]);
    cs[j] = r > 0 ? h[j][j] / r : 1;
    sn[j] = r > 0 ? h[j + 1][j] / r : 0;
    h[j][j] = r;
    h[j + 1][j] = 0;
    g[j + 1] = -sn[j] * g[j];
    g[j] = cs[j] * g[j];
    used = j + 1;
    if (std::fabs(g[j + 1]) <= stop_at || !(h[j][j] > 0)) break;
    if (j + 1 < m) {
      const double norm = std::sqrt(dot(w, w));
      if (!(norm > 0)) break;
      for (Rgb& c : w) c *= 1 / norm;
      v.push_back(std::move(w));
    }
  }
  // y from the triangular system, x = x0 + V y.
  std::vector<double> y(used, 0.0);
  for (int i = used - 1; i >= 0; --i) {
    double s = g[i];
    for (int k = i + 1; k < used; ++k) s -= h[i][k] * y[k];
    y[i] = h[i][i] != 0 ? s / h[i][i] : 0;
  }
  b_ = x0;
  for (int k = 0; k < used; ++k) {
    for (size_t i = 0; i < n; ++i) b_[i] += v[k][i] * y[k];
  }
  progress_.shots += used + 2;
  // G of the new B, for the sweep that follows.
  return Gather() || undo();
}

bool HierarchicalSolver::Sweep() {
  // Kept to undo a sweep cut short, so the books stay those of the previous iterate.
  saved_b_ = b_;
  saved_b_lo_ = b_lo_;
  saved_b_hi_ = b_hi_;
  saved_g_ = g_;
  saved_cluster_e_.clear();
  for (const auto& list : cluster_links_) {
    for (const ClusterLink& l : list) saved_cluster_e_.push_back(l.e);
  }
  if (PushPull(true) && Gather() && PushPull(false)) return true;
  b_.swap(saved_b_);
  b_lo_.swap(saved_b_lo_);
  b_hi_.swap(saved_b_hi_);
  g_.swap(saved_g_);
  size_t at = 0;
  for (auto& list : cluster_links_) {
    for (ClusterLink& l : list) l.e = saved_cluster_e_[at++];
  }
  return false;
}

absl::StatusOr<bool> HierarchicalSolver::Step() {
  if (done_) return false;
  const double refine_at = std::max(options_.tolerance, kRefineResidual);
  if (!measured_ && !(measured_ = MeasureOpenness())) {
    EndStep(/*interrupted=*/true);
    return true;
  }
  bool interrupted = false;
  if (!linked_) {
    absl::Status s = InitialLinks();
    if (absl::IsCancelled(s)) {  // Stopped or out of time.
      interrupted = true;
    } else if (!s.ok()) {
      return s;
    } else {
      linked_ = true;
      if (params_.max_refine_passes == 0) links_final_ = true;
      interrupted = !UpdateBooks();
    }
  } else if (!books_current_) {
    // The books of new links were cut short: finish them before anything else.
    interrupted = !UpdateBooks();
  } else if (!links_final_ && progress_.unshot_fraction <= refine_at) {
    bool completed = false;
    absl::StatusOr<bool> changed = RefinePass(&completed);
    if (!changed.ok()) return changed.status();
    if (!completed) {
      links_final_ = true;  // Out of time: finish with the links as they are.
      interrupted = true;
    } else {
      ++refine_passes_;
      if (!*changed || refine_passes_ >= params_.max_refine_passes) links_final_ = true;
      if (*changed) interrupted = !UpdateBooks();
    }
  } else {
    // A Krylov cycle from the current B, then one Jacobi sweep: B from G, then G and the
    // residual from the new B (and the pieces' B ranges the refinement reads).
    const double before = residual_;
    interrupted = !KrylovCycle() || !Sweep();
    if (!interrupted) {
      progress_.shots += 1;
      stalled_cycles_ = links_final_ && residual_ > kStallFactor * before ? stalled_cycles_ + 1 : 0;
      stalled_ = stalled_cycles_ >= kStallCycles &&
                 progress_.unshot_fraction > options_.tolerance;
    }
  }
  EndStep(interrupted);
  if ((links_final_ && books_current_ && progress_.unshot_fraction <= options_.tolerance) ||
      stalled_) {
    done_ = true;
  }
  return !done_;
}

bool HierarchicalSolver::SaveState(StateWriter* out) const {
  SaveBase(out);
  out->Put("hierarchical.flags", std::array<bool, 7>{measured_, linked_, books_current_,
                                                     links_final_, done_, closed_, stalled_});
  out->Put("hierarchical.refine_passes", refine_passes_);
  out->Put("hierarchical.stalled_cycles", stalled_cycles_);
  out->PutVector("hierarchical.closure", closure_);
  out->Put("hierarchical.unshot", unshot_);
  out->Put("hierarchical.residual", residual_);
  out->PutVector("hierarchical.openness", openness_);
  // Links receiver by receiver: the count of each, then all of them.
  std::vector<int64_t> counts(links_.size());
  int64_t total = 0;
  for (size_t k = 0; k < links_.size(); ++k) total += counts[k] = links_[k].size();
  std::vector<Link> all;
  all.reserve(static_cast<size_t>(total));
  for (const std::vector<Link>& l : links_) all.insert(all.end(), l.begin(), l.end());
  out->PutVector("hierarchical.link_counts", counts);
  out->PutVector("hierarchical.links", all);
  std::vector<int64_t> cluster_counts(cluster_links_.size());
  std::vector<ClusterLink> cluster_all;
  for (size_t k = 0; k < cluster_links_.size(); ++k) {
    cluster_counts[k] = static_cast<int64_t>(cluster_links_[k].size());
    cluster_all.insert(cluster_all.end(), cluster_links_[k].begin(), cluster_links_[k].end());
  }
  out->PutVector("hierarchical.cluster_link_counts", cluster_counts);
  out->PutVector("hierarchical.cluster_links", cluster_all);
  out->PutVector("hierarchical.b", b_);
  out->PutVector("hierarchical.g", g_);
  out->PutVector("hierarchical.b_lo", b_lo_);
  out->PutVector("hierarchical.b_hi", b_hi_);
  return true;
}

absl::Status HierarchicalSolver::RestoreState(StateReader* in) {
  if (absl::Status st = RestoreBase(in); !st.ok()) return st;
  std::array<bool, 7> flags{};
  std::vector<int64_t> counts(links_.size());
  std::vector<Link> all;
  std::vector<int64_t> cluster_counts(cluster_links_.size());
  std::vector<ClusterLink> cluster_all;
  for (absl::Status st :
       {in->Get("hierarchical.flags", &flags),
        in->Get("hierarchical.refine_passes", &refine_passes_),
        in->Get("hierarchical.stalled_cycles", &stalled_cycles_),
        in->GetAnyVector("hierarchical.closure", &closure_),
        in->Get("hierarchical.unshot", &unshot_), in->Get("hierarchical.residual", &residual_),
        in->GetAnyVector("hierarchical.openness", &openness_),
        in->GetVector("hierarchical.link_counts", &counts),
        in->GetAnyVector("hierarchical.links", &all),
        in->GetVector("hierarchical.cluster_link_counts", &cluster_counts),
        in->GetAnyVector("hierarchical.cluster_links", &cluster_all),
        in->GetVector("hierarchical.b", &b_), in->GetVector("hierarchical.g", &g_),
        in->GetVector("hierarchical.b_lo", &b_lo_), in->GetVector("hierarchical.b_hi", &b_hi_)}) {
    if (!st.ok()) return st;
  }
  std::tie(measured_, linked_, books_current_, links_final_, done_, closed_, stalled_) =
      std::tuple(flags[0], flags[1], flags[2], flags[3], flags[4], flags[5], flags[6]);
  // Every index is checked before it is used: the sweeps index without checks.
  const size_t n = nodes_.size();
  if (!(closure_.empty() || closure_.size() == 2 * n)) {
    return absl::DataLossError("the hierarchical state's closure is of another hierarchy");
  }
  if (!(openness_.empty() || openness_.size() == 2 * n) || (measured_ && openness_.empty())) {
    return absl::DataLossError("the hierarchical state's openness is of another hierarchy");
  }
  size_t at = 0;
  for (size_t k = 0; k < n; ++k) {
    if (counts[k] < 0 || static_cast<size_t>(counts[k]) > all.size() - at) {
      return absl::DataLossError("the hierarchical state's links do not add up");
    }
    links_[k].assign(all.begin() + at, all.begin() + at + counts[k]);
    at += counts[k];
    for (const Link& l : links_[k]) {
      if (l.source < 0 || static_cast<size_t>(l.source) >= n || l.receiver_side > 1 ||
          l.source_side > 1) {
        return absl::DataLossError("the hierarchical state has a link to no piece");
      }
    }
  }
  if (at != all.size()) return absl::DataLossError("the hierarchical state's links do not add up");
  at = 0;
  for (size_t k = 0; k < cluster_links_.size(); ++k) {
    if (cluster_counts[k] < 0 || static_cast<size_t>(cluster_counts[k]) > cluster_all.size() - at) {
      return absl::DataLossError("the hierarchical state's cluster links do not add up");
    }
    cluster_links_[k].assign(cluster_all.begin() + at,
                             cluster_all.begin() + at + cluster_counts[k]);
    at += cluster_counts[k];
    for (const ClusterLink& l : cluster_links_[k]) {
      if (l.source < 0 || static_cast<size_t>(l.source) >= n || l.source_side > 1) {
        return absl::DataLossError("the hierarchical state has a cluster link to no piece");
      }
    }
  }
  if (at != cluster_all.size()) {
    return absl::DataLossError("the hierarchical state's cluster links do not add up");
  }
  return in->Finish();
}

Solution HierarchicalSolver::Snapshot() const {
  Solution sol = NewSolution();
  const auto& elements = mesh_.elements();
  sol.radiosity.assign(2 * elements.size(), Rgb());
  for (size_t e = 0; e < elements.size(); ++e) {
    const int leaf = leaf_of_element_[e];
    if (leaf < 0) continue;
    const FaceSides& info = face_info_[elements[e].face];
    for (int side = 0; side < 2; ++side) {
      if (info[side].exists) sol.radiosity[Slot(static_cast<int>(e), side)] = b_[2 * leaf + side];
    }
  }
  sol.unshot_power = unshot_;
  if (!done_) AddAmbient(&sol);  // The residual's light, before convergence.
  sol.links = links();
  sol.link_memory_bytes = memory_bytes();
  return sol;
}

int64_t HierarchicalSolver::links() const {
  int64_t total = 0;
  for (const auto& list : links_) total += static_cast<int64_t>(list.size());
  for (const auto& list : cluster_links_) total += static_cast<int64_t>(list.size());
  return total;
}

std::vector<int> HierarchicalSolver::ReceiverPieces() const {
  std::vector<int> piece(mesh_.elements().size(), -1);
  // Depth first from every face root, carrying the deepest gathering node so far.
  std::vector<std::pair<int32_t, int32_t>> stack;
  for (int32_t root : roots_) {
    if (root >= 0) stack.push_back({root, -1});
  }
  while (!stack.empty()) {
    auto [n, deepest] = stack.back();
    stack.pop_back();
    const auto& list = links_[n];
    if (std::any_of(list.begin(), list.end(), [](const Link& l) { return l.f > 0; })) deepest = n;
    const Node& node = nodes_[n];
    if (node.element >= 0 && static_cast<size_t>(node.element) < piece.size()) {
      piece[node.element] = deepest;
    }
    for (int32_t c = 0; c < node.num_children; ++c) {
      stack.push_back({children_[node.first_child + c], deepest});
    }
  }
  return piece;
}

int64_t HierarchicalSolver::memory_bytes() const {
  int64_t bytes = static_cast<int64_t>(
      nodes_.capacity() * sizeof(Node) + children_.capacity() * sizeof(int32_t) +
      roots_.capacity() * sizeof(int32_t) + leaf_of_element_.capacity() * sizeof(int32_t) +
      face_info_.capacity() * sizeof(FaceSides) + (b_.capacity() + g_.capacity()) * sizeof(Rgb) +
      (b_lo_.capacity() + b_hi_.capacity()) * sizeof(float) +
      links_.capacity() * sizeof(std::vector<Link>));
  for (const auto& list : links_) bytes += static_cast<int64_t>(list.capacity() * sizeof(Link));
  for (const auto& list : cluster_links_) {
    bytes += static_cast<int64_t>(list.capacity() * sizeof(ClusterLink));
  }
  bytes += static_cast<int64_t>(
      clusters_.capacity() * sizeof(Cluster) +
      (cluster_faces_.capacity() + parent_cluster_.capacity()) * sizeof(int32_t) +
      cluster_face_area_.capacity() * sizeof(double) +
      (face_centroid_.capacity() + face_normal_.capacity()) * sizeof(Vec3));
  return bytes;
}

}  // namespace radiosity
