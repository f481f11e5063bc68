#include "solver/transport/formfactor.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include "absl/strings/str_cat.h"
#include "solver/geometry/box.h"
#include "solver/geometry/rect_sampler.h"
#include "solver/geometry/solution.h"
#include "solver/transport/area_to_polygon.h"
#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "solver/transport/sobol.h"

namespace radiosity {

double FormFactorRow::Sum() const {
  double s = 0;
  for (double x : f) s += x;
  return s;
}

namespace {

// Keeps a value in [0, 1) after sums of uniforms.
double Wrap01(double x) {
  x -= std::floor(x);
  return x < 1.0 ? x : 0x1.fffffffffffffp-1;
}

// Radical inverse of i in `base` (van der Corput; Halton 1960 uses one prime base per dimension).
double RadicalInverse(int base, uint64_t i) {
  const double inv = 1.0 / base;
  double f = inv, r = 0;
  while (i > 0) {
    r += static_cast<double>(i % base) * f;
    i /= base;
    f *= inv;
  }
  return r;
}

// The elements of a row's source, for area-uniform sampling by a measure-preserving map of the
// unit square: s picks an element by its share of the area, and its remainder and t place the
// point in it.
struct SourceSampler {
  std::vector<int> elements;
  std::vector<double> cumulative;  // Area of elements [0, k].
  double area = 0;

  SourceSampler(const Mesh& mesh, const FormFactorSource& source) {
    const auto& all = mesh.elements();
    for (int e = source.first_element; e < source.first_element + source.num_elements; ++e) {
      if (e < 0 || e >= static_cast<int>(all.size()) || all[e].area <= 0) continue;
      area += all[e].area;
      elements.push_back(e);
      cumulative.push_back(area);
    }
  }

  Vec3 Sample(const Mesh& mesh, double s, double t, int* element, int* half, int* face) const {
    const double x = s * area;
    size_t k = std::upper_bound(cumulative.begin(), cumulative.end(), x) - cumulative.begin();
    k = std::min(k, elements.size() - 1);
    const double lo = k == 0 ? 0.0 : cumulative[k - 1];
    const double a = cumulative[k] - lo;
    const double rem = a > 0 ? std::clamp((x - lo) / a, 0.0, 0x1.fffffffffffffp-1) : 0.0;
    *element = elements[k];
    return SampleElementArea(mesh, *element, rem, t, half, face);
  }
};

// Front normal of the source side at a sample on `half` of mesh face `face`.
Vec3 SideNormal(const Mesh& mesh, int face, int half, int side) {
  const Vec3& n = mesh.faces()[face].normal[half];
  return side == 0 ? n : -n;
}

// The element side a ray hit: the element from (face, u, v) and the side from the direction
// (Mesh::FindElement; a ray arriving against the normal of the hit half strikes the front).
int HitSlot(const Mesh& mesh, const Vec3& dir, const Hit& hit) {
  if (!hit.valid()) return -1;
  const int e = mesh.FindElement(hit.face, hit.u, hit.v);
  if (e < 0) return -1;
  const MeshFace& f = mesh.faces()[hit.face];
  return Slot(e, Dot(dir, f.normal[f.Half(hit.u, hit.v)]) < 0 ? 0 : 1);
}

// Counts of hit slots, with bounded memory: slots are buffered, and the buffer is sorted and
// merged into the sorted (slot, count) list whenever it fills.
class SlotCounter {
 public:
  void Add(int slot) {
    buffer_.push_back(slot);
    if (buffer_.size() >= kBuffer) Flush();
  }
  // Writes F = count / n for every slot, ascending.
  void Finish(double n, FormFactorRow* row) {
    Flush();
    row->slots.reserve(counts_.size());
    row->f.reserve(counts_.size());
    for (const auto& [slot, count] : counts_) {
      row->slots.push_back(slot);
      row->f.push_back(static_cast<double>(count) / n);
    }
  }

 private:
  static constexpr size_t kBuffer = size_t{1} << 20;
  void Flush() {
    if (buffer_.empty()) return;
    std::sort(buffer_.begin(), buffer_.end());
    std::vector<std::pair<int, int64_t>> runs;
    for (size_t i = 0; i < buffer_.size();) {
      size_t j = i;
      while (j < buffer_.size() && buffer_[j] == buffer_[i]) ++j;
      runs.push_back({buffer_[i], static_cast<int64_t>(j - i)});
      i = j;
    }
    buffer_.clear();
    std::vector<std::pair<int, int64_t>> merged;
    merged.reserve(runs.size() + counts_.size());
    size_t a = 0, b = 0;
    while (a < counts_.size() || b < runs.size()) {
      if (b == runs.size() || (a < counts_.size() && counts_[a].first < runs[b].first)) {
        merged.push_back(counts_[a++]);
      } else if (a == counts_.size() || runs[b].first < counts_[a].first) {
        merged.push_back(runs[b++]);
      } else {
        merged.push_back({counts_[a].first, counts_[a].second + runs[b].second});
        ++a;
        ++b;
      }
    }
    counts_ = std::move(merged);
  }
  std::vector<int> buffer_;
  std::vector<std::pair<int, int64_t>> counts_;
};

// Sums (slot, value) contributions into a row, in a fixed order (stable sort by slot), so the
// result does not depend on anything but the contributions' order.
void SumIntoRow(std::vector<std::pair<int, double>>* contributions, FormFactorRow* row) {
  std::stable_sort(contributions->begin(), contributions->end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  for (size_t i = 0; i < contributions->size();) {
    size_t j = i;
    double sum = 0;
    while (j < contributions->size() && (*contributions)[j].first == (*contributions)[i].first) {
      sum += (*contributions)[j].second;
      ++j;
    }
    if (sum > 0) {
      row->slots.push_back((*contributions)[i].first);
      row->f.push_back(sum);
    }
    i = j;
  }
}

// ---------------------------------------------------------------------------------------------
// Monte Carlo: cosine-distributed rays from area-uniform points (Shirley 6.2). F_j = hits_j / n.

class MonteCarloEstimator : public FormFactorEstimator {
 public:
  enum class Sampling { kSobol, kRandom, kStratified, kHalton };
  MonteCarloEstimator(const Mesh& mesh, const Visibility& vis, Sampling sampling)
      : mesh_(mesh), vis_(vis), sampling_(sampling) {}

  std::string name() const override { return "montecarlo"; }

  using FormFactorEstimator::Estimate;
  void Estimate(const FormFactorSource& source, int64_t budget, uint64_t stream,
                const StopToken& stop, FormFactorRow* row) const override {
    row->Clear();
    if (budget <= 0) return;
    SourceSampler sampler(mesh_, source);
    if (sampler.area <= 0) return;
    SlotCounter counter;
    Rng rng(stream);
    // The stop token is read every kStopCheck samples; once it stops, the loops below end.
    constexpr int64_t kStopCheck = 4096;
    int64_t traced = 0;
    bool stopped = false;
    // One sample: (d0, d1) the point (area-uniform over the source), (d2, d3) the direction.
    auto trace = [&](double d0, double d1, double d2, double d3) {
      if (++traced % kStopCheck == 0 && stop.ShouldStop()) stopped = true;
      int element = 0, half = 0, face = 0;
      Vec3 origin = sampler.Sample(mesh_, d0, d1, &element, &half, &face);
      Vec3 dir = CosineDirection(SideNormal(mesh_, face, half, source.side), d2, d3);
      // The source face is skipped (a planar face cannot see itself), as in the progressive
      // solver, so rays start exactly on the surface.
      Hit hit = vis_.Intersect(origin, dir, 0, 1e30, face);
      int slot = HitSlot(mesh_, dir, hit);
      if (slot >= 0) counter.Add(slot);
    };
    switch (sampling_) {
      case Sampling::kSobol: {
        // Owen-scrambled Sobol' points (sobol.h), one scramble per row: (0, 1) the point, (2, 3)
        // the direction. Indices are 32-bit: a larger budget continues with random points.
        const OwenSobol seq(stream);
        for (int64_t i = 0; i < budget && !stopped; ++i) {
          if (i >= (int64_t{1} << 32)) {
            trace(rng.Uniform(), rng.Uniform(), rng.Uniform(), rng.Uniform());
            continue;
          }
          const uint32_t k = static_cast<uint32_t>(i);
          trace(seq.Get(k, 0), seq.Get(k, 1), seq.Get(k, 2), seq.Get(k, 3));
        }
        break;
      }
      case Sampling::kRandom:
        for (int64_t i = 0; i < budget && !stopped; ++i) {
          double d0 = rng.Uniform(), d1 = rng.Uniform();
          double d2 = rng.Uniform(), d3 = rng.Uniform();
          trace(d0, d1, d2, d3);
        }
        break;
      case Sampling::kStratified: {
        // Jittered strata of the 4D (point, direction) sample space: a k x k x k x k grid with
        // one jittered sample per cell (the largest k with k^4 <= n), repeated while whole grids
        // fit, and the remaining samples in distinct cells chosen at random (still unbiased).
        // Blocks bound the memory of that choice.
        constexpr int64_t kBlock = int64_t{1} << 22;
        std::vector<uint32_t> cells;
        for (int64_t begin = 0; begin < budget && !stopped; begin += kBlock) {
          const int64_t m = std::min(kBlock, budget - begin);
          int64_t k = std::max<int64_t>(1, static_cast<int64_t>(std::pow(m, 0.25)));
          while ((k + 1) * (k + 1) * (k + 1) * (k + 1) <= m) ++k;
          while (k > 1 && k * k * k * k > m) --k;
          const int64_t grid = k * k * k * k;
          const double inv = 1.0 / static_cast<double>(k);
          auto jittered = [&](int64_t cell) {
            const int64_t i0 = cell % k, i1 = (cell / k) % k, i2 = (cell / (k * k)) % k,
                          i3 = cell / (k * k * k);
            double d0 = (i0 + rng.Uniform()) * inv, d1 = (i1 + rng.Uniform()) * inv;
            double d2 = (i2 + rng.Uniform()) * inv, d3 = (i3 + rng.Uniform()) * inv;
            trace(d0, d1, d2, d3);
          };
          const int64_t full = m / grid, rest = m % grid;
          for (int64_t g = 0; g < full && !stopped; ++g) {
            for (int64_t c = 0; c < grid && !stopped; ++c) jittered(c);
          }
          if (rest > 0 && !stopped) {
            // A partial Fisher-Yates shuffle picks `rest` distinct cells.
            cells.resize(static_cast<size_t>(grid));
            for (int64_t c = 0; c < grid; ++c) cells[c] = static_cast<uint32_t>(c);
            for (int64_t c = 0; c < rest && !stopped; ++c) {
              int64_t j = c + std::min<int64_t>(grid - c - 1,
                                                static_cast<int64_t>(rng.Uniform() * (grid - c)));
              std::swap(cells[c], cells[j]);
              jittered(cells[c]);
            }
          }
        }
        break;
      }
      case Sampling::kHalton: {
        // Halton points (bases 2, 3, 5, 7: point, then direction), randomised by a
        // Cranley-Patterson rotation: a random shift modulo 1 per dimension, per row.
        double shift[4];
        for (double& x : shift) x = rng.Uniform();
        for (int64_t i = 0; i < budget && !stopped; ++i) {
          const uint64_t k = static_cast<uint64_t>(i);
          trace(Wrap01(RadicalInverse(2, k) + shift[0]), Wrap01(RadicalInverse(3, k) + shift[1]),
                Wrap01(RadicalInverse(5, k) + shift[2]), Wrap01(RadicalInverse(7, k) + shift[3]));
        }
        break;
      }
    }
    if (stopped) {
      row->Clear();
      return;
    }
    counter.Finish(static_cast<double>(budget), row);
    row->rays = budget;
  }

 private:
  const Mesh& mesh_;
  const Visibility& vis_;
  Sampling sampling_;
};

// ---------------------------------------------------------------------------------------------
// Source polygons in space (mesh coordinates), each with the normal of the source side.

// The source as polygons: a whole patch as its rectangle (one Lambert evaluation instead of one
// per element), otherwise each element's pieces.
std::vector<SpacePolygon> SourcePolygons(const Mesh& mesh, const FormFactorSource& source) {
  std::vector<SpacePolygon> out;
  const auto& elements = mesh.elements();
  if (source.num_elements <= 0 || source.first_element < 0 ||
      source.first_element + source.num_elements > static_cast<int>(elements.size())) {
    return out;
  }
  const Patch& patch = mesh.patches()[elements[source.first_element].patch];
  if (source.num_elements > 1 && patch.first_element == source.first_element &&
      patch.num_elements == source.num_elements) {
    const QuadNode& root = mesh.nodes()[patch.root];
    FacePolygons(mesh.faces()[patch.face], root.u0, root.v0, root.u1, root.v1, source.side, &out);
    return out;
  }
  for (int e = source.first_element; e < source.first_element + source.num_elements; ++e) {
    ElementPolygons(mesh, e, source.side, &out);
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Analytic: exact point-to-polygon factors from stratified points of each receiver, visibility
// by shadow rays, and reciprocity (Shirley 6.3; Wallace et al. 1989 shoot the same way).

// The analytic factors from a source (its sampler, polygons and side) to both sides of receiver
// element j: the unoccluded factor F_j->src integrated over the receiver to a stated tolerance
// (area_to_polygon.h: exact also beside a shared edge, where the kernel is singular and sample
// points miss most of the integral), times a kernel-weighted visible fraction from shadow rays
// between `points` stratified points of the receiver and `shadow_rays` of the source, then by
// reciprocity, A_src F_src->j = A_j F_j->src (Shirley eq. 6.4). f[side] = 0 where nothing is
// seen; false when the receiver is not in front of the source or sees none of it.
struct AnalyticPairs {
  const Mesh& mesh;
  const Visibility& vis;
  const SourceSampler& sampler;
  const std::vector<SpacePolygon>& polygons;
  int source_side;
  int points, shadow_rays;

  bool Factors(int j, uint64_t stream, double f[2], int64_t* rays) const {
    f[0] = f[1] = 0;
    const Element& rec = mesh.elements()[j];
    const auto& faces = mesh.faces();
    const double eps = vis.epsilon();
    // Whole-element rejection: the receiver must have a point in front of the source side, and
    // the source a point in front of one of the receiver's sides.
    std::vector<SpacePolygon> rec_polys;
    ElementPolygons(mesh, j, kFront, &rec_polys);
    bool receiver_in_front = false;
    bool side_sees[2] = {false, false};
    for (const SpacePolygon& sp : polygons) {
      for (const SpacePolygon& rp : rec_polys) {
        for (int k = 0; k < rp.n; ++k) {
          if (Dot(rp.v[k] - sp.v[0], sp.normal) > eps) receiver_in_front = true;
        }
        for (int k = 0; k < sp.n; ++k) {
          double d = Dot(sp.v[k] - rp.v[0], rp.normal);
          if (d > eps) side_sees[0] = true;
          if (d < -eps) side_sees[1] = true;
        }
      }
    }
    if (!receiver_in_front || !(side_sees[0] || side_sees[1])) return false;
    QuadratureOptions quadrature;
    quadrature.relative = 1e-5;
    quadrature.absolute = 1e-10;
    quadrature.far_ratio = 4;
    // A row has one pair per element: a budget per pair keeps a row's cost bounded where
    // receivers nearly touch the source along their whole length (a light under a ceiling).
    quadrature.max_evaluations = 50000;
    double unoccluded[2] = {0, 0};
    for (const SpacePolygon& sp : polygons) {
      const AreaFormFactor a = AreaToPolygon(rec_polys, rec.area, sp, quadrature);
      unoccluded[0] += side_sees[0] ? a.front : 0.0;
      unoccluded[1] += side_sees[1] ? a.back : 0.0;
    }
    if (!(unoccluded[0] > 0) && !(unoccluded[1] > 0)) return false;
    // The visible fraction of each side, weighted by the kernel: V = sum w v / sum w
    // (correlated: 1 where nothing blocks).
    Rng rng(StreamKey(stream, static_cast<uint64_t>(j)));
    std::vector<Vec3> targets(static_cast<size_t>(shadow_rays));
    std::vector<int> target_face(static_cast<size_t>(shadow_rays));
    std::vector<Vec3> target_normal(static_cast<size_t>(shadow_rays));
    double seen_w[2] = {0, 0}, all_w[2] = {0, 0};
    for (int p = 0; p < points; ++p) {
      Stratum cell = StratumCell(points, p);
      int half = 0, y_face = 0;
      const Vec3 y = SampleElementArea(mesh, j, cell.u0 + cell.du * rng.Uniform(),
                                       cell.v0 + cell.dv * rng.Uniform(), &half, &y_face);
      const Vec3 ny = faces[y_face].normal[half];
      for (int s = 0; s < shadow_rays; ++s) {
        Stratum c = StratumCell(shadow_rays, s);
        int th = 0, te = 0;
        targets[s] = sampler.Sample(mesh, c.u0 + c.du * rng.Uniform(), c.v0 + c.dv * rng.Uniform(),
                                    &te, &th, &target_face[s]);
        target_normal[s] = SideNormal(mesh, target_face[s], th, source_side);
      }
      for (int s = 0; s < shadow_rays; ++s) {
        const Vec3 d = targets[s] - y;
        const double r2 = Dot(d, d);
        const double cx = -Dot(d, target_normal[s]);
        if (!(r2 > 0) || !(cx > 0)) continue;
        double w[2];
        for (int side = 0; side < 2; ++side) {
          const double cy = Dot(d, side == 0 ? ny : -ny);
          w[side] = unoccluded[side] > 0 && cy > 0 ? cy * cx / (r2 * r2) : 0.0;
        }
        if (!(w[0] > 0) && !(w[1] > 0)) continue;
        const bool visible = SegmentVisible(vis, y, y_face, targets[s], target_face[s],
                                            cx / std::sqrt(r2), rays);
        for (int side = 0; side < 2; ++side) {
          all_w[side] += w[side];
          if (visible) seen_w[side] += w[side];
        }
      }
    }
    for (int side = 0; side < 2; ++side) {
      const double v = all_w[side] > 0 ? seen_w[side] / all_w[side] : 1.0;
      f[side] = rec.area / sampler.area * unoccluded[side] * v;
    }
    return true;
  }
};

// The faces of a source's elements, sorted (a planar face does not see itself).
std::vector<int> SourceFaces(const Mesh& mesh, const SourceSampler& sampler) {
  std::vector<int> faces;
  for (int e : sampler.elements) faces.push_back(mesh.elements()[e].face);
  std::sort(faces.begin(), faces.end());
  faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
  return faces;
}

class AnalyticEstimator : public FormFactorEstimator {
 public:
  AnalyticEstimator(const Mesh& mesh, const Visibility& vis, int points, int shadow_rays)
      : mesh_(mesh), vis_(vis), points_(points), shadow_rays_(shadow_rays) {}

  std::string name() const override { return "analytic"; }

  using FormFactorEstimator::Estimate;
  void Estimate(const FormFactorSource& source, int64_t /*budget*/, uint64_t stream,
                const StopToken& stop, FormFactorRow* row) const override {
    row->Clear();
    SourceSampler sampler(mesh_, source);
    if (sampler.area <= 0) return;
    const std::vector<SpacePolygon> polygons = SourcePolygons(mesh_, source);
    const AnalyticPairs pairs{mesh_, vis_, sampler, polygons, source.side, points_, shadow_rays_};
    const std::vector<int> source_faces = SourceFaces(mesh_, sampler);
    const auto& elements = mesh_.elements();
    int64_t rays = 0;
    for (int j = 0; j < static_cast<int>(elements.size()); ++j) {
      if (stop.ShouldStop()) {
        row->Clear();
        return;
      }
      if (elements[j].area <= 0 ||
          std::binary_search(source_faces.begin(), source_faces.end(), elements[j].face)) {
        continue;
      }
      double f[2];
      if (!pairs.Factors(j, stream, f, &rays)) continue;
      for (int side = 0; side < 2; ++side) {
        if (f[side] > 0) {
          row->slots.push_back(Slot(j, side));
          row->f.push_back(f[side]);
        }
      }
    }
    row->rays = rays;
  }

 private:
  const Mesh& mesh_;
  const Visibility& vis_;
  int points_;
  int shadow_rays_;
};

// ---------------------------------------------------------------------------------------------
// Hemicube (Cohen & Greenberg 1985): a unit half-cube over the point, each cell's delta form
// factor given to the element seen through the cell's centre; here the "item buffer" is a ray
// per cell.

class HemicubeEstimator : public FormFactorEstimator {
 public:
  HemicubeEstimator(const Mesh& mesh, const Visibility& vis, int resolution, int points,
                    int analytic_points, int shadow_rays)
      : mesh_(mesh),
        vis_(vis),
        points_(points),
        analytic_points_(analytic_points),
        shadow_rays_(shadow_rays),
        deltas_(ComputeHemicubeDeltas(resolution, /*exact=*/true)) {
    // Each element's bounding box, for the near-field test of every row.
    boxes_.resize(mesh.elements().size());
    std::vector<SpacePolygon> polys;
    for (int e = 0; e < static_cast<int>(boxes_.size()); ++e) {
      polys.clear();
      ElementPolygons(mesh, e, kFront, &polys);
      for (const SpacePolygon& p : polys) {
        for (int k = 0; k < p.n; ++k) boxes_[e].Add(p.v[k]);
      }
    }
  }

  std::string name() const override { return "hemicube"; }

  using FormFactorEstimator::Estimate;
  void Estimate(const FormFactorSource& source, int64_t /*budget*/, uint64_t stream,
                const StopToken& stop, FormFactorRow* row) const override {
    row->Clear();
    SourceSampler sampler(mesh_, source);
    if (sampler.area <= 0) return;
    const int res = deltas_.resolution, half_res = res / 2;
    const double cell = 2.0 / res;
    Rng rng(stream);
    std::vector<std::pair<int, double>> hits;
    hits.reserve(static_cast<size_t>(3) * res * res);
    const double weight = 1.0 / points_;
    for (int p = 0; p < points_; ++p) {
      if (stop.ShouldStop()) {
        row->Clear();
        return;
      }
      Stratum c = StratumCell(points_, p);
      int element = 0, half = 0, ignore = 0;
      const Vec3 origin = sampler.Sample(mesh_, c.u0 + c.du * rng.Uniform(),
                                         c.v0 + c.dv * rng.Uniform(), &element, &half, &ignore);
      const Vec3 n = SideNormal(mesh_, ignore, half, source.side);
      // The hemicube's frame, rotated by a random angle about the normal so that its aliasing
      // differs from shot to shot instead of repeating.
      Vec3 t0, b0;
      OrthonormalBasis(n, &t0, &b0);
      const double angle = 2 * kPi * rng.Uniform();
      const Vec3 t = t0 * std::cos(angle) + b0 * std::sin(angle);
      const Vec3 b = b0 * std::cos(angle) - t0 * std::sin(angle);
      auto shoot = [&](const Vec3& dir, double df) {
        Hit hit = vis_.Intersect(origin, dir, 0, 1e30, ignore);
        int slot = HitSlot(mesh_, dir, hit);
        if (slot >= 0) hits.push_back({slot, df * weight});
      };
      for (int iy = 0; iy < res; ++iy) {
        const double y = -1 + (iy + 0.5) * cell;
        for (int ix = 0; ix < res; ++ix) {
          const double x = -1 + (ix + 0.5) * cell;
          shoot(t * x + b * y + n, deltas_.top[static_cast<size_t>(iy) * res + ix]);
        }
      }
      // The four sides: outward axis a, across axis c (a x c = n keeps them alike), height n.
      const Vec3 axes[4][2] = {{t, b}, {b, -t}, {-t, -b}, {-b, t}};
      for (const auto& ax : axes) {
        for (int iz = 0; iz < half_res; ++iz) {
          const double z = (iz + 0.5) * cell;
          for (int is = 0; is < res; ++is) {
            const double s = -1 + (is + 0.5) * cell;
            shoot(ax[0] + ax[1] * s + n * z, deltas_.side[static_cast<size_t>(iz) * res + is]);
          }
        }
      }
    }
    SumIntoRow(&hits, row);
    row->rays = static_cast<int64_t>(points_) * 3 * res * res;
    CorrectNearField(source, sampler, stream, stop, row);
  }

 private:
  // Receivers closer to the source than kNearField times its diameter (its bounding boxes')
  // get the analytic factor instead of the hemicube's.
  static constexpr double kNearField = 3;

  // Near the source the hemicube's assumptions fail (Baum, Rushmeier & Winget 1989): the whole
  // source is not seen from one point, and a receiver beside it (a shared edge) subtends a
  // large, steeply varying solid angle that a few cells alias. Their entries are replaced by
  // the analytic factors (AnalyticPairs); where the source is enclosed, the rest of the row,
  // where the point assumption holds, is scaled so that the row keeps the hemicube's total of 1:
  // the far receivers get what the near ones do not take.
  void CorrectNearField(const FormFactorSource& source, const SourceSampler& sampler,
                        uint64_t stream, const StopToken& stop, FormFactorRow* row) const {
    Box src;
    for (int e : sampler.elements) src.Add(boxes_[e]);
    const double reach = kNearField * Length(src.hi - src.lo);
    const std::vector<SpacePolygon> polygons = SourcePolygons(mesh_, source);
    const AnalyticPairs pairs{mesh_, vis_,          sampler,     polygons,
                              source.side, analytic_points_, shadow_rays_};
    const std::vector<int> source_faces = SourceFaces(mesh_, sampler);
    // The receivers within reach, the nearest first, at most as many slots as the hemicube has
    // cells (so a row holds at most twice that: MatrixSolver's bound).
    std::vector<std::pair<double, int>> within;
    for (int j = 0; j < static_cast<int>(boxes_.size()); ++j) {
      if ((j & 255) == 0 && stop.ShouldStop()) return;  // The caller discards the row.
      const double d = boxes_[j].Distance(src);
      if (!(mesh_.elements()[j].area > 0) || d > reach ||
          std::binary_search(source_faces.begin(), source_faces.end(), mesh_.elements()[j].face)) {
        continue;
      }
      within.push_back({d, j});
    }
    const size_t cap = static_cast<size_t>(points_) * 3 * deltas_.resolution * deltas_.resolution / 2;
    if (within.size() > cap) {
      std::nth_element(within.begin(), within.begin() + cap, within.end());
      within.resize(cap);
    }
    std::sort(within.begin(), within.end(),
              [](const auto& a, const auto& b) { return a.second < b.second; });
    std::vector<std::pair<int, double>> near;  // (slot, analytic factor), in slot order.
    int64_t rays = 0;
    for (const auto& [d, j] : within) {
      if (stop.ShouldStop()) return;
      double f[2];
      near.push_back({Slot(j, 0), 0.0});
      near.push_back({Slot(j, 1), 0.0});
      if (pairs.Factors(j, StreamKey(stream, 0x6e656172 /* "near" */), f, &rays)) {
        near[near.size() - 2].second = f[0];
        near.back().second = f[1];
      }
    }
    if (near.empty()) return;
    // near is in slot order, as the row is.
    double total = 0, near_hemicube = 0, near_analytic = 0;
    for (double f : row->f) total += f;
    for (const auto& [slot, f] : near) near_analytic += f;
    std::vector<std::pair<int, double>> merged;
    size_t k = 0;
    for (size_t i = 0; i < row->slots.size(); ++i) {
      while (k < near.size() && near[k].first < row->slots[i]) ++k;
      if (k < near.size() && near[k].first == row->slots[i]) {
        near_hemicube += row->f[i];
      } else {
        merged.push_back({row->slots[i], row->f[i]});
      }
    }
    // Where every cell met a surface (the source is enclosed), the row keeps the hemicube's
    // total, 1: the far part scaled, or where every receiver is near (or the analytic factors
    // take it all), the near part. Elsewhere the hemicube's total is its centre's, which the
    // near field also distorts: the far part stays as it is, and the row is kept below 1.
    const double far = total - near_hemicube;
    const bool enclosed = total >= 1 - 1e-6;
    const bool far_takes = far > 0 && total - near_analytic > 0;
    double far_scale = enclosed && far_takes ? (total - near_analytic) / far : 1.0;
    double near_scale = enclosed && !far_takes && near_analytic > 0 ? (total - far) / near_analytic : 1.0;
    const double sum = far * far_scale + near_analytic * near_scale;
    if (sum > 1) {
      far_scale /= sum;
      near_scale /= sum;
    }
    for (auto& m : merged) m.second *= far_scale;
    for (const auto& n : near) {
      if (n.second > 0) merged.push_back({n.first, n.second * near_scale});
    }
    row->slots.clear();
    row->f.clear();
    SumIntoRow(&merged, row);
    row->rays += rays;
  }

  const Mesh& mesh_;
  const Visibility& vis_;
  int points_;
  int analytic_points_, shadow_rays_;
  HemicubeDeltas deltas_;
  std::vector<Box> boxes_;  // Per element.
};

// Sutherland-Hodgman clip of a polygon against dot(x - p, n) >= 0. Writes at most count + 1
// vertices; returns the count (0 when nothing is in front).
int ClipToHalfSpace(const Vec3& p, const Vec3& n, const Vec3* in, int count, Vec3* out) {
  int m = 0;
  for (int k = 0; k < count; ++k) {
    const Vec3& a = in[k];
    const Vec3& b = in[(k + 1) % count];
    double da = Dot(a - p, n), db = Dot(b - p, n);
    if (da >= 0) out[m++] = a;
    if ((da > 0 && db < 0) || (da < 0 && db > 0)) {
      double t = da / (da - db);
      out[m++] = a + (b - a) * t;
    }
  }
  return m;
}

}  // namespace

double PointToPolygonFormFactor(const Vec3& p, const Vec3& n, const Vec3* polygon, int count) {
  // Lambert's contour formula (Howell B-3; Baum, Rushmeier & Winget 1989 eq. 1):
  //   F = 1/(2 pi) | sum_k gamma_k n . (R_k x R_k+1) / |R_k x R_k+1| |, gamma_k = angle(R_k, R_k+1)
  double sum = 0;
  for (int k = 0; k < count; ++k) {
    const Vec3 a = polygon[k] - p;
    const Vec3 b = polygon[(k + 1) % count] - p;
    const Vec3 c = Cross(a, b);
    const double len = Length(c);
    if (len <= 0) continue;  // An edge through p, or a repeated vertex: no contribution.
    const double gamma = std::atan2(len, Dot(a, b));
    sum += gamma * Dot(n, c) / len;
  }
  return std::fabs(sum) / (2 * kPi);
}

bool SegmentVisible(const Visibility& visibility, const Vec3& a, int face_a, const Vec3& b,
                    int face_b, double cos_b, int64_t* rays) {
  const Vec3 d = b - a;
  const double len = Length(d);
  if (len <= 0) return true;
  // Embree's hit distance on b's plane is off by about (float rounding) / cos_b; epsilon() is ten
  // times that rounding.
  const double margin = 4 * visibility.epsilon() / (len * std::max(cos_b, 1e-300));
  if (margin < 0.25) {
    ++*rays;
    return !visibility.Occluded(a, d, 0, 1 - margin, face_a);
  }
  *rays += 2;
  return !visibility.Occluded(a, d, 0, 0.5, face_a) && !visibility.Occluded(b, -d, 0, 0.5, face_b);
}

double PointToPolygonFormFactorClipped(const Vec3& p, const Vec3& n, const Vec3* polygon,
                                       int count) {
  if (count < 3) return 0;
  constexpr int kStack = 31;
  Vec3 stack[kStack + 1];
  std::vector<Vec3> heap;
  Vec3* out = stack;
  if (count > kStack) {
    heap.resize(static_cast<size_t>(count) + 1);
    out = heap.data();
  }
  const int m = ClipToHalfSpace(p, n, polygon, count, out);
  return m >= 3 ? PointToPolygonFormFactor(p, n, out, m) : 0.0;
}

double HemicubeDeltas::Sum() const {
  double s = 0, side_sum = 0;
  for (double x : top) s += x;
  for (double x : side) side_sum += x;
  return s + 4 * side_sum;
}

HemicubeDeltas ComputeHemicubeDeltas(int resolution, bool exact) {
  HemicubeDeltas d;
  if (resolution < 2 || resolution % 2 != 0) return d;
  d.resolution = resolution;
  const int half = resolution / 2;
  const double h = 2.0 / resolution, da = h * h;
  const Vec3 origin, z_axis{0, 0, 1};
  d.top.resize(static_cast<size_t>(resolution) * resolution);
  d.side.resize(static_cast<size_t>(half) * resolution);
  for (int iy = 0; iy < resolution; ++iy) {
    const double y0 = -1 + iy * h, y1 = y0 + h, y = y0 + 0.5 * h;
    for (int ix = 0; ix < resolution; ++ix) {
      const double x0 = -1 + ix * h, x1 = x0 + h, x = x0 + 0.5 * h;
      double v;
      if (exact) {
        const Vec3 cell[4] = {{x0, y0, 1}, {x1, y0, 1}, {x1, y1, 1}, {x0, y1, 1}};
        v = PointToPolygonFormFactor(origin, z_axis, cell, 4);
      } else {
        // Cohen & Greenberg 1985: dF = dA / (pi (x^2 + y^2 + 1)^2) on the top face.
        const double r = x * x + y * y + 1;
        v = da / (kPi * r * r);
      }
      d.top[static_cast<size_t>(iy) * resolution + ix] = v;
    }
  }
  for (int iz = 0; iz < half; ++iz) {
    const double z0 = iz * h, z1 = z0 + h, z = z0 + 0.5 * h;
    for (int is = 0; is < resolution; ++is) {
      const double s0 = -1 + is * h, s1 = s0 + h, s = s0 + 0.5 * h;
      double v;
      if (exact) {
        const Vec3 cell[4] = {{1, s0, z0}, {1, s1, z0}, {1, s1, z1}, {1, s0, z1}};
        v = PointToPolygonFormFactor(origin, z_axis, cell, 4);
      } else {
        // Sides: dF = z dA / (pi (y^2 + z^2 + 1)^2).
        const double r = s * s + z * z + 1;
        v = z * da / (kPi * r * r);
      }
      d.side[static_cast<size_t>(iz) * resolution + is] = v;
    }
  }
  return d;
}

const std::vector<EstimatorInfo>& FormFactorEstimators() {
  static const auto* estimators = new std::vector<EstimatorInfo>{
      {"montecarlo",
       "cosine-distributed rays from the source, F_j = hits_j / rays (Shirley 6.2)",
       {"formfactor.sampling", "rays_per_element"}},
      {"analytic",
       "Lambert's exact point-to-polygon factor at stratified receiver points, shadow rays for "
       "visibility, reciprocity (Shirley 6.3)",
       {"formfactor.analytic_points", "formfactor.shadow_rays"}},
      {"hemicube",
       "delta form factors of hemicube cells, a ray per cell (Cohen & Greenberg 1985)",
       {"formfactor.hemicube_resolution", "formfactor.hemicube_points"}},
  };
  return *estimators;
}

const EstimatorInfo* FindEstimator(const std::string& name) {
  for (const EstimatorInfo& e : FormFactorEstimators()) {
    if (e.name == name) return &e;
  }
  return nullptr;
}

absl::StatusOr<std::unique_ptr<FormFactorEstimator>> CreateFormFactorEstimator(
    const Mesh& mesh, const Visibility& visibility, const FormFactorOptions& options) {
  auto out_of = [](const char* what, double value, const Bounds& bounds) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, " must be in ", bounds.text, ", got ", value));
  };
  if (options.method == "montecarlo") {
    MonteCarloEstimator::Sampling sampling;
    if (options.sampling == "sobol") {
      sampling = MonteCarloEstimator::Sampling::kSobol;
    } else if (options.sampling == "random") {
      sampling = MonteCarloEstimator::Sampling::kRandom;
    } else if (options.sampling == "stratified") {
      sampling = MonteCarloEstimator::Sampling::kStratified;
    } else if (options.sampling == "halton") {
      sampling = MonteCarloEstimator::Sampling::kHalton;
    } else {
      return absl::InvalidArgumentError(
          absl::StrCat("unknown sampling '", options.sampling,
                       "' (expected sobol, random, stratified or halton)"));
    }
    return std::make_unique<MonteCarloEstimator>(mesh, visibility, sampling);
  }
  if (options.method == "analytic") {
    if (!kAnalyticPointsBounds.Contains(options.analytic_points)) {
      return out_of("analytic points", options.analytic_points, kAnalyticPointsBounds);
    }
    if (!kShadowRaysBounds.Contains(options.shadow_rays)) {
      return out_of("shadow rays", options.shadow_rays, kShadowRaysBounds);
    }
    return std::make_unique<AnalyticEstimator>(mesh, visibility, options.analytic_points,
                                               options.shadow_rays);
  }
  if (options.method == "hemicube") {
    if (!kHemicubeResolutionBounds.Contains(options.hemicube_resolution) ||
        options.hemicube_resolution % 2 != 0) {
      return absl::InvalidArgumentError(absl::StrCat("hemicube resolution must be even and in ",
                                                     kHemicubeResolutionBounds.text, ", got ",
                                                     options.hemicube_resolution));
    }
    if (!kHemicubePointsBounds.Contains(options.hemicube_points)) {
      return out_of("hemicube points", options.hemicube_points, kHemicubePointsBounds);
    }
    return std::make_unique<HemicubeEstimator>(mesh, visibility, options.hemicube_resolution,
                                               options.hemicube_points, options.analytic_points,
                                               options.shadow_rays);
  }
  return absl::InvalidArgumentError(absl::StrCat("unknown form-factor method '", options.method,
                                                 "' (expected montecarlo, analytic or hemicube)"));
}

}  // namespace radiosity
