#include "solver/transport/luminaire.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include "absl/strings/str_format.h"
#include "solver/geometry/sides.h"
#include "solver/transport/rng.h"
#include "solver/transport/sobol.h"

namespace radiosity {
namespace {

// The luminaire's frame: w toward gamma = 0, u toward C0, v toward C90 = u x w, a quarter turn
// counterclockwise from u seen from behind the luminaire (y up, w = -y, u = +x: v = -z).
struct Frame {
  Vec3 u, v, w;
};

Frame FrameOf(const Luminaire& l) {
  Frame f;
  f.w = Normalize(l.aim);
  Vec3 c0 = l.c0 - f.w * Dot(l.c0, f.w);
  if (!(Length(c0) > 1e-9)) {
    const Vec3 other = std::fabs(f.w.z) < 0.9 ? Vec3{0, 0, 1} : Vec3{1, 0, 0};
    c0 = other - f.w * Dot(other, f.w);
  }
  f.u = Normalize(c0);
  f.v = Cross(f.u, f.w);
  return f;
}

// The colour scaled to luminance 1 (white when it has none).
Rgb Chroma(const Rgb& color) {
  const double y = color.Luminance();
  return y > 0 ? color / y : Rgb(1, 1, 1);
}

// E at x (normal n) from one emission point y, without visibility: I cos(theta_x) / d^2.
Rgb PointIrradiance(const Luminaire& l, const Frame& f, const Rgb& chroma, const Vec3& y,
                    const Vec3& x, const Vec3& n, Vec3* to_light, double* distance) {
  const Vec3 d = x - y;
  const double d2 = Dot(d, d);
  if (!(d2 > 1e-18)) return Rgb();
  const double dist = std::sqrt(d2);
  const Vec3 dir = d / dist;
  const double cos_x = -Dot(dir, n);
  if (cos_x <= 0) return Rgb();
  const double gamma = std::acos(std::clamp(Dot(dir, f.w), -1.0, 1.0)) * 180 / kPi;
  const double c = std::atan2(Dot(dir, f.v), Dot(dir, f.u)) * 180 / kPi;
  const double intensity = l.photometry->Intensity(c, gamma) * l.multiplier;
  if (!(intensity > 0)) return Rgb();
  *to_light = y - x;
  *distance = dist;
  return chroma * (intensity * cos_x / d2);
}

// Shadow ray from x toward y = x + to_light, stopping short of the luminaire (which may sit on a
// ceiling's plane); `ignore` is the face x lies on (-1 for a free point).
bool Visible(const Visibility& visibility, const Vec3& x, const Vec3& to_light, int ignore) {
  return !visibility.Occluded(x, to_light, 0, 1 - 1e-4, ignore);
}

}  // namespace

Rgb Luminaire::Intensity(const Vec3& dir) const {
  if (!photometry) return Rgb();
  const Frame f = FrameOf(*this);
  const double gamma = std::acos(std::clamp(Dot(Normalize(dir), f.w), -1.0, 1.0)) * 180 / kPi;
  const double c = std::atan2(Dot(dir, f.v), Dot(dir, f.u)) * 180 / kPi;
  return Chroma(color) * (photometry->Intensity(c, gamma) * multiplier);
}

Rgb Luminaire::Flux() const {
  if (!photometry) return Rgb();
  return Chroma(color) * (photometry->flux * multiplier);
}

bool Luminaire::IsArea() const {
  return photometry && photometry->length != 0 && photometry->width != 0;
}

Vec3 Luminaire::OpeningPoint(double u1, double u2) const {
  if (!IsArea()) return position;
  const Frame f = FrameOf(*this);
  if (photometry->width < 0) {  // A disc of diameter -width (LM-63: both negative).
    const double r = -photometry->width / 2 * std::sqrt(u1), phi = 2 * kPi * u2;
    return position + f.u * (r * std::cos(phi)) + f.v * (r * std::sin(phi));
  }
  // Length along C0-C180, width along C90-C270 (LM-63, EULUMDAT).
  return position + f.u * ((u1 - 0.5) * photometry->length) +
         f.v * ((u2 - 0.5) * photometry->width);
}

std::string Luminaire::ToString() const {
  return absl::StrFormat(
      "Luminaire{%s at (%g, %g, %g) aim (%g, %g, %g) c0 (%g, %g, %g) x%g color %s %s}", file,
      position.x, position.y, position.z, aim.x, aim.y, aim.z, c0.x, c0.y, c0.z, multiplier,
      color.ToString(), photometry ? photometry->ToString() : "not loaded");
}

Rgb LuminaireIrradianceAt(const Mesh& mesh, const Visibility& visibility,
                          const std::vector<Luminaire>& luminaires, const Vec3& x, const Vec3& n,
                          int samples, uint64_t stream, Rgb* variance, int64_t* rays) {
  Rgb total;
  const Vec3 start = x + n * visibility.epsilon();
  for (size_t k = 0; k < luminaires.size(); ++k) {
    const Luminaire& l = luminaires[k];
    if (!l.photometry) continue;
    const Frame f = FrameOf(l);
    const Rgb chroma = Chroma(l.color);
    Luminaire local = l;
    local.position = l.position - mesh.origin();
    const int count = l.IsArea() ? samples : 1;
    const OwenSobol points(StreamKey(stream, 0x6c756d /* "lum" */, k));
    Rgb sum, sum_sq;
    for (int s = 0; s < count; ++s) {
      double u[2] = {0.5, 0.5};
      if (l.IsArea()) points.GetPoint(static_cast<uint32_t>(s), 0, 2, u);
      const Vec3 y = local.OpeningPoint(u[0], u[1]);
      Vec3 to_light;
      double dist = 0;
      const Rgb e = PointIrradiance(l, f, chroma, y, x, n, &to_light, &dist);
      if (e.IsZero()) continue;
      ++*rays;
      if (!Visible(visibility, start, y - start, -1)) continue;
      sum += e;
      sum_sq += e * e;
    }
    const Rgb mean = sum / count;
    total += mean;
    if (count > 1) *variance += (sum_sq / count - mean * mean) / (count - 1.0);
  }
  return total;
}

ElementIrradiance LuminaireIrradiance(const Mesh& mesh, const Visibility& visibility,
                                      const std::vector<Luminaire>& luminaires, int samples,
                                      uint64_t seed, const StopToken& stop,
                                      const ElementRange& range) {
  const size_t n = mesh.elements().size();
  ElementIrradiance out;
  out.irradiance.assign(2 * n, Rgb());
  out.std_error.assign(2 * n, Rgb());
  if (luminaires.empty()) return out;
  // In mesh coordinates, with their frames and colours once.
  struct Prepared {
    Luminaire l;
    Frame f;
    Rgb chroma;
  };
  std::vector<Prepared> prepared;
  for (const Luminaire& l : luminaires) {
    if (!l.photometry) continue;
    Prepared p{l, FrameOf(l), Chroma(l.color)};
    p.l.position = l.position - mesh.origin();
    prepared.push_back(std::move(p));
  }
  const SideTable& sides = mesh.sides();
  std::atomic<int64_t> rays{0};
  std::atomic<bool> stopped{false};
  const size_t count = range.size(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 8), [&](const tbb::blocked_range<size_t>& r) {
    int64_t local_rays = 0;
    for (size_t i = r.begin(); i < r.end(); ++i) {
      const size_t e = static_cast<size_t>(range.Element(i));
      if (stop.ShouldStop()) {
        stopped = true;
        break;
      }
      for (int side : {kFront, kBack}) {
        const int slot = Slot(static_cast<int>(e), side);
        if (!sides.exists(slot)) continue;
        Rgb total, variance;
        for (size_t k = 0; k < prepared.size(); ++k) {
          const Prepared& p = prepared[k];
          const OwenSobol points(
              StreamKey(seed, 0x6c756d /* "lum" */, static_cast<uint64_t>(slot), k));
          Rgb sum, sum_sq;
          for (int s = 0; s < samples; ++s) {
            double u[5];
            points.GetPoint(static_cast<uint32_t>(s), 0, 5, u);
            int half = 0, face = 0;
            const Vec3 x = mesh.SampleElement(static_cast<int>(e), u[0], u[1], u[2], &half, &face);
            const Vec3& front = mesh.faces()[face].normal[half];
            const Vec3 normal = side == kFront ? front : -front;
            const Vec3 y = p.l.OpeningPoint(u[3], u[4]);
            Vec3 to_light;
            double dist = 0;
            const Rgb value = PointIrradiance(p.l, p.f, p.chroma, y, x, normal, &to_light, &dist);
            if (value.IsZero()) continue;
            ++local_rays;
            if (!Visible(visibility, x, to_light, face)) continue;
            sum += value;
            sum_sq += value * value;
          }
          const Rgb mean = sum / samples;
          total += mean;
          variance += (sum_sq / samples - mean * mean) / std::max(1, samples - 1);
        }
        out.irradiance[slot] = total;
        for (int c = 0; c < 3; ++c) {
          out.std_error[slot][c] = std::sqrt(std::max(0.0, variance[c]));
        }
      }
    }
    rays += local_rays;
  });
  out.rays = rays;
  out.complete = !stopped && !stop.ShouldStop();
  return out;
}

}  // namespace radiosity
