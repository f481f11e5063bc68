// Meshing with substructuring (Cohen et al. 1986; Shirley's thesis 6.1): every input polygon is
// cut into "faces" (quads, or triangles stored as quads with v3 == v2), each face into patches
// (which shoot) and each patch into elements (which receive). A patch keeps its elements in a
// quadtree over the face's (u, v) parameter square, so a ray hit on the input geometry,
// given as (face, u, v), finds its element in O(log) and adaptive refinement can split leaves.
//
// Parameterisation: the one Embree uses for RTC_GEOMETRY_TYPE_QUAD. A face with corners p0..p3 is
// two triangles, (p0, p1, p3) for u + v <= 1 and (p2, p3, p1) for u + v > 1:
//    P(u, v) = p0 + u (p1 - p0) + v (p3 - p0)              when u + v <= 1,
//    P(u, v) = p2 + (1 - u) (p3 - p2) + (1 - v) (p1 - p2)  otherwise.
// Each half has a constant Jacobian (twice its triangle's area), so element areas, centroids and
// area-uniform sampling are exact, also for non-planar quads (traced as the same two triangles).
#ifndef RADIOSITY_SOLVER_GEOMETRY_MESH_H_
#define RADIOSITY_SOLVER_GEOMETRY_MESH_H_

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/sides.h"
#include "solver/geometry/vec.h"
#include "solver/util/progress.h"
#include "solver/util/stop.h"

namespace radiosity {

// Largest ratio of a scene's longest edge to the element size that is meshed or counted at all.
inline constexpr double kMaxEdgeRatio = 1e8;

// The normal bound of agglomeration that jobs use unless told otherwise (MeshOptions).
inline constexpr double kDefaultAgglomerateDegrees = 30;

struct MeshOptions {
  // Target element edge length in scene units; 0 means derive it from max_elements.
  double element_size = 0;
  // Upper bound on the element count when element_size is 0 (the mesh has at most this many).
  int64_t max_elements = 4096;
  // Elements per patch edge is 2^patch_depth (patch_depth 2: up to 4 x 4 elements per patch).
  int patch_depth = 2;
  // Hard limit on elements, checked before allocating (protects a server from huge requests).
  int64_t element_limit = 20'000'000;
  // Agglomeration of small faces (as OpenFOAM's faceAgglomerate): faces whose edges are all
  // within the element size, that share an edge and a surface, and whose normals lie within this
  // many degrees of the normal of the face a group starts from, are gathered into one element
  // (and patch) of about the element size. 0: off, every face its own elements (what a Mesh
  // built here gets by default; jobs take kDefaultAgglomerateDegrees). Such an element's light
  // is a mean over the faces it holds; the quadtree-based methods (hierarchical, the matrix
  // estimators, adaptive refinement) need meshes without (Mesh::agglomerated).
  double agglomerate_degrees = 0;

  std::string ToString() const;
};

// One traced primitive: a quad of the input (or a piece of a larger polygon).
struct MeshFace {
  std::array<Vec3, 4> p;           // Corners in recentred coordinates (see Mesh::origin).
  std::array<Vec3, 2> normal;      // Unit front normal of each half (0: u + v <= 1, 1: u + v > 1).
  std::array<double, 2> jacobian;  // |dP/du x dP/dv| on each half; 0 for the empty half.
  std::array<int32_t, 4> vertex;   // Scene::vertices of p (vertex[3] == vertex[2] for triangles).
  int surface = -1;                // Index into Scene::surfaces.
  int input_face = -1;             // Index into Scene::faces.
  bool triangle = false;           // p3 == p2, the half u + v > 1 is empty.
  int first_patch = 0;             // Patches of this face: [first_patch, first_patch + pu * pv).
  int pu = 1, pv = 1;              // Patch grid over the (u, v) square.
  int nu = 1, nv = 1;              // Uniform element lattice over the (u, v) square.
  int64_t lattice = 0;             // Offset of this face's nu x nv cells in Mesh's lattice.
  double len_u = 0, len_v = 0;     // Longest edge along u and along v.

  int Half(double u, double v) const { return u + v <= 1.0 ? 0 : 1; }
  // The area of both halves, and their area-weighted unit normal.
  double Area() const { return 0.5 * (jacobian[0] + jacobian[1]); }
  Vec3 Normal() const { return Normalize(normal[0] * jacobian[0] + normal[1] * jacobian[1]); }
  Vec3 Eval(double u, double v) const;
  // The affine map of one half, also off it: evaluating a piece on its own half keeps points on
  // the diagonal u + v = 1 exact for both halves of a non-planar quad.
  Vec3 EvalOnHalf(int half, double u, double v) const {
    return half == 0 ? p[0] + u * (p[1] - p[0]) + v * (p[3] - p[0])
                     : p[2] + (1 - u) * (p[3] - p[2]) + (1 - v) * (p[1] - p[2]);
  }
};

// A node of a patch's quadtree over its (u, v) rectangle. Leaves hold an element (or -1 where the
// leaf has no area, e.g. beyond a triangle's diagonal).
//
// A node splits in u, in v or in both, so that leaves stay close to the target size on slivers
// too; children are contiguous, ordered u-low before u-high, then v-low before v-high.
struct QuadNode {
  enum Split : uint8_t { kLeaf = 0, kSplitU = 1, kSplitV = 2, kSplitBoth = 3 };
  float u0, v0, u1, v1;
  int32_t child = -1;    // First child, or -1 for a leaf.
  int32_t element = -1;  // Leaf only.
  int32_t face = -1;     // The MeshFace whose patch tree holds the node.
  uint8_t split = kLeaf;
};

struct Patch {
  int face = -1;
  int root = -1;                            // Index of its root QuadNode.
  int first_element = 0, num_elements = 0;  // Elements of a patch are contiguous.
  double area = 0;
};

// An element is a leaf of one face's quadtree, or, agglomerated, the whole of several faces: then
// face, node and (u0, v0, u1, v1) are those of its first face (the whole parameter square) and
// Mesh::Members lists them all; area and centroid are those of the union.
struct Element {
  int face = -1;
  int patch = -1;
  int node = -1;  // Its leaf in the patch's quadtree.
  int surface = -1;
  int index_in_surface = 0;  // The "element" column of elements.csv.
  float u0, v0, u1, v1;      // Rectangle in the face's parameter square.
  double area = 0;
  Vec3 centroid;                          // In scene coordinates (origin added back).
  int first_member = 0, num_members = 0;  // Agglomerated: its faces in Mesh::Members; else 0.
};

// The faces of an agglomerated element (Mesh::Members), each whole, with the cumulative share of
// the element's area up to and including each (the last is 1).
struct ElementMembers {
  const int32_t* faces = nullptr;
  const double* cumulative_area = nullptr;
  int count = 0;
};

// A convex polygon in a face's parameter square, and its image in space.
struct ElementPiece {
  int half = 0;
  int n = 0;
  std::array<double, 2 * 6> uv;  // Up to 6 (u, v) vertices (a rectangle clipped by a line has 5).
  double ParamArea() const;
};

// The pieces of the rectangle [u0,u1]x[v0,v1] of `face`'s parameter square on each half of its
// diagonal u + v = 1 (Mesh::Pieces for an element; the hierarchical solver's pieces of faces):
// halves with no area are left out. Returns the count (0 to 2).
int RectPieces(double u0, double v0, double u1, double v1, const MeshFace& face,
               std::array<ElementPiece, 2>* pieces);

class Mesh {
 public:
  // Builds the mesh of a validated scene. Fails with INVALID_ARGUMENT / RESOURCE_EXHAUSTED when
  // the options are out of range or the element count would exceed options.element_limit; with
  // `stop`, checked between the build's passes over the faces, CANCELLED or DEADLINE_EXCEEDED
  // (StopStatus) once it stops. `progress` hears the fraction built (faces split, then patches
  // enumerated) in steps of at least 1 %, ending at 1.
  static absl::StatusOr<Mesh> Build(const Scene& scene, const MeshOptions& options,
                                    const StopToken* stop = nullptr,
                                    const ProgressCallback& progress = {});

  // Number of elements Build would make with this element size (no allocation).
  static int64_t CountElements(const Scene& scene, double element_size, int patch_depth);

  const std::vector<MeshFace>& faces() const { return faces_; }
  const std::vector<Patch>& patches() const { return patches_; }
  const std::vector<Element>& elements() const { return elements_; }
  const std::vector<QuadNode>& nodes() const { return nodes_; }
  // What each element side does (sides.h), from the scene the mesh was built from.
  const SideTable& sides() const { return sides_; }
  // Scene coordinates = mesh (recentred) coordinates + origin().
  const Vec3& origin() const { return origin_; }
  double element_size() const { return element_size_; }
  // Diagonal of the scene's bounding box.
  double scale() const { return scale_; }

  // The element containing parameter point (u, v) of `face`, or -1. O(depth of the quadtree).
  int FindElement(int face, double u, double v) const;

  // The element's area-uniform sample: maps (r1, r2, r3) in [0,1)^3 to a point (mesh
  // coordinates), and returns the face and the half of it the point lies on (for the normal, and
  // the face a ray from it skips). On an agglomerated element r1 first picks a face by area.
  Vec3 SampleElement(int element, double r1, double r2, double r3, int* half, int* face) const;

  // The element's rectangle clipped to each half of its face (pieces with zero area omitted); of
  // an agglomerated element, those of its member `member` (the whole face).
  int Pieces(int element, std::array<ElementPiece, 2>* pieces, int member = 0) const;

  // Whether any element is agglomerated (MeshOptions::agglomerate_degrees).
  bool agglomerated() const { return !member_faces_.empty(); }
  // The normal bound faces were agglomerated within (MeshOptions::agglomerate_degrees; 0: off).
  double agglomerate_degrees() const { return agglomerate_degrees_; }
  // The faces element `element` holds when agglomerated (count 0 otherwise).
  ElementMembers Members(int element) const;
  // The faces that element `element` covers, in part or whole: its members, or its face.
  int FaceCount(int element) const { return std::max(1, elements_[element].num_members); }
  int FaceOf(int element, int member) const {
    const Element& e = elements_[element];
    return e.num_members > 0 ? member_faces_[e.first_member + member] : e.face;
  }

  // The leaf node containing (u, v) of `face`.
  int FindLeaf(int face, double u, double v) const;

  std::string ToString() const;

 private:
  friend class MeshRefiner;
  // Splits leaf n (in u, v or both); returns the index of its first child.
  int SplitNode(int n, uint8_t split);
  // Walks down from node n to the leaf containing (u, v).
  int Descend(int n, double u, double v) const;
  // Numbers the leaves with area as elements (patch by patch, depth first), builds the lattice
  // and the side table.
  // With `progress`: the fraction of the patches enumerated, as Build reports it.
  void Enumerate(const Scene& scene, const ProgressCallback& progress = {});
  // The elements of patch p, whose first face is agglomerated: one per group of its patch.
  void EnumerateGroup(int p, std::vector<int>* per_surface);
  // Groups the faces that one element can hold (MeshOptions::agglomerate_degrees) for element
  // size `target`: per face, its group's index (-1: not agglomerated, or alone on its surface);
  // returns the number of groups (of two faces or more, or of one face with a grouped edge
  // neighbour of its surface within the bound), and the faces in them in *grouped.
  int64_t Agglomerate(double target, double degrees, std::vector<int32_t>* group,
                      int64_t* grouped) const;

  // Edge neighbours of each face (built when agglomerating): face f's are
  // face_neighbours_[face_neighbour_start_[f] .. face_neighbour_start_[f + 1]).
  std::vector<int32_t> face_neighbour_start_, face_neighbours_;
  // When agglomerated, per face: its group (-1: none) and its own root node (a leaf holding the
  // group's element; -1: none); per group, its faces (group_faces_[group_start_[g] ..]).
  std::vector<int32_t> face_group_, face_node_, group_start_, group_faces_;
  // Patches of groups: patch k holds groups patch_groups_[k] .. patch_groups_[k + 1] - 1;
  // group_patch_[g] is g's patch.
  std::vector<int32_t> patch_groups_, group_patch_;
  // Agglomerated elements' faces (Element::first_member) and their cumulative area shares.
  double agglomerate_degrees_ = 0;
  std::vector<int32_t> member_faces_;
  std::vector<double> member_cumulative_;

  Vec3 origin_;
  double scale_ = 0;
  double element_size_ = 0;
  std::vector<MeshFace> faces_;
  std::vector<Patch> patches_;
  std::vector<Element> elements_;
  std::vector<QuadNode> nodes_;
  SideTable sides_;
  // Per face, for each cell of its uniform lattice (row-major, v-major): the element of the leaf
  // covering exactly that cell (or -1), else -(node + 2) for the node to descend from. A uniform
  // mesh finds an element in O(1).
  std::vector<int32_t> lattice_;
  // What FindElement reads of each face, packed: the faces themselves are too large to stay in
  // cache when a ray may hit any of a million.
  struct FaceLattice {
    int64_t offset;
    int32_t nu, nv;
    bool triangle;
  };
  std::vector<FaceLattice> face_lattice_;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_MESH_H_
