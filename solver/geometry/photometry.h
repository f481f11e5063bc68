// A luminaire's luminous intensity distribution, as photometric files give it (IES LM-63 and
// EULUMDAT; parsed in solver/input/photometry_file.h): candela on a grid of C-plane and gamma
// angles (photometric type C, CIE 121-1996 / IES LM-63-2019 sec. 5.13). gamma = 0 is the nadir,
// the direction the luminaire aims at; C is the angle about that axis from the C0 plane.
//
// Between the grid's angles the intensity is interpolated linearly in both angles (what
// photometric software does, LM-63-2019 annex D); outside the measured gamma range it is zero.
// Horizontal symmetry is read from the C range: a single angle (rotationally symmetric), 0-90
// (quadrant), 0-180 (about the C0-C180 plane), 90-270 (about the C90-C270 plane), or a full
// circle (0 to 360, or 0 to less than 360, continued through 360 = 0).
#ifndef RADIOSITY_SOLVER_GEOMETRY_PHOTOMETRY_H_
#define RADIOSITY_SOLVER_GEOMETRY_PHOTOMETRY_H_

#include <string>
#include <vector>

namespace radiosity {

struct Photometry {
  enum class Symmetry { kAxial, kQuadrant, kBilateral0, kBilateral90, kFull };

  std::string source;  // The file it came from (for messages).
  std::string format;  // "IES LM-63-2002", "EULUMDAT", ...
  // Gamma angles (degrees, increasing, within [0, 180]) and C angles (degrees, increasing).
  std::vector<double> gamma;
  std::vector<double> c;
  // candela[i * gamma.size() + j]: intensity in C plane c[i] at gamma[j], cd, multipliers applied.
  std::vector<double> candela;
  Symmetry symmetry = Symmetry::kAxial;
  // The lamps' rated flux as the file states it (lm; 0 when it gives none, as for absolute
  // photometry).
  double lamp_lumens = 0;
  // The luminous opening, metres (0: a point source). A negative width means a circular opening of
  // diameter -width (LM-63); EULUMDAT's 0 width of a round luminaire is converted to that form.
  double width = 0, length = 0;

  // Intensity toward (C, gamma), degrees (any C; gamma in [0, 180]), cd.
  double Intensity(double c_deg, double gamma_deg) const;
  // The luminaire's flux, integral of I d omega over the sphere, lm: exact for the interpolated
  // distribution (trapezoids in C, the linear segments in gamma integrated in closed form).
  // Computes it; CheckPhotometry stores it in `flux`.
  double Flux() const;
  double flux = 0;  // Flux(), set by CheckPhotometry.
  double MaxIntensity() const;
  std::string ToString() const;
};

// Angle `k` of `angles` (degrees, named `what` in the message): within [0, max] and above the one
// before. "" when it is, else the problem.
std::string CheckPhotometryAngle(const std::string& what, const std::vector<double>& angles,
                                 size_t k, double max);

// Checks the grid (sizes, increasing angles in range, a C range of one of the symmetries, finite
// candela >= 0) and sets `symmetry` and `flux`. The message names the problem; the parsers add the
// line.
std::string CheckPhotometry(Photometry* p);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_PHOTOMETRY_H_
