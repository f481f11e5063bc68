#include "solver/results/tone_map.h"

#include <algorithm>
#include <cmath>

namespace radiosity {

double Exposure(std::vector<float>* luminance) {
  std::vector<float>& lum = *luminance;
  lum.erase(std::remove_if(lum.begin(), lum.end(), [](float l) { return !(l > 0); }), lum.end());
  if (lum.empty()) return 1;
  // Nearest-rank percentile: the smallest value with at least 99% of the values at or below it.
  size_t k = static_cast<size_t>(std::ceil(0.99 * static_cast<double>(lum.size()))) - 1;
  k = std::min(k, lum.size() - 1);
  std::nth_element(lum.begin(), lum.begin() + static_cast<std::ptrdiff_t>(k), lum.end());
  double p99 = lum[k];
  return p99 > 0 && std::isfinite(p99) ? 0.9 / p99 : 1;
}

// Linear value (already exposed) to an 8-bit sRGB code: clamp to [0,1], then the sRGB transfer
// function (IEC 61966-2-1): 12.92 c for c <= 0.0031308, else 1.055 c^(1/2.4) - 0.055.
uint8_t ToSrgb8(double c) {
  if (!(c > 0)) return 0;
  if (c >= 1) return 255;
  double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1 / 2.4) - 0.055;
  return static_cast<uint8_t>(std::lround(s * 255));
}

}  // namespace radiosity
