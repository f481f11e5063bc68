#include "solver/geometry/photometry.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/geometry/vec.h"

namespace radiosity {
namespace {

// Linear interpolation in the increasing table `x` at `at` (clamped to its ends): the index of the
// segment's start and the weight of its end.
void Segment(const std::vector<double>& x, double at, size_t* i, double* t) {
  if (x.size() < 2 || at <= x.front()) {
    *i = 0;
    *t = 0;
    return;
  }
  if (at >= x.back()) {
    *i = x.size() - 2;
    *t = 1;
    return;
  }
  *i = static_cast<size_t>(std::upper_bound(x.begin(), x.end(), at) - x.begin()) - 1;
  *t = (at - x[*i]) / (x[*i + 1] - x[*i]);
}

// C folded into the range the table covers, by its symmetry.
double FoldC(Photometry::Symmetry symmetry, double c) {
  c = std::fmod(c, 360.0);
  if (c < 0) c += 360;
  switch (symmetry) {
    case Photometry::Symmetry::kAxial:
    case Photometry::Symmetry::kFull:
      return c;
    case Photometry::Symmetry::kQuadrant:
      if (c > 180) c = 360 - c;
      return c > 90 ? 180 - c : c;
    case Photometry::Symmetry::kBilateral0:
      return c > 180 ? 360 - c : c;
    case Photometry::Symmetry::kBilateral90:  // Mirror about the C90-C270 plane: C -> 180 - C.
      if (c < 90) return 180 - c;
      return c > 270 ? 540 - c : c;
  }
  return c;
}

// Integral of I(C, gamma) sin(gamma) d gamma at one C (exact for I linear between the table's
// gamma angles): for I = a + (b - a) s / h on [g0, g0 + h], s = gamma - g0,
//   integral = a (cos g0 - cos g1) + (b - a) / h (sin g1 - sin g0 - h cos g1).
double GammaIntegral(const Photometry& p, double c_deg) {
  double sum = 0;
  for (size_t j = 0; j + 1 < p.gamma.size(); ++j) {
    const double g0 = p.gamma[j] * kPi / 180, g1 = p.gamma[j + 1] * kPi / 180, h = g1 - g0;
    const double a = p.Intensity(c_deg, p.gamma[j]), b = p.Intensity(c_deg, p.gamma[j + 1]);
    sum += a * (std::cos(g0) - std::cos(g1)) +
           (b - a) / h * (std::sin(g1) - std::sin(g0) - h * std::cos(g1));
  }
  return sum;
}

}  // namespace

double Photometry::Intensity(double c_deg, double gamma_deg) const {
  if (gamma.size() < 2 || c.empty()) return 0;
  const double tol = 1e-9;
  if (!(gamma_deg >= gamma.front() - tol && gamma_deg <= gamma.back() + tol)) return 0;
  size_t j;
  double tg;
  Segment(gamma, gamma_deg, &j, &tg);
  const size_t ng = gamma.size();
  auto at = [&](size_t i) { return (1 - tg) * candela[i * ng + j] + tg * candela[i * ng + j + 1]; };
  if (c.size() == 1 || symmetry == Symmetry::kAxial) return at(0);
  const double folded = FoldC(symmetry, c_deg);
  if (symmetry == Symmetry::kFull && folded > c.back()) {
    // Between the last plane and 360 = the first.
    const double t = (folded - c.back()) / (360 + c.front() - c.back());
    return (1 - t) * at(c.size() - 1) + t * at(0);
  }
  size_t i;
  double tc;
  Segment(c, folded, &i, &tc);
  return (1 - tc) * at(i) + tc * at(i + 1);
}

double Photometry::Flux() const {
  if (gamma.size() < 2 || c.empty()) return 0;
  if (c.size() == 1 || symmetry == Symmetry::kAxial) return 2 * kPi * GammaIntegral(*this, c[0]);
  // I is linear in C between the images of the table's planes under the symmetry: the trapezoid
  // rule over those breakpoints is exact.
  std::vector<double> breaks = {0, 360};
  for (double a : c) {
    for (double image : {a, 360 - a, 180 - a, 180 + a}) {
      image = std::fmod(image, 360.0);
      if (image < 0) image += 360;
      breaks.push_back(image);
    }
  }
  std::sort(breaks.begin(), breaks.end());
  breaks.erase(std::unique(breaks.begin(), breaks.end()), breaks.end());
  double sum = 0, previous = GammaIntegral(*this, breaks[0]);
  for (size_t k = 1; k < breaks.size(); ++k) {
    const double next = GammaIntegral(*this, breaks[k]);
    sum += (breaks[k] - breaks[k - 1]) * kPi / 180 * (previous + next) / 2;
    previous = next;
  }
  return sum;
}

double Photometry::MaxIntensity() const {
  return candela.empty() ? 0 : *std::max_element(candela.begin(), candela.end());
}

std::string Photometry::ToString() const {
  return absl::StrFormat(
      "Photometry{%s %s gamma=%d [%g, %g] c=%d [%g, %g] max=%g cd flux=%g lm lamps=%g lm "
      "opening=%gx%g m}",
      source, format, gamma.size(), gamma.empty() ? 0 : gamma.front(),
      gamma.empty() ? 0 : gamma.back(), c.size(), c.empty() ? 0 : c.front(),
      c.empty() ? 0 : c.back(), MaxIntensity(), flux, lamp_lumens, width, length);
}

std::string CheckPhotometryAngle(const std::string& what, const std::vector<double>& angles,
                                 size_t k, double max) {
  if (!(angles[k] >= 0 && angles[k] <= max)) {
    return absl::StrCat(what, " angle ", angles[k], " is outside [0, ", max, "] degrees");
  }
  if (k > 0 && !(angles[k] > angles[k - 1])) {
    return absl::StrCat(what, " angle ", angles[k], " follows ", angles[k - 1],
                        ": the angles must increase");
  }
  return "";
}

std::string CheckPhotometry(Photometry* p) {
  if (p->gamma.size() < 2) {
    return absl::StrCat(p->gamma.size(), " vertical (gamma) angle(s): at least 2 are needed");
  }
  if (p->c.empty()) return "no horizontal (C) angles";
  for (size_t j = 0; j < p->gamma.size(); ++j) {
    if (std::string problem = CheckPhotometryAngle("vertical", p->gamma, j, 180);
        !problem.empty()) {
      return problem;
    }
  }
  for (size_t i = 0; i < p->c.size(); ++i) {
    if (std::string problem = CheckPhotometryAngle("horizontal", p->c, i, 360); !problem.empty()) {
      return problem;
    }
  }
  const double first = p->c.front(), last = p->c.back();
  if (p->c.size() == 1) {
    p->symmetry = Photometry::Symmetry::kAxial;
  } else if (first == 0 && last == 90) {
    p->symmetry = Photometry::Symmetry::kQuadrant;
  } else if (first == 0 && last == 180) {
    p->symmetry = Photometry::Symmetry::kBilateral0;
  } else if (first == 90 && last == 270) {
    p->symmetry = Photometry::Symmetry::kBilateral90;
  } else if (first == 0 && last > 180) {
    p->symmetry = Photometry::Symmetry::kFull;
  } else {
    return absl::StrCat("horizontal angles from ", first, " to ", last,
                        ": expected one angle, 0 to 90, 0 to 180, 90 to 270 or 0 to 360");
  }
  if (p->candela.size() != p->c.size() * p->gamma.size()) {
    return absl::StrCat(p->candela.size(), " candela values for ", p->c.size(), " x ",
                        p->gamma.size(), " angles");
  }
  for (size_t k = 0; k < p->candela.size(); ++k) {
    if (!std::isfinite(p->candela[k]) || p->candela[k] < 0) {
      return absl::StrCat("candela value ", p->candela[k], " (C ", p->c[k / p->gamma.size()],
                          ", gamma ", p->gamma[k % p->gamma.size()],
                          ") is not a finite intensity >= 0");
    }
  }
  p->flux = p->Flux();
  return "";
}

}  // namespace radiosity
