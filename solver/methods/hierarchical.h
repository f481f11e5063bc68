// Hierarchical radiosity (Hanrahan, Salzman & Aupperle 1991, "A Rapid Hierarchical Radiosity
// Algorithm"; HSA below), with visibility by shadow rays (which the original lacked).
//
// Hierarchy. Every mesh face (Mesh::faces(): the traced quads and triangles) gets a tree of pieces
// over its (u, v) parameter square: the face's grid of patches is halved (by patch rows or
// columns, the longer physical extent first) down to single patches, and each patch follows the
// mesh's own quadtree (Mesh::nodes()) down to its elements. Leaves are exactly the mesh elements,
// so no piece is smaller than an element and the answer maps one-to-one onto element slots; empty
// pieces (beyond a triangle's diagonal) are dropped and single-child chains collapsed.
//
// Links. A link carries light from a source piece s to a receiver piece r (HSA sec. 3):
//   G_r += F_rs B_s,
// F_rs the form factor from r to s: Lambert's exact point-to-polygon factor
// (PointToPolygonFormFactorClipped) averaged over points of r, times the visible fraction.
//  - Points: `formfactor.analytic_points` stratified points of r, the same for all of r's links,
//    so the factors of a piece to all sources sum to exactly 1 in a closed scene; a leaf (which
//    cannot be split where F varies) averages over 4 times as many cell midpoints instead (the
//    midpoint rule, weighted by the area element).
//  - Visibility: `formfactor.shadow_rays` rays from each point to stratified points of s
//    (SegmentVisible), the kernel-weighted visible fraction F_vis = mean F x sum F V / sum F. A
//    probe (from the points and r's corners) decides whether the pair is partly hidden; a partly
//    hidden pair that is not split is estimated with fresh rays from 16 times more points, so the
//    decision never selects on the estimate's own outcome (which would darken penumbrae).
//  - Each (receiver side, source side) that can exchange light is its own link: two-sided and
//    transmitting surfaces work as in the other solvers. Pieces of one face never link (a planar
//    face cannot see itself; the fold of a non-planar quad is neglected, as elsewhere), coplanar
//    faces exchange nothing.
//  - Look-ahead: a link to an inner source also keeps the share of F taken by each of the
//    source's children, and gathers their B weighted by it rather than the source's area mean.
//
// Refinement: the BF oracle (HSA sec. 4, with area: power, as in Cohen & Wallace 1993, 7.4),
// split into the errors it stands for, each B x F x A in watts:
//   receiver    B_s (F_hi - F_lo) A_r     F varies over r  -> split r (splitting s cannot help:
//                                         Lambert integrates over s exactly)
//   source      3 dB_s F_hi A_r           B varies over s  -> split s (3: these errors share their
//                                         sign over many links and add up)
//   visibility  B_s F_hi A_r              partly hidden (half that if wholly hidden: a few rays
//                                         cannot tell hidden from mostly hidden) -> split the
//                                         larger
// where [F_lo, F_hi] is the range of F over r's points and corners (F_hi at least HSA's disk
// estimate A_s / (pi d^2 + A_s) when s is within r's size, d the gap between bounding spheres),
// and dB_s the largest departure of a leaf's B below s from s's mean. A pair is refined while the
// sum exceeds epsilon x emitted power and a useful split exists. Receivers that absorb everything
// (R = T = 0) ask for nothing. Refinement starts from every pair of face roots with B = E; pairs
// with no visible exchange yet where they could still be split are kept with F = 0, so that once
// the solution has settled (residual below 5 %) each refinement pass re-tests every link with the
// current B, and the solution is iterated again, until a pass refines nothing (HSA's "solve,
// refine, repeat"; at most HierarchicalParams::max_refine_passes).
//
// Contact: a link to a partly hidden receiver pushes its irradiance down to all of the receiver's
// leaves, also to those no light can reach (the floor under a block resting on it). Before
// solving, 20 probe rays (from the element's four corners and 16 stratified points, in cosine
// directions) measure each receiving leaf side's openness o: the fraction that does not meet the
// back of a one-sided surface (which sends nothing); a piece's o is its leaves' area-weighted
// mean. A piece passes what reaches it to each child in proportion to o_child / o_piece (the same
// power in all), and a leaf with o = 0 gathers nothing: the power goes where the probes see out.
// Shadows not caused by contact leave o = 1 everywhere and are the links' business.
//
// Solution (HSA sec. 5): Jacobi sweeps. Gather: each piece gathers G over its links from the
// current B. Push-pull: G is pushed down to the leaves (adding each ancestor's), where
//   B = E + R G + T G'   (G' at the other side; transmission as in the progressive solver)
// and B is pulled up as the area-weighted mean of the children. The residual
//   u = E + R G + T G' - B   (per leaf side, times its area)
// is the power that has arrived but is not yet accounted for in B; the solve stops when
// sum |u| <= tolerance x emitted and refinement is complete. Energy books from the leaves:
// absorbed = sum (1 - R - T) H with H = G x A the arriving power, unshot = sum u, and
// escaped = sum B A - sum H (power that left surfaces minus power that arrived anywhere), so that
// emitted = absorbed + escaped + unshot to rounding; escaped also carries the error of the
// transport (slightly negative where the estimated factors sum above 1).
//
// Clusters (Smits, Arvo & Greenberg 1994, "A Clustering Algorithm for Radiosity in Complex
// Environments"; Sillion 1995), for scenes of more than HierarchicalParams::cluster_above_faces
// faces: a binary tree over the face roots (median splits of the faces' centroids along the longest
// axis of their box), each cluster with a bounding sphere and a cone of its faces' normals.
// Refinement starts from the whole scene paired with itself; a pair involving a cluster is split
// (the piece with the larger sphere that can be split) while the spheres overlap or the power it
// could carry, (B_s + 3 dB_s) F_hi A_r with
//   F_hi = A_s |cos_r|max |cos_s|max / (pi gap^2),
// the cosines bounded by the normal cones against the cone of directions between the spheres, is
// above epsilon; pairs of face pieces go to the rules above. A linked pair's factor is estimated
// by Monte Carlo: points x on s and y on r, area-uniform over their faces (points_ x shadow_rays_
// pairs, each with a shadow ray), F = A_s mean(cos_y cos_x V / (pi r^2)), unbiased whatever the
// shapes (a kernel between cluster centroids overestimated them over a concave surface:
// bench/REPORT.md, "Clustering"). A cluster source gives its area-mean B per side.
// A cluster receives as a whole only if its normals lie within 0.5 rad of their mean (within it,
// light is shared out without visibility); what it gathers, f B_s per unit area, goes to its faces'
// sides in proportion to A_f |cos_f| cos_s / d^2 from the source's centroid (cos_s from the
// source's normal when it has one), normalised so that the faces receive exactly f B_s A_r; sides
// that do not exist or are enclosed (openness 0) take no share. Each face adds what its ancestor
// clusters gathered before its own tree's push. A pair none of whose samples saw the other piece
// keeps one link of F = 0, re-tested at full weight by later passes (a lighter test for zeros
// would select on the estimate's outcome and bias the light low). A receiving cluster that no
// side can take a link's light (every share 0) is split instead. Coplanar planar pieces exchange
// nothing and are not linked.
//
// Cost: links grow about linearly with the elements the light needs (not N^2). Without clusters
// refinement starts from the F^2 pairs of face roots; with them, from one pair, and the sweeps pay
// for sharing each cluster link out over the cluster's faces.
// Results depend only on the seed: a pair's random streams are keyed by (seed, receiver, source),
// pairs are examined in parallel and merged in order, and every sum runs in a fixed order.
//
// Parameters from SolveOptions: tolerance (the residual, and the refinement epsilon, 0.1 x
// tolerance of the emitted power unless HierarchicalParams::epsilon is set),
// formfactor.analytic_points (receiver points per link, 4), formfactor.shadow_rays (shadow rays
// per point, 4), max_matrix_mb (refuse when the links would exceed it), threads, seed,
// max_seconds (also checked inside refinement).
#ifndef RADIOSITY_SOLVER_METHODS_HIERARCHICAL_H_
#define RADIOSITY_SOLVER_METHODS_HIERARCHICAL_H_

#include <array>
#include <atomic>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "solver/methods/solver.h"

namespace radiosity {

struct HierarchicalParams {
  // Refinement threshold as a fraction of the emitted power (B_s F_rs A_r against
  // epsilon x emitted); 0: kEpsilonPerTolerance x SolveOptions::tolerance.
  double epsilon = 0;
  // Refinement passes with the current solution after the initial linking, at most.
  int max_refine_passes = 8;
  // Scenes of more faces than this start from clusters of faces (see "Clusters" above); fewer
  // start from every pair of face roots. Negative: never cluster.
  int cluster_above_faces = kClusterAboveFaces;
  static constexpr double kEpsilonPerTolerance = 0.1;
  static constexpr int kClusterAboveFaces = 200;
};

class HierarchicalSolver : public SolverBase {
 public:
  // Fails with INVALID_ARGUMENT for bad parameters (points, shadow rays, epsilon, max_matrix_mb)
  // and RESOURCE_EXHAUSTED when the links between face roots alone would exceed max_matrix_mb.
  static absl::StatusOr<std::unique_ptr<HierarchicalSolver>> Create(
      const Scene& scene, const Mesh& mesh, const Visibility& visibility,
      const SolveOptions& options, const std::atomic<bool>* stop,
      const HierarchicalParams& params = HierarchicalParams());
  ~HierarchicalSolver() override;

  // The first step links the face roots and refines with B = E; later steps are one Jacobi sweep
  // each (gather, push-pull, residual), or a refinement pass when the residual has settled.
  // The stop flag and the deadline are checked between probes, pairs, pieces and faces; a step
  // cut short keeps the links (and the iterate) it started with.
  absl::StatusOr<bool> Step() override;
  bool Stalled() const override { return stalled_; }
  Solution Snapshot() const override;
  // The state: openness, every link, B and G per piece, the refinement's progress (the hierarchy
  // itself follows from the mesh).
  bool SaveState(StateWriter* out) const override;
  absl::Status RestoreState(StateReader* in) override;

  // Links held now (each a (receiver side, source side) pair of pieces; including the F = 0 ones
  // kept for later passes).
  int64_t links() const;
  // Bytes held by the hierarchy and its links (nodes, per-node solution arrays, link lists).
  int64_t memory_bytes() const;
  // Pieces in the hierarchy (inner nodes and the element leaves).
  int64_t nodes() const { return static_cast<int64_t>(nodes_.size()); }
  // Refinement passes with the current solution done so far (the initial linking not counted).
  int refine_passes() const { return refine_passes_; }
  // The refinement threshold in watts (channel sum).
  double epsilon_power() const { return epsilon_power_; }
  // Per mesh element: the piece whose gathered light it takes, the deepest node at or above its
  // leaf with a link of F > 0 (elements sharing one such piece gather the same G: the subdivision
  // the solution really has, drawn by DrawWireframe); -1 where no node above it gathers.
  std::vector<int> ReceiverPieces() const;

 private:
  struct Node {
    double u0, v0, u1, v1;  // Rectangle in the face's parameter square.
    double area = 0;
    int32_t face = -1;
    int32_t element = -1;      // Leaf: its mesh element.
    int32_t first_child = -1;  // Into children_.
    int32_t num_children = 0;
  };
  struct Link {
    int32_t source;  // Node.
    float f;         // Form factor from the receiver to the source, visibility included.
    float f_hi;      // Largest unoccluded factor over the receiver (for the oracle).
    float f_range;   // Its largest minus its smallest over the receiver (for the oracle).
    uint8_t receiver_side;
    uint8_t source_side;
    uint8_t partial;  // kLinkVisible, kLinkPartial (some probe rays blocked) or kLinkHidden.
    // Shares (of 255) of the factor taken by each of the source's first four children: the gather
    // weights their B by these instead of using the source's mean (all 0: use the mean).
    uint8_t child_share[4] = {0, 0, 0, 0};
  };
  // A link whose receiver is a cluster: what the cluster gathers from the source side, and how
  // it is shared out among the sides of its faces (see "Clusters" above).
  struct ClusterLink {
    int32_t source;  // Node (a face piece or a cluster).
    uint8_t source_side;
    uint8_t hidden;       // No sample saw the source (F = 0, kept to be tested again).
    float f;              // Sampled factor from the cluster (area mean) to the source side.
    float f_hi;           // Bound of the factor (see "Clusters" above), at most 1.
    float norm;           // A_R / sum over the cluster's face sides of A_f w_f.
    float source_at[3];   // The source's centroid.
    float source_dir[3];  // The source side's unit normal (0: a cluster of mixed orientation).
    Rgb e;                // Gathered: f x B of the source side (per unit area of the cluster).
  };
  // A cluster of faces: its faces' roots are cluster_faces_[first, first + count).
  struct Cluster {
    Vec3 centroid;  // Area-weighted.
    double radius = 0;
    int32_t first = 0, count = 0;
    // Unit normal per side when the faces agree (the mean of their unit normals is at least 0.9
    // long), else 0.
    Vec3 normal[2];
    bool sends = false;
    Vec3 axis;  // Normal cone: its axis (unit, or 0) and half-angle (pi: no bound).
    double spread = kPi;
    bool planar = false;  // Every face in one plane (through the centroid, normal axis).
  };
  // A bounding sphere, a cone of the normals, and whether the piece lies in one plane.
  struct Bound {
    Vec3 centre;
    double radius = 0;
    Vec3 axis;
    double spread = kPi;
    bool planar = false;
  };
  // The radiosity a link gathers from its source side (see Link::child_share).
  Rgb SourceRadiosity(const Link& l) const;
  static constexpr uint8_t kLinkVisible = 0, kLinkPartial = 1, kLinkHidden = 2;
  struct Pair {
    int32_t r, s;
  };
  // The outcome of looking at one pair: links to keep at r, or child pairs to look at.
  struct PairResult {
    std::vector<Link> links;
    std::vector<ClusterLink> cluster_links;
    std::vector<Pair> children;
    int64_t rays = 0;
  };
  // Per face: what each of its sides does (sides.h).
  using FaceSides = std::array<SideRule, 2>;

  HierarchicalSolver(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
                     const SolveOptions& options, const std::atomic<bool>* stop,
                     const HierarchicalParams& params);

  int BuildPatchRange(int face, int i0, int j0, int i1, int j1);
  int BuildMeshNode(int face, int quad_node);
  int MakeNode(int face, double u0, double v0, double u1, double v1, int element,
               const std::vector<int>& children);

  // Estimates pair (r, s) and decides: links at r, or child pairs (one of the pieces split).
  void ExaminePair(const Pair& pair, PairResult* out) const;
  // The refinement oracle's error estimates for a pair, in watts (channel sums).
  struct Oracle {
    double receiver = 0;    // B_s (F_hi - F_lo) A_r: F varies over the receiver.
    double source = 0;      // 3 dB_s F_hi A_r: B varies over the source.
    double visibility = 0;  // B_s F_hi A_r when partly hidden (half when wholly hidden).
  };
  enum class Split { kNone, kReceiver, kSource };
  Split Decide(const Pair& pair, const Oracle& oracle) const;
  bool IsCluster(int node) const { return node >= first_cluster_; }
  Bound BoundOf(int node) const;
  // Area-uniform point of a node from three uniform numbers: the point, its face and unit normal.
  Vec3 SamplePoint(int node, double a, double b, double c, int* face, Vec3* normal) const;
  void BuildClusters();
  int BuildCluster(int first, int count);
  // Whether the cluster pair (one of them a cluster) is linked (false: split), from the bound
  // f_hi of its factor and the current B.
  bool ClusterPairFits(const Pair& pair, double f_hi) const;
  // The piece of the pair to split: the one with the larger bounding sphere that can be split.
  Split ClusterSplit(const Pair& pair) const;
  // Estimates or splits a pair of which one piece is a cluster.
  void ExamineClusterPair(const Pair& pair, PairResult* out) const;
  // The irradiance per side that face f receives from its ancestors' cluster links.
  void ClusterIrradiance(int face, Rgb out[2]) const;
  // The weight (per unit area, before ClusterLink::norm) of face f's share of a cluster link, and
  // the side of f that receives it.
  double ShareWeight(int face, const ClusterLink& l, int* side) const;
  void PullClusters();
  void SplitPair(const Pair& pair, Split split, std::vector<Pair>* out) const;
  // Largest deviation of a leaf's B from s's mean B, per side (channel sum); 0 for a leaf.
  void SourceVariation(int s, double db[2]) const;
  // Expands pairs level by level into `staged` (per-node link lists). Returns false if cancelled
  // or past the deadline (nothing committed).
  struct Staged {
    std::vector<std::vector<Link>> links;                 // Per node.
    std::vector<std::vector<ClusterLink>> cluster_links;  // Per cluster.
  };
  absl::StatusOr<bool> Expand(std::vector<Pair> pairs, Staged* staged);
  absl::Status InitialLinks();
  // Re-tests every link with the current B; returns whether any link was refined.
  absl::StatusOr<bool> RefinePass(bool* completed);
  // G over every piece's links from the current B; false when cut short.
  bool Gather();
  // Sets openness_: per leaf side, the fraction of probe rays that do not meet the back of a
  // one-sided surface (0: enclosed, as a floor element under a block resting on it); per inner
  // piece, the area-weighted mean of its children's. Adds the probe rays traced; false when cut
  // short.
  bool MeasureOpenness();
  // Pushes G to the leaves; with update, sets leaf B to E + R G + T G' and pulls B up. Without,
  // computes the energy books and the residual of the current B; with row_sums, only records
  // what arrives at each leaf side in row_sum_. False when cut short.
  bool PushPull(bool update, bool row_sums = false);
  // closure_ from the links' factor sums (row_sum_, gathered from B = 1 everywhere): a leaf side
  // open all round in a closed scene (no openness probe escaped) whose sides all send light
  // (links come only from those) gathers its light scaled so that its factors sum to 1
  // exactly, and nowhere do they sum above 1. Near reflectance 1 the
  // solution is 1 / (1 - rho sum F): a sum off by 1e-4 would make it diverge or fall short.
  bool MeasureClosure();
  // G and the books of the current B (after new links); false when cut short.
  bool UpdateBooks();
  // One Jacobi sweep (B from G, then G and the books); false, and undone, when cut short.
  bool Sweep();
  // One cycle of restarted GMRES (Saad & Schultz 1986) on the system the sweeps iterate,
  // B - K B = E (K: gather, push and reflect; each product one sweep's work), from the current
  // B, minimising the area-weighted residual over up to kKrylovDimension products. Jacobi
  // sweeps converge like rho^k, hopelessly near rho = 1 (10^5 sweeps a decade at 0.99999); the
  // Krylov cycle removes the slow, nearly uniform mode at once. False, with B as before, when
  // cut short.
  bool KrylovCycle();
  // B := S(B), the sweep's affine map E + K B (Gather, then PushPull's update); false when cut
  // short.
  bool ApplySweepMap();
  static constexpr int kKrylovDimension = 16;
  int64_t LinkBytes(int64_t links) const;

  HierarchicalParams params_;

  std::vector<FaceSides> face_info_;
  std::vector<Node> nodes_;
  std::vector<int32_t> children_;
  std::vector<int32_t> roots_;  // Per face (-1: no area).
  std::vector<int32_t> leaf_of_element_;
  std::vector<float> openness_;           // Per node side (see MeasureOpenness).
  bool closed_ = false;                   // No openness probe left the scene.
  std::vector<double> row_sum_, closure_;  // Per node side (leaves; see MeasureClosure).
  std::vector<std::vector<Link>> links_;  // Per receiver node (face pieces; clusters: none).
  // Clusters: nodes [first_cluster_, nodes_.size()), children before parents.
  int first_cluster_ = std::numeric_limits<int>::max();
  std::vector<Cluster> clusters_;                        // Per cluster node.
  std::vector<std::vector<ClusterLink>> cluster_links_;  // Per cluster node, as receiver.
  std::vector<int32_t> cluster_faces_;                   // Face indices, grouped by cluster.
  std::vector<double> cluster_face_area_;  // Prefix sums of the faces' areas, in that order.
  std::vector<int32_t> parent_cluster_;    // Per node: the cluster above it (-1: none).
  std::vector<Vec3> face_centroid_;        // Per face (area-weighted).
  std::vector<Vec3> face_normal_;          // Per face (MeshFace::Normal).
  std::vector<Rgb> b_;  // Per node side (2 * node + side): radiosity (leaves) or its area mean.
  std::vector<Rgb> g_;  // Per node side: gathered over the node's own links.
  // Per node side: the least and greatest B (channel sum) of the leaves below it.
  std::vector<float> b_lo_, b_hi_;
  // The iterate before the current sweep (to undo one cut short).
  std::vector<Rgb> saved_b_, saved_g_;
  std::vector<float> saved_b_lo_, saved_b_hi_;
  std::vector<Rgb> saved_cluster_e_;

  double epsilon_power_ = 0;
  int points_ = 4, shadow_rays_ = 4;
  Rgb unshot_;
  double residual_ = 0;
  bool measured_ = false;  // openness_ is complete.
  bool linked_ = false;
  bool books_current_ = false;  // g_ and the books are those of the current links and B.
  bool links_final_ = false;
  int refine_passes_ = 0;
  bool done_ = false;
  // Krylov cycles in a row, once the links are final, that brought the residual down by less
  // than kStallFactor: after kStallCycles of them the solve stops as stalled.
  int stalled_cycles_ = 0;
  bool stalled_ = false;
  static constexpr int kStallCycles = 4;
  static constexpr double kStallFactor = 0.99;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_HIERARCHICAL_H_
