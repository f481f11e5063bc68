#include "solver/methods/adaptive.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <functional>
#include <map>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/geometry/interpolation.h"
#include "solver/transport/direct_irradiance.h"
#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace radiosity {

std::string RefineOptions::ToString() const {
  return absl::StrFormat(
      "RefineOptions{tolerance=%g min_element_size=%g light_samples=%d max_passes=%d resolve=%d "
      "direct_samples=%d}",
      tolerance, min_element_size, light_samples, max_passes, resolve, direct_samples);
}

std::vector<RefineCandidate> SelectForRefinement(const Scene& scene, const Mesh& mesh,
                                                 const Visibility& visibility,
                                                 const Solution& solution,
                                                 const RefineOptions& options) {
  const auto& elements = mesh.elements();
  const auto& faces = mesh.faces();
  const int n = static_cast<int>(elements.size());
  std::vector<RefineCandidate> out;
  if (n == 0) return out;

  // Light sample points: centroids of the emitting elements with the most power.
  struct LightSample {
    Vec3 p;  // Mesh coordinates.
    int face;
  };
  std::vector<std::pair<double, int>> emitters;
  for (int e = 0; e < n; ++e) {
    const SideRule& front = mesh.sides().at(e, kFront);
    if (front.Emits()) emitters.push_back({front.exitance.Sum() * elements[e].area, e});
  }
  std::sort(emitters.begin(), emitters.end(), std::greater<>());
  std::vector<LightSample> lights;
  // Spread the samples over the emitters: every k-th of the ranked emitter elements.
  const int want = std::min<int>(options.light_samples, static_cast<int>(emitters.size()));
  for (int k = 0; k < want; ++k) {
    int e = emitters[static_cast<size_t>(k) * emitters.size() / std::max(1, want)].second;
    lights.push_back({elements[e].centroid - mesh.origin(), elements[e].face});
  }

  double mean_lum = 0, area = 0;
  for (int e = 0; e < n; ++e) {
    mean_lum += solution.radiosity[Slot(e, 0)].Luminance() * elements[e].area;
    area += elements[e].area;
  }
  mean_lum /= area;
  const double floor_lum = 1e-3 * mean_lum;
  double min_size =
      options.min_element_size > 0 ? options.min_element_size : mesh.element_size() / 64;

  std::vector<double> priority(n, 0);
  const double eps = visibility.epsilon();
  tbb::parallel_for(tbb::blocked_range<int>(0, n), [&](const tbb::blocked_range<int>& range) {
    for (int e = range.begin(); e < range.end(); ++e) {
      const Element& el = elements[e];
      const MeshFace& f = faces[el.face];
      if (std::max(f.len_u * (el.u1 - el.u0), f.len_v * (el.v1 - el.v0)) < 2 * min_size) {
        continue;
      }
      double best = 0;
      // Radiosity differences with the neighbours across the four edges (same face).
      const double lum = solution.radiosity[Slot(e, 0)].Luminance();
      const float um = 0.5f * (el.u0 + el.u1), vm = 0.5f * (el.v0 + el.v1);
      const double probes[4][2] = {
          {um, el.v0 - 1e-6}, {um, el.v1 + 1e-6}, {el.u0 - 1e-6, vm}, {el.u1 + 1e-6, vm}};
      for (const auto& pr : probes) {
        if (pr[0] < 0 || pr[0] > 1 || pr[1] < 0 || pr[1] > 1) continue;
        int other = mesh.FindElement(el.face, pr[0], pr[1]);
        if (other < 0 || other == e) continue;
        double lo = solution.radiosity[Slot(other, 0)].Luminance();
        double diff = std::fabs(lum - lo) / std::max({lum, lo, floor_lum});
        // Differences within 3 standard errors of the pair are noise, not gradient: the
        // solver's own estimates where it gives them, else 1/sqrt(h) for h Monte Carlo hits.
        double noise = 0;
        if (!solution.std_error.empty()) {
          const double se = std::hypot(solution.std_error[Slot(e, 0)].Luminance(),
                                       solution.std_error[Slot(other, 0)].Luminance());
          noise = 3 * se / std::max({lum, lo, floor_lum});
        } else if (!solution.hits.empty()) {
          double he = solution.hits[Slot(e, 0)], ho = solution.hits[Slot(other, 0)];
          noise = he > 0 && ho > 0 ? 3 * std::sqrt(1 / he + 1 / ho) : 1.0;
        }
        if (diff > std::max(options.tolerance, noise)) best = std::max(best, diff);
      }
      // Shadow boundaries: does each light sample's visibility agree at the element's corners
      // (inset slightly) and centre?
      if (!lights.empty()) {
        const double inset = 0.02;
        const double us[3] = {el.u0 + inset * (el.u1 - el.u0), 0.5 * (el.u0 + el.u1),
                              el.u1 - inset * (el.u1 - el.u0)};
        const double vs[3] = {el.v0 + inset * (el.v1 - el.v0), 0.5 * (el.v0 + el.v1),
                              el.v1 - inset * (el.v1 - el.v0)};
        const int pts[5][2] = {{0, 0}, {2, 0}, {0, 2}, {2, 2}, {1, 1}};
        int changed = 0;
        for (const LightSample& light : lights) {
          int seen = 0, tested = 0;
          for (const auto& pt : pts) {
            double u = us[pt[0]], v = vs[pt[1]];
            if (f.triangle && u + v >= 1) continue;
            Vec3 p = f.Eval(u, v);
            Vec3 normal = f.normal[f.Half(u, v)];
            Vec3 d = light.p - p;
            if (Dot(d, normal) <= 0) continue;  // The light is behind: no direct light here.
            ++tested;
            seen += !visibility.Occluded(p + normal * eps, d, 0, 1 - 1e-4, el.face);
          }
          if (tested > 0 && seen > 0 && seen < tested) ++changed;
        }
        if (changed > 0) best = std::max(best, 1.0 + static_cast<double>(changed) / lights.size());
      }
      priority[e] = best;
    }
  });
  for (int e = 0; e < n; ++e) {
    if (priority[e] > 0) out.push_back({e, priority[e]});
  }
  std::stable_sort(out.begin(), out.end(), [](const RefineCandidate& a, const RefineCandidate& b) {
    return a.priority > b.priority;
  });
  return out;
}

Solution RegatherRefinement(const Scene& scene, const Mesh& coarse, const Solution& solution,
                            const Mesh& refined, const Visibility& visibility,
                            const RefineOptions& options, uint64_t seed, int pass) {
  constexpr uint64_t kRegatherStream = 0x5245474154484552ULL;  // "REGATHER"
  const auto& old_elements = coarse.elements();
  const auto& elements = refined.elements();
  const int n = static_cast<int>(elements.size());
  const size_t slots = 2 * static_cast<size_t>(n);
  // The solver recorded how much of each side's irradiance came straight from the emitters.
  const bool tracked = solution.irradiance.size() == solution.radiosity.size() &&
                       solution.direct_irradiance.size() == solution.radiosity.size();
  Solution out = solution;
  out.radiosity.assign(slots, Rgb());
  if (!solution.hits.empty()) out.hits.assign(slots, 0);
  if (!solution.std_error.empty()) out.std_error.assign(slots, Rgb());
  if (tracked) {
    out.irradiance.assign(slots, Rgb());
    out.direct_irradiance.assign(slots, Rgb());
  }

  // Each element of `refined` lies inside one element of `coarse` (refinement only halves).
  std::vector<std::vector<int>> pieces(old_elements.size());
  for (int e = 0; e < n; ++e) {
    const Element& el = elements[e];
    const int c =
        coarse.FindElement(el.face, 0.5 * (double{el.u0} + el.u1), 0.5 * (double{el.v0} + el.v1));
    const Element& o = old_elements[c];
    if (o.u0 == el.u0 && o.u1 == el.u1 && o.v0 == el.v0 && o.v1 == el.v1) {
      for (int side = 0; side < 2; ++side) {
        out.radiosity[Slot(e, side)] = solution.radiosity[Slot(c, side)];
        if (!out.hits.empty()) out.hits[Slot(e, side)] = solution.hits[Slot(c, side)];
        if (!out.std_error.empty())
          out.std_error[Slot(e, side)] = solution.std_error[Slot(c, side)];
        if (tracked) {
          out.irradiance[Slot(e, side)] = solution.irradiance[Slot(c, side)];
          out.direct_irradiance[Slot(e, side)] = solution.direct_irradiance[Slot(c, side)];
        }
      }
    } else {
      pieces[c].push_back(e);
    }
  }
  std::vector<int> split;
  for (int c = 0; c < static_cast<int>(pieces.size()); ++c) {
    if (!pieces[c].empty()) split.push_back(c);
  }

  // The indirect irradiance of the coarse elements, smoothed to their corners (CornerRadiosity's
  // area-weighted means within each face), to give pieces its gradient across their element.
  std::vector<std::array<Rgb, 4>> indirect_corners;
  if (tracked) {
    Solution indirect_field;
    indirect_field.radiosity.resize(solution.radiosity.size());
    for (size_t slot = 0; slot < solution.radiosity.size(); ++slot) {
      indirect_field.radiosity[slot] = solution.irradiance[slot] - solution.direct_irradiance[slot];
    }
    indirect_corners = CornerRadiosity(coarse, indirect_field);
  }
  // Direct light of the new elements computed (direct_irradiance.h): exact unoccluded factors,
  // visible fractions from shadow rays, more of them in penumbrae.
  DirectOptions direct_options;
  direct_options.max_shadow_rays = std::max(direct_options.shadow_rays, options.direct_samples);
  direct_options.seed = StreamKey(seed, kRegatherStream, static_cast<uint64_t>(pass));
  const DirectIrradiance direct(refined, visibility, direct_options, n);
  std::atomic<int64_t> spent{0};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, split.size()), [&](const auto& range) {
    std::vector<std::array<Rgb, 2>> hd, se;
    for (size_t i = range.begin(); i < range.end(); ++i) {
      const int c = split[i];
      const std::vector<int>& mine = pieces[c];
      const int sides = coarse.sides().at(c, kBack).exists ? 2 : 1;
      hd.assign(mine.size(), {Rgb(), Rgb()});
      se.assign(mine.size(), {Rgb(), Rgb()});
      std::array<Rgb, 2> mean = {Rgb(), Rgb()};
      double area = 0;
      int64_t evaluations = 0;
      for (size_t k = 0; k < mine.size(); ++k) {
        const int e = mine[k];
        Rgb h[2], var[2];
        bool penumbra = false;
        spent += direct.ForElement(e, h, var, &penumbra, &evaluations);
        for (int side = 0; side < sides; ++side) {
          hd[k][side] = h[side];
          se[k][side] = Rgb(std::sqrt(var[side].r), std::sqrt(var[side].g), std::sqrt(var[side].b));
          mean[side] += hd[k][side] * elements[e].area;
        }
        area += elements[e].area;
      }
      for (int side = 0; side < sides; ++side) mean[side] = mean[side] * (1.0 / area);
      // The indirect irradiance c received (tracked: its irradiance less the part straight from
      // the emitters; negative only through overshooting's negative rays).
      std::array<Rgb, 2> indirect = {Rgb(), Rgb()};
      for (int side = 0; side < sides && tracked; ++side) {
        indirect[side] =
            solution.irradiance[Slot(c, side)] - solution.direct_irradiance[Slot(c, side)];
        for (int ch = 0; ch < 3; ++ch) indirect[side][ch] = std::max(0.0, indirect[side][ch]);
      }
      const Element& ce = old_elements[c];
      for (size_t k = 0; k < mine.size(); ++k) {
        const int e = mine[k];
        std::array<Rgb, 2> h = {hd[k][0] + indirect[0], hd[k][1] + indirect[1]};
        if (tracked) {
          // c's indirect irradiance plus the bilinear interpolation of its corner values at the
          // piece's centre (its mean over the piece) less their mean (its mean over c): the
          // gradient, with c's total kept.
          const Element& el = elements[e];
          const double a = (0.5 * (double{el.u0} + el.u1) - ce.u0) / (double{ce.u1} - ce.u0);
          const double b = (0.5 * (double{el.v0} + el.v1) - ce.v0) / (double{ce.v1} - ce.v0);
          for (int side = 0; side < sides; ++side) {
            const auto& q = indirect_corners[Slot(c, side)];
            const Rgb at = q[0] * ((1 - a) * (1 - b)) + q[1] * (a * (1 - b)) +
                           q[2] * ((1 - a) * b) + q[3] * (a * b);
            const Rgb mean_q = (q[0] + q[1] + q[2] + q[3]) * 0.25;
            h[side] += at - mean_q;
            for (int ch = 0; ch < 3; ++ch) h[side][ch] = std::max(hd[k][side][ch], h[side][ch]);
          }
        }
        for (int side = 0; side < sides; ++side) {
          const int other = 1 - side;
          const SideRule& rule = refined.sides().at(e, side);
          const Rgb& emitted = rule.exitance;
          const Rgb& reflect = rule.reflectance;
          // T: of what arrives at the other side, the part that leaves from this one.
          const Rgb& transmit = refined.sides().at(e, other).transmittance;
          Rgb b;
          if (tracked) {
            // B = E + R H + T H'.
            b = emitted + reflect * h[side];
            if (sides == 2) b += transmit * h[other];
            out.irradiance[Slot(e, side)] = h[side];
            out.direct_irradiance[Slot(e, side)] = hd[k][side];
          } else {
            b = solution.radiosity[Slot(c, side)] + reflect * (hd[k][side] - mean[side]);
            if (sides == 2) b += transmit * (hd[k][other] - mean[other]);
            // B = E + reflected + transmitted >= E: a noisy B_c can leave a piece in full shadow
            // slightly below its emission.
            for (int ch = 0; ch < 3; ++ch) b[ch] = std::max(b[ch], emitted[ch]);
          }
          out.radiosity[Slot(e, side)] = b;
          // Its value is c's estimate, corrected: c's noise, c's hits, and the error of its own
          // direct light.
          if (!out.hits.empty()) out.hits[Slot(e, side)] = solution.hits[Slot(c, side)];
          if (!out.std_error.empty()) {
            const Rgb d = reflect * se[k][side];
            const Rgb& sc = solution.std_error[Slot(c, side)];
            out.std_error[Slot(e, side)] =
                Rgb(std::sqrt(sc.r * sc.r + d.r * d.r), std::sqrt(sc.g * sc.g + d.g * d.g),
                    std::sqrt(sc.b * sc.b + d.b * d.b));
          }
        }
      }
    }
  });
  out.rays += spent.load();
  return out;
}

}  // namespace radiosity
