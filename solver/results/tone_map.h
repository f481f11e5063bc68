// Tone mapping shared by the PNG image and the PLY vertex colours.
#ifndef RADIOSITY_SOLVER_RESULTS_TONE_MAP_H_
#define RADIOSITY_SOLVER_RESULTS_TONE_MAP_H_

#include <cstdint>
#include <vector>

namespace radiosity {

// Exposure k such that k x (99th percentile of the positive luminances) = 0.9; 1 if none.
// Reorders and shrinks *luminance.
double Exposure(std::vector<float>* luminance);

// Linear value (already exposed) to an 8-bit sRGB code: clamp to [0,1], then the sRGB transfer
// function (IEC 61966-2-1): 12.92 c for c <= 0.0031308, else 1.055 c^(1/2.4) - 0.055.
uint8_t ToSrgb8(double c);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_TONE_MAP_H_
