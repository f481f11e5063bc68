// False colour: an image's radiosity mapped linearly from MIN to MAX onto viridis (van der Walt
// and Smith's perceptually uniform scale of matplotlib), with a legend of the scale and its
// values at five ticks and its unit drawn to the right of the image (docs/guide/outputs.md).
#ifndef RADIOSITY_SOLVER_RESULTS_FALSE_COLOR_H_
#define RADIOSITY_SOLVER_RESULTS_FALSE_COLOR_H_

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/results/image.h"

namespace radiosity {

struct FalseColorRange {
  double min = 0, max = 0;
  // `auto`: min and max are taken from the image (AutoFalseColorRange) when it is drawn.
  bool automatic = false;
  std::string ToString() const;
};

// "MIN:MAX" with finite MIN < MAX, or "auto". INVALID_ARGUMENT naming `flag` and the problem
// otherwise.
absl::StatusOr<FalseColorRange> ParseFalseColorRange(const std::string& text,
                                                     const std::string& flag);

// 8-bit sRGB image, row-major from the top-left pixel.
struct Image8 {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // 3 * width * height.
};

// The colour of `t` in [0, 1] on the scale (clamped), 8-bit sRGB.
std::array<uint8_t, 3> FalseColorOf(double t);

// Each pixel's radiosity luminance, pi x Y(radiance) (W per square scene unit; the luminance
// weights of Rgb::Luminance), placed on the scale from range.min to range.max (clamped); pixels
// of zero radiance (no surface, or a surface that receives no light) are black. The legend
// (FalseColorLegendWidth(height) pixels wide) follows on the right: the scale from min at the
// bottom to max at the top, labelled at min, the quarters and max.
// The legend's top carries the unit, "W/m2" (radiosity is W per square scene unit: W/m^2 for a
// scene modelled in metres). An automatic range is resolved first (AutoFalseColorRange).
Image8 FalseColorImage(const Image& radiance, const FalseColorRange& range);

// The scene's own range in this image: from the lowest radiosity luminance of the pixels that
// show a lit surface to the 99th percentile of them, so that a lamp in view (a few per cent of
// the pixels, far brighter than what it lights) saturates at the top colour instead of
// compressing every other surface into the bottom of the scale. [0, 1] when no pixel is lit;
// max > min always.
FalseColorRange AutoFalseColorRange(const Image& radiance);
int FalseColorLegendWidth(int height);

// Writes an 8-bit sRGB PNG (as is: no tone mapping).
absl::Status WritePng8(const Image8& image, const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_FALSE_COLOR_H_
