#include "solver/transport/direct_irradiance.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>

#include "absl/strings/str_format.h"
#include "solver/geometry/rect_sampler.h"
#include "solver/transport/formfactor.h"
#include "solver/transport/rng.h"
#include "solver/transport/sobol.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace radiosity {

namespace {

// Shadow-ray samples of one receiver-emitter pair, for the ratio estimator of the visible
// fraction (see the header) of one receiver side. Sample j belongs to replicate j % replicates,
// an independently scrambled sequence. With several replicates the standard error is the spread
// of their ratios (randomised quasi-Monte Carlo: honest for the scrambled points); with one, the
// independent-sampling formula of the header (an upper bound for them, often several times too
// large, but every sample then comes from one sequence, the most accurate estimate).
class VisibleFraction {
 public:
  static constexpr int kMaxReplicates = 16;
  explicit VisibleFraction(int replicates) : replicates_(replicates) {}

  void Add(double w, bool visible, int replicate) {
    sum_w_ += w;
    if (visible) sum_wv_ += w;
    w_[replicate] += w;
    if (visible) wv_[replicate] += w;
    if (replicates_ == 1) {
      samples_w_.push_back(w);
      samples_v_.push_back(visible);
    }
  }
  bool empty() const { return !(sum_w_ > 0); }
  // Some rays arrived and some did not.
  bool Mixed() const { return sum_wv_ > 0 && sum_wv_ < sum_w_; }
  // With no ray of positive kernel, nothing is known to block: 1.
  double Value() const { return sum_w_ > 0 ? sum_wv_ / sum_w_ : 1.0; }
  double StdError() const {
    if (!Mixed()) return 0;
    const double v = Value();
    double s = 0;
    if (replicates_ == 1) {
      // Cochran (1977) 6.3: sqrt(sum_k w_k^2 (v_k - V)^2) / sum_k w_k.
      for (size_t k = 0; k < samples_w_.size(); ++k) {
        const double d = samples_w_[k] * ((samples_v_[k] ? 1.0 : 0.0) - v);
        s += d * d;
      }
      return std::sqrt(s) / sum_w_;
    }
    int count = 0;
    for (int r = 0; r < replicates_; ++r) {
      if (!(w_[r] > 0)) continue;
      const double d = wv_[r] / w_[r] - v;
      s += d * d;
      ++count;
    }
    // Fewer than two replicates saw the emitter: as uncertain as a fraction can be.
    if (count < 2) return 0.5;
    return std::sqrt(s / (count * (count - 1.0)));
  }
  void Clear() { *this = VisibleFraction(replicates_); }

 private:
  int replicates_;
  double sum_w_ = 0, sum_wv_ = 0;
  double w_[kMaxReplicates] = {}, wv_[kMaxReplicates] = {};
  std::vector<double> samples_w_;
  std::vector<bool> samples_v_;
};

// The replicates' sequences of one pair.
struct Replicates {
  Replicates(uint64_t key, int replicates) : count(replicates) {
    for (int r = 0; r < count; ++r) seq.emplace_back(StreamKey(key, static_cast<uint64_t>(r)));
  }
  // Coordinate `dim` of sample j.
  double Get(int j, int dim) const {
    return seq[static_cast<size_t>(j % count)].Get(static_cast<uint32_t>(j / count), dim);
  }
  // Coordinates 0-3 of sample j (the index scrambled once).
  void GetPoint(int j, double out[4]) const {
    seq[static_cast<size_t>(j % count)].GetPoint(static_cast<uint32_t>(j / count), 0, 4, out);
  }
  int count;
  std::vector<OwenSobol> seq;
};

// Deep penumbrae: see ForElement.
constexpr int kDeepFactor = 16;
constexpr double kDeepRelative = 0.1;

// The point y of em's real face, of normal ny there, as a receiver sees it: itself, or (an image)
// its reflection in em's mirror. False for a point of an image's emitter behind the mirror's
// plane, which has no image (BuildMirrorImages clipped it away): the sample is not the image's.
bool Apparent(const DirectEmitter& em, Vec3* y, Vec3* ny) {
  if (em.via < 0) return true;
  const double d = Dot(*y - em.plane_point, em.plane_normal);
  if (!(d > 0)) return false;
  *y = *y - em.plane_normal * (2 * d);
  *ny = *ny - em.plane_normal * (2 * Dot(*ny, em.plane_normal));
  return true;
}

// Whether the light of em's point real_y reaches x (on mesh face x_face, or -1 for a free point)
// along the path by which x sees it at seen_y: straight, or by way of em's mirror plane (its
// index in `plane_of`, the mirror plane of each face slot or -1), a face of which the ray
// towards the image must meet first, on its reflecting side, before the real point is in sight.
bool PathVisible(const Visibility& visibility, const std::vector<int>& plane_of, const Vec3& x,
                 int x_face, const DirectEmitter& em, const Vec3& real_y, const Vec3& seen_y,
                 double cos_y, int64_t* rays) {
  if (em.via < 0) return SegmentVisible(visibility, x, x_face, real_y, em.face, cos_y, rays);
  const Vec3 d = seen_y - x;
  const double r = Length(d);
  if (!(r > 0)) return false;
  const Vec3 dir = d / r;
  const Hit hit = visibility.Intersect(x, dir, 0, r, x_face);
  ++*rays;
  if (!hit.valid() || plane_of[Slot(hit.face, hit.StrikesFront(dir) ? kFront : kBack)] != em.via) {
    return false;
  }
  const Vec3 m = x + dir * static_cast<double>(hit.t);
  return SegmentVisible(visibility, m, hit.face, real_y, em.face, cos_y, rays);
}

bool CornersDisagree(const Mesh& mesh, const Visibility& visibility,
                     const std::vector<int>& plane_of, int element, const RectSampler& target,
                     const DirectEmitter& em, const Replicates& seq, int index, bool all_visible,
                     int64_t* rays) {
  // Every ray so far arrived, or none did: a thin strip of the element that the stratified points
  // missed (the uncovered edge of an element a block rests on, a shadow edge along its border)
  // shows at one of its corners, which the strata never reach. Each corner, inset by 1e-3 of the
  // element, tests one emitter point; they only decide whether to trace more, and enter no
  // estimate.
  const Element& el = mesh.elements()[element];
  const MeshFace& face = mesh.faces()[el.face];
  const auto& faces = mesh.faces();
  constexpr double kInset = 1e-3;
  for (int c = 0; c < 4; ++c) {
    const double u = (c & 1) ? el.u1 - kInset * (el.u1 - el.u0) : el.u0 + kInset * (el.u1 - el.u0);
    const double v = (c & 2) ? el.v1 - kInset * (el.v1 - el.v0) : el.v0 + kInset * (el.v1 - el.v0);
    if (face.triangle && u + v >= 1) continue;
    const Vec3 x = face.Eval(u, v);
    int hy = 0;
    const Vec3 real_y = target.Sample(seq.Get(index + c, 2), seq.Get(index + c, 3), &hy);
    Vec3 y = real_y;
    Vec3 ny = em.side == kFront ? faces[em.face].normal[hy] : -faces[em.face].normal[hy];
    if (!Apparent(em, &y, &ny)) continue;
    const Vec3 d = y - x;
    const double r = Length(d);
    if (!(r > 0)) continue;
    const double cos_y = -Dot(d, ny) / r;
    const double cos_x = Dot(d, face.normal[face.Half(u, v)]) / r;
    if (!(cos_y > 0) || std::fabs(cos_x) < 1e-9) continue;
    if (PathVisible(visibility, plane_of, x, el.face, em, real_y, y, cos_y, rays) != all_visible) {
      return true;
    }
  }
  return false;
}

}  // namespace

DirectIrradiance::DirectIrradiance(const Mesh& mesh, const Visibility& visibility,
                                   const DirectOptions& options, int64_t receivers)
    : mesh_(mesh),
      visibility_(visibility),
      options_(options),
      replicates_(std::clamp(options.replicates, 1, VisibleFraction::kMaxReplicates)) {
  const auto& faces = mesh.faces();
  std::vector<DirectEmitter> all;
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    for (int side : {kFront, kBack}) {
      const SideRule& rule = mesh.sides().OfSurface(faces[f].surface, side);
      if (!rule.Emits() || !(rule.exitance.Sum() > 0)) continue;
      DirectEmitter em;
      em.face = f;
      em.side = side;
      em.exitance = rule.exitance;
      FacePolygons(faces[f], 0, 0, 1, 1, side, &em.polygons);
      for (const SpacePolygon& p : em.polygons) em.area += p.Area();
      em.power = em.exitance * em.area;
      if (em.area > 0) all.push_back(std::move(em));
    }
  }
  // Brightest first (ties by face, for a deterministic order).
  std::stable_sort(all.begin(), all.end(), [](const DirectEmitter& a, const DirectEmitter& b) {
    return a.power.Sum() > b.power.Sum();
  });
  computes_.assign(2 * faces.size(), 0);
  int64_t pairs = 0;
  for (DirectEmitter& em : all) {
    const int64_t cost = std::max<int64_t>(1, receivers) * static_cast<int64_t>(em.polygons.size());
    if (!emitters_.empty() && pairs + cost > options_.max_pairs) {
      ++skipped_;
      continue;
    }
    pairs += cost;
    computes_[Slot(em.face, em.side)] = static_cast<int32_t>(emitters_.size()) + 1;
    emitters_.push_back(std::move(em));
  }
  if (options_.mirror_images) BuildMirrorImages(std::max<int64_t>(1, receivers), pairs);
}

void DirectIrradiance::BuildMirrorImages(int64_t receivers, int64_t pairs) {
  const auto& faces = mesh_.faces();
  const double eps = 1e-9 * mesh_.scale();
  // The mirror planes: planar faces (a triangle, or a quad whose halves agree) with a mirror part
  // on a side, grouped by the plane of that side (its normal towards the reflecting side, its
  // offset) and the mirror's reflectance, so a mirror modelled as many faces makes one image of
  // each emitter.
  struct Plane {
    Vec3 point, normal;
    Rgb mirror;
    double area = 0;
  };
  std::vector<std::array<Vec3, 2>> plane_box;  // lo, hi per plane.
  std::vector<Plane> planes;
  // Keyed by the normal and offset rounded to 1e-6 (of the scene's size), which the facets of a
  // modelled plane share despite their vertices' rounding; facets on either side of a rounding
  // boundary make two planes, each of whose images is seen only through its own facets.
  std::map<std::array<int64_t, 7>, int> plane_index;
  auto key_of = [&](const Vec3& n, double offset, const Rgb& mirror) {
    auto q = [](double v) { return static_cast<int64_t>(std::llround(v * 1e6)); };
    return std::array<int64_t, 7>{q(n.x),
                                  q(n.y),
                                  q(n.z),
                                  q(offset / mesh_.scale()),
                                  q(mirror.r * 1e6),
                                  q(mirror.g * 1e6),
                                  q(mirror.b * 1e6)};
  };
  mirror_plane_.assign(2 * faces.size(), -1);
  for (int m = 0; m < static_cast<int>(faces.size()); ++m) {
    const MeshFace& mf = faces[m];
    if (!mf.triangle && Dot(mf.normal[0], mf.normal[1]) < 1 - 1e-12) continue;
    for (int ms : {kFront, kBack}) {
      const SideRule& rule = mesh_.sides().OfSurface(mf.surface, ms);
      if (!rule.exists || rule.mirror.IsZero()) continue;
      const Vec3 nm = ms == kFront ? mf.normal[0] : -mf.normal[0];
      const auto [it, added] = plane_index.try_emplace(key_of(nm, Dot(mf.p[0], nm), rule.mirror),
                                                       static_cast<int>(planes.size()));
      if (added) {
        planes.push_back({mf.p[0], nm, rule.mirror, 0.0});
        plane_box.push_back({mf.p[0], mf.p[0]});
      }
      mirror_plane_[Slot(m, ms)] = it->second;
      planes[it->second].area += mf.Area();
      for (const Vec3& v : mf.p) {
        plane_box[it->second][0] = Min(plane_box[it->second][0], v);
        plane_box[it->second][1] = Max(plane_box[it->second][1], v);
      }
    }
  }
  // Mirror planes x emitters examined, bounded (a million mirror facets facing away from
  // thousands of lamps would otherwise cost 1e9 tests); images made, bounded by kMaxMirrorImages
  // and max_pairs.
  int64_t examined = 0;
  bool full = false;
  mirror_box_.resize(planes.size());
  for (int plane = 0; plane < static_cast<int>(planes.size()) && !full; ++plane) {
    const Vec3& nm = planes[plane].normal;
    const Vec3& p0 = planes[plane].point;
    const Vec3 lo = plane_box[plane][0], hi = plane_box[plane][1];
    mirror_box_[plane] = {lo, hi};
    // Small mirrors (a curved mirror's facets) are left to the rays: each image would be seen
    // through a small aperture, found by many shadow rays from every receiver.
    if (planes[plane].area < kMinMirrorPlaneArea * mesh_.scale() * mesh_.scale()) continue;
    for (const DirectEmitter& em : emitters_) {
      if (++examined > kMaxMirrorPairsExamined) {
        full = true;
        break;
      }
      // Only the part of the emitter in front of the plane has an image, and only if its
      // emitting side faces some of the mirror's faces.
      std::vector<SpacePolygon> front;
      for (const SpacePolygon& p : em.polygons) {
        SpacePolygon q;
        q.normal = p.normal;
        for (int k = 0; k < p.n; ++k) {
          const Vec3& a = p.v[k];
          const Vec3& b = p.v[(k + 1) % p.n];
          const double da = Dot(a - p0, nm), db = Dot(b - p0, nm);
          if (da >= 0) q.v[q.n++] = a;
          if ((da > 0 && db < 0) || (da < 0 && db > 0)) {
            q.v[q.n++] = a + (b - a) * (da / (da - db));
          }
        }
        bool in_front = false, faces_mirror = false;
        for (int k = 0; k < q.n; ++k) in_front = in_front || Dot(q.v[k] - p0, nm) > eps;
        for (int c = 0; c < 8 && q.n >= 3; ++c) {
          const Vec3 corner((c & 1) ? hi.x : lo.x, (c & 2) ? hi.y : lo.y, (c & 4) ? hi.z : lo.z);
          faces_mirror = faces_mirror || Dot(corner - q.v[0], q.normal) > eps;
        }
        if (q.n >= 3 && in_front && faces_mirror && q.Area() > 0) front.push_back(q);
      }
      if (front.empty()) continue;
      const int64_t cost = receivers * static_cast<int64_t>(front.size());
      if (static_cast<int>(images_.size()) >= kMaxMirrorImages ||
          pairs + cost > options_.max_pairs) {
        full = true;
        break;
      }
      pairs += cost;
      DirectEmitter image;
      image.face = em.face;
      image.side = em.side;
      image.exitance = em.exitance * planes[plane].mirror;
      image.area = 0;
      for (const SpacePolygon& p : front) image.area += p.Area();
      image.power = image.exitance * image.area;
      image.via = plane;
      image.plane_point = p0;
      image.plane_normal = nm;
      for (const SpacePolygon& p : front) {
        // Reflected, in reverse order: counter-clockwise about the reflected normal.
        SpacePolygon q;
        q.n = p.n;
        for (int k = 0; k < p.n; ++k) {
          const Vec3& v = p.v[p.n - 1 - k];
          q.v[k] = v - nm * (2 * Dot(v - p0, nm));
        }
        q.normal = p.normal - nm * (2 * Dot(p.normal, nm));
        image.polygons.push_back(q);
      }
      image_keys_.emplace_back(Slot(em.face, em.side), plane);
      images_.push_back(std::move(image));
    }
  }
  std::sort(image_keys_.begin(), image_keys_.end());
}

bool DirectIrradiance::ApertureOverlaps(const std::vector<SpacePolygon>& receiver,
                                        const DirectEmitter& em) const {
  // Every segment from a receiver point x to an image point y' crosses the plane inside the
  // convex hull of the crossings of the segments between their polygons' vertices (the crossing
  // point is a projective map of (x, y'), linear on each segment, and both sets are convex), so
  // the box of those crossings bounds it; with a receiver vertex on or behind the plane the map
  // is unbounded, and nothing is culled.
  const Vec3& p0 = em.plane_point;
  const Vec3& nm = em.plane_normal;
  Vec3 lo(std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
          std::numeric_limits<double>::max());
  Vec3 hi = lo * -1.0;
  for (const SpacePolygon& r : receiver) {
    for (int i = 0; i < r.n; ++i) {
      const double dx = Dot(r.v[i] - p0, nm);
      if (!(dx > 0)) return true;
      for (const SpacePolygon& q : em.polygons) {
        for (int k = 0; k < q.n; ++k) {
          const double dy = Dot(q.v[k] - p0, nm);  // Behind the plane: negative.
          if (!(dy < 0)) return true;
          const Vec3 c = r.v[i] + (q.v[k] - r.v[i]) * (dx / (dx - dy));
          lo = Min(lo, c);
          hi = Max(hi, c);
        }
      }
    }
  }
  const double eps = 1e-9 * mesh_.scale();
  const auto& box = mirror_box_[static_cast<size_t>(em.via)];
  for (int a = 0; a < 3; ++a) {
    if (hi[a] < box[0][a] - eps || lo[a] > box[1][a] + eps) return false;
  }
  return true;
}

int DirectIrradiance::EmitterIndex(int face, int side) const {
  if (face < 0 || static_cast<size_t>(Slot(face, side)) >= computes_.size()) return -1;
  return computes_[Slot(face, side)] - 1;
}

int64_t DirectIrradiance::ForElement(int element, Rgb irradiance[2], Rgb variance[2],
                                     bool* penumbra, int64_t* evaluations, const StopToken& stop,
                                     Rgb* via_mirrors) const {
  const Element& el = mesh_.elements()[element];
  if (!(el.area > 0)) return 0;
  const auto& faces = mesh_.faces();
  const double eps = 1e-9 * mesh_.scale();
  std::vector<SpacePolygon> receiver;
  ElementPolygons(mesh_, element, kFront, &receiver);
  // Unoccluded factors to every emitter and image, per receiver side.
  const size_t num = NumSources();
  std::vector<AreaFormFactor> f(num);
  double total = 0;
  for (size_t k = 0; k < num; ++k) {
    if ((k & 63) == 63 && stop.ShouldStop()) return 0;
    const DirectEmitter& em = Source(k);
    if (em.via < 0 && em.face == el.face) continue;  // A planar face does not see itself.
    if (em.via >= 0) {
      // A receiver behind the mirror's plane, or in it, sees no image.
      bool in_front = false;
      for (const SpacePolygon& p : receiver) {
        for (int i = 0; i < p.n; ++i) {
          in_front = in_front || Dot(p.v[i] - em.plane_point, em.plane_normal) > eps;
        }
      }
      if (!in_front || !ApertureOverlaps(receiver, em)) continue;
    }
    for (const SpacePolygon& p : em.polygons) {
      const AreaFormFactor a = AreaToPolygon(receiver, el.area, p, options_.quadrature);
      f[k].front += a.front;
      f[k].back += a.back;
      f[k].evaluations += a.evaluations;
    }
    *evaluations += f[k].evaluations;
    total += em.exitance.Sum() * (f[k].front + f[k].back);
  }
  int64_t rays = 0;
  VisibleFraction fraction[2] = {VisibleFraction(replicates_), VisibleFraction(replicates_)};
  for (size_t k = 0; k < num; ++k) {
    if ((k & 63) == 63 && stop.ShouldStop()) return rays;
    const DirectEmitter& em = Source(k);
    const double fk[2] = {f[k].front, f[k].back};
    if (!(fk[0] > 0) && !(fk[1] > 0)) continue;
    const bool minor = em.exitance.Sum() * (fk[0] + fk[1]) < 1e-3 * total;
    const int first =
        minor ? std::min(options_.min_shadow_rays, options_.shadow_rays) : options_.shadow_rays;
    const int most = minor ? first : std::max(first, options_.max_shadow_rays);
    const RectSampler target(faces[em.face], 0, 0, 1, 1);
    const Replicates seq(
        StreamKey(options_.seed, static_cast<uint64_t>(element), static_cast<uint64_t>(k), 0xd1ec7),
        replicates_);
    fraction[0].Clear();
    fraction[1].Clear();
    int count = first;
    for (int j = 0; j < count; ++j) {
      int hx = 0, hy = 0, x_face = 0;
      double u[4];
      seq.GetPoint(j, u);
      const Vec3 x = SampleElementArea(mesh_, element, u[0], u[1], &hx, &x_face);
      const Vec3 real_y = target.Sample(u[2], u[3], &hy);
      const Vec3 nx = faces[x_face].normal[hx];
      Vec3 y = real_y;
      Vec3 ny = em.side == kFront ? faces[em.face].normal[hy] : -faces[em.face].normal[hy];
      if (!Apparent(em, &y, &ny)) continue;
      const Vec3 d = y - x;
      const double r2 = Dot(d, d);
      if (!(r2 > 0)) continue;
      const double r = std::sqrt(r2);
      const double cos_y = -Dot(d, ny) / r;
      if (!(cos_y > 0)) continue;
      double w[2];
      w[0] = fk[0] > 0 ? std::max(0.0, Dot(d, nx) / r) * cos_y / r2 : 0.0;
      w[1] = fk[1] > 0 ? std::max(0.0, -Dot(d, nx) / r) * cos_y / r2 : 0.0;
      if (!(w[0] > 0) && !(w[1] > 0)) continue;
      const bool visible =
          PathVisible(visibility_, mirror_plane_, x, x_face, em, real_y, y, cos_y, &rays);
      for (int s = 0; s < 2; ++s) {
        if (w[s] > 0) fraction[s].Add(w[s], visible, j % seq.count);
      }
      // A penumbra: trace more, continuing the same sequence (its prefixes stay stratified).
      // Every ray blocked is not proof of an umbra: a sliver of the element left uncovered by a
      // block, itself half in the block's shadow, sees a few per cent of the emitter, and 0 would
      // be wrong by all of it (every ray arriving, in contrast, is wrong by at most what the rays
      // missed), so that case traces more too; every ray arriving asks the corners.
      const VisibleFraction& seen = fraction[0].empty() ? fraction[1] : fraction[0];
      if (j + 1 == count && count < most &&
          (fraction[0].Mixed() || fraction[1].Mixed() ||
           (!seen.empty() &&
            (seen.Value() == 0 ||
             CornersDisagree(mesh_, visibility_, mirror_plane_, element, target, em, seq, count,
                             /*all_visible=*/true, &rays))))) {
        count = most;
      } else if (j + 1 == count && count >= most && !minor && count < kDeepFactor * most) {
        // Deep in a penumbra (a few per cent of the emitter seen), the relative error of
        // max_shadow_rays is still tens of per cent: 4 x more, up to kDeepFactor x, while it
        // exceeds kDeepRelative.
        for (const VisibleFraction& v : fraction) {
          if (v.Mixed() && v.StdError() > kDeepRelative * v.Value()) {
            count *= 4;
            break;
          }
        }
      }
    }
    for (int s = 0; s < 2; ++s) {
      if (!(fk[s] > 0)) continue;
      // An image no sample saw at all is not known to be seen through its mirror: nothing.
      if (em.via >= 0 && fraction[s].empty()) continue;
      const Rgb h = em.exitance * fk[s];
      irradiance[s] += h * fraction[s].Value();
      if (via_mirrors != nullptr && em.via >= 0) via_mirrors[s] += h * fraction[s].Value();
      const double se = fraction[s].StdError();
      variance[s] += h * h * (se * se);
      if (fraction[s].Mixed()) *penumbra = true;
    }
  }
  return rays;
}

DirectElements DirectIrradiance::ForElements(const StopToken& stop) const {
  std::vector<int> all(mesh_.elements().size());
  for (size_t e = 0; e < all.size(); ++e) all[e] = static_cast<int>(e);
  return ForElementList(all.data(), all.size(), stop);
}

DirectElements DirectIrradiance::ForElementList(const int* elements, size_t n,
                                                const StopToken& stop) const {
  DirectElements out;
  out.irradiance.assign(2 * n, Rgb());
  out.std_error.assign(2 * n, Rgb());
  out.penumbra.assign(n, 0);
  out.work.assign(n, 0);
  out.element_rays.assign(n, 0);
  if (!images_.empty()) out.via_mirrors.assign(2 * n, Rgb());
  if (emitters_.empty()) return out;
  std::atomic<int64_t> rays{0}, evaluations{0};
  std::atomic<bool> stopped{false};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 2), [&](const tbb::blocked_range<size_t>& r) {
    int64_t local_rays = 0, local_evaluations = 0;
    for (size_t i = r.begin(); i < r.end(); ++i) {
      if (stop.ShouldStop()) {
        stopped = true;
        break;
      }
      Rgb h[2], var[2], mirrored[2];
      bool penumbra = false;
      int64_t evaluations = 0;
      const int64_t element_rays =
          ForElement(elements[i], h, var, &penumbra, &evaluations, stop, mirrored);
      local_rays += element_rays;
      local_evaluations += evaluations;
      out.work[i] = element_rays + evaluations;
      out.element_rays[i] = element_rays;
      for (int s = 0; s < 2; ++s) {
        out.irradiance[2 * i + s] = h[s];
        if (!out.via_mirrors.empty()) out.via_mirrors[2 * i + s] = mirrored[s];
        out.std_error[2 * i + s] =
            Rgb(std::sqrt(var[s].r), std::sqrt(var[s].g), std::sqrt(var[s].b));
      }
      out.penumbra[i] = penumbra ? 1 : 0;
    }
    rays += local_rays;
    evaluations += local_evaluations;
  });
  out.rays = rays;
  out.evaluations = evaluations;
  // A stop inside the last element's faces leaves it partial too.
  out.complete = !stopped && !stop.ShouldStop();
  return out;
}

Rgb DirectIrradiance::AtPoint(const Vec3& x, const Vec3& n, uint64_t stream, Rgb* std_error,
                              int64_t* rays, const StopToken& stop) const {
  const auto& faces = mesh_.faces();
  const Vec3 origin = x + n * visibility_.epsilon();
  Rgb sum, variance;
  // The real emitters, then their images in mirrors.
  const size_t num = NumSources();
  std::vector<double> f(num, 0.0);
  double total = 0;
  for (size_t k = 0; k < num; ++k) {
    if ((k & 63) == 63 && stop.ShouldStop()) break;
    const DirectEmitter& em = Source(k);
    // An image is seen only from the mirror's reflecting side, through the mirror's faces.
    if (em.via >= 0) {
      if (Dot(x - em.plane_point, em.plane_normal) <= 0) continue;
      SpacePolygon point;
      point.v[0] = x;
      point.n = 1;
      if (!ApertureOverlaps({point}, em)) continue;
    }
    for (const SpacePolygon& p : em.polygons) {
      if (Dot(x - p.v[0], p.normal) <= 0) continue;  // x behind the emitting side.
      f[k] += PointToPolygonFormFactorClipped(x, n, p.v.data(), p.n);
    }
    total += em.exitance.Sum() * f[k];
  }
  VisibleFraction fraction(replicates_);
  for (size_t k = 0; k < num; ++k) {
    if ((k & 63) == 63 && stop.ShouldStop()) break;
    if (!(f[k] > 0)) continue;
    const DirectEmitter& em = Source(k);
    const bool minor = em.exitance.Sum() * f[k] < 1e-3 * total;
    const int first =
        minor ? std::min(options_.min_shadow_rays, options_.shadow_rays) : options_.shadow_rays;
    const int most = minor ? first : std::max(first, options_.max_shadow_rays);
    const RectSampler target(faces[em.face], 0, 0, 1, 1);
    const Replicates seq(StreamKey(stream, static_cast<uint64_t>(k), 0xd1ec7), replicates_);
    fraction.Clear();
    int count = first;
    for (int j = 0; j < count; ++j) {
      int hy = 0;
      const Vec3 real_y = target.Sample(seq.Get(j, 0), seq.Get(j, 1), &hy);
      Vec3 y = real_y;
      Vec3 ny = em.side == kFront ? faces[em.face].normal[hy] : -faces[em.face].normal[hy];
      if (!Apparent(em, &y, &ny)) continue;
      const Vec3 d = y - origin;
      const double r2 = Dot(d, d);
      if (!(r2 > 0)) continue;
      const double r = std::sqrt(r2);
      const double cos_x = Dot(d, n) / r, cos_y = -Dot(d, ny) / r;
      if (!(cos_x > 0) || !(cos_y > 0)) continue;
      const bool visible =
          PathVisible(visibility_, mirror_plane_, origin, -1, em, real_y, y, cos_y, rays);
      fraction.Add(cos_x * cos_y / r2, visible, j % seq.count);
      // Mixed: a penumbra. None arriving: maybe a small part of the emitter seen (as for
      // elements), so more rays too.
      if (j + 1 == count && count < most && (fraction.Mixed() || fraction.Value() == 0)) {
        count = most;
      }
    }
    if (em.via >= 0 && fraction.empty()) continue;  // As for elements.
    const Rgb h = em.exitance * f[k];
    sum += h * fraction.Value();
    const double se = fraction.StdError();
    variance += h * h * (se * se);
  }
  if (std_error != nullptr) {
    *std_error = Rgb(std::sqrt(variance.r), std::sqrt(variance.g), std::sqrt(variance.b));
  }
  return sum;
}

bool DirectIrradiance::ComputesImage(int face, int side, int via, int via_side) const {
  if (via < 0 || static_cast<size_t>(Slot(via, via_side)) >= mirror_plane_.size()) return false;
  const int plane = mirror_plane_[Slot(via, via_side)];
  return plane >= 0 && std::binary_search(image_keys_.begin(), image_keys_.end(),
                                          std::make_pair(Slot(face, side), plane));
}

std::string DirectIrradiance::ToString() const {
  return absl::StrFormat(
      "DirectIrradiance{%d emitting faces computed, %d left to shooting, %d mirror images, shadow "
      "rays %d to %d}",
      emitters_.size(), skipped_, images_.size(), options_.shadow_rays, options_.max_shadow_rays);
}

}  // namespace radiosity
