// Images of a solution: an RGB float image and writing it as linear HDR and tone-mapped sRGB.
#ifndef RADIOSITY_SOLVER_RESULTS_IMAGE_H_
#define RADIOSITY_SOLVER_RESULTS_IMAGE_H_

#include <string>
#include <vector>

#include "absl/status/status.h"

namespace radiosity {

// An RGB float image, row-major from the top-left pixel.
struct Image {
  int width = 0, height = 0;
  std::vector<float> rgb;  // 3 * width * height, linear radiance (W/m^2/sr).
};

// Writes linear HDR (OpenEXR, half float) and a tone-mapped sRGB PNG (exposure set so that the
// 99th percentile of luminance maps to 0.9). Either path may be empty to skip it.
absl::Status WriteImage(const Image& image, const std::string& exr_path,
                        const std::string& png_path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_IMAGE_H_
