// Photometric files written from a candela table, for tests: the same distribution as IES LM-63
// text and as EULUMDAT text, so that the parsers can be checked against each other and against
// the function the table samples.
#ifndef RADIOSITY_TESTS_TESTING_PHOTOMETRY_FILES_H_
#define RADIOSITY_TESTS_TESTING_PHOTOMETRY_FILES_H_

#include <functional>
#include <string>
#include <vector>

namespace radiosity::testing {

struct CandelaTable {
  std::vector<double> gamma;    // Degrees, increasing.
  std::vector<double> c;        // Degrees, increasing (the planes given).
  std::vector<double> candela;  // [i * gamma.size() + j].
};

// The table of `intensity(c, gamma)` (cd) on the given angles.
CandelaTable Tabulate(const std::vector<double>& c, const std::vector<double>& gamma,
                      const std::function<double(double, double)>& intensity);
// first, first + step, ..., last.
std::vector<double> Angles(double first, double step, double last);

// LM-63-2002 text: absolute photometry (lumens -1), multiplier 1, metres, the given opening.
// Values are written 10 to a line, with full precision.
std::string IesText(const CandelaTable& t, double width = 0, double length = 0);

// EULUMDAT text of a table on Mc planes of spacing 360 / Mc with symmetry `isym` (the planes
// that symmetry gives, taken from `full`, a table of all Mc planes 0 .. 360 - Dc); intensities in
// cd/klm of lamps of `lamp_lumens`.
std::string LdtText(const CandelaTable& full, int isym, double lamp_lumens = 1000,
                    double length_mm = 0, double width_mm = 0);

}  // namespace radiosity::testing

#endif  // RADIOSITY_TESTS_TESTING_PHOTOMETRY_FILES_H_
