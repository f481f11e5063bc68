// Photometric files (solver/input/photometry_file.h) and the distributions they give
// (solver/geometry/photometry.h): fluxes against closed forms (isotropic 4 pi I, Lambertian
// pi I0), the symmetries of LM-63 and EULUMDAT against the full circle they stand for, the two
// formats against each other, a file as vendors write it, and errors that name the line.
#include "solver/geometry/photometry.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/str_split.h"
#include "solver/geometry/vec.h"
#include "solver/input/photometry_file.h"
#include "tests/testing/photometry_files.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using testing::Angles;
using testing::CandelaTable;
using testing::IesText;
using testing::LdtText;
using testing::Tabulate;

double Rad(double deg) { return deg * kPi / 180; }

// An independent flux: the midpoint rule over a fine grid of Intensity sin(gamma).
double BruteFlux(const Photometry& p) {
  const int nc = 720, ng = 1800;
  double sum = 0;
  for (int i = 0; i < nc; ++i) {
    const double c = (i + 0.5) * 360.0 / nc;
    for (int j = 0; j < ng; ++j) {
      const double g = (j + 0.5) * 180.0 / ng;
      sum += p.Intensity(c, g) * std::sin(Rad(g));
    }
  }
  return sum * Rad(360.0 / nc) * Rad(180.0 / ng);
}

TEST(PhotometryTest, IsotropicSourceSendsFourPiTimesItsIntensity) {
  ASSERT_OK_AND_ASSIGN(
      Photometry p,
      ParseIes(IesText(Tabulate({0}, {0, 180}, [](double, double) { return 1000.0; })), "iso.ies"));
  EXPECT_EQ(p.symmetry, Photometry::Symmetry::kAxial);
  EXPECT_NEAR(p.Flux(), 4 * kPi * 1000, 1e-9 * 4 * kPi * 1000);
  EXPECT_EQ(p.flux, p.Flux());  // Computed once, when the file was read.
  for (double c : {0.0, 77.0, 200.0, -30.0}) {
    for (double g : {0.0, 33.0, 90.0, 180.0}) EXPECT_DOUBLE_EQ(p.Intensity(c, g), 1000);
  }
}

TEST(PhotometryTest, LambertianSourceSendsPiTimesItsPeak) {
  // I = I0 cos(gamma) downward, nothing upward, tabulated every degree.
  const CandelaTable t =
      Tabulate({0}, Angles(0, 1, 90), [](double, double g) { return 1000 * std::cos(Rad(g)); });
  ASSERT_OK_AND_ASSIGN(Photometry p, ParseIes(IesText(t), "lambert.ies"));
  // Linear interpolation of cos between degrees: within 4e-5 of the closed form.
  EXPECT_NEAR(p.Flux(), kPi * 1000, 4e-5 * kPi * 1000);
  EXPECT_NEAR(p.Flux(), BruteFlux(p), 1e-5 * p.Flux());
  EXPECT_EQ(p.Intensity(0, 120), 0);  // Outside the measured gamma range.
  EXPECT_NEAR(p.Intensity(45, 60), 500, 0.05);
}

// Distributions with each symmetry (a function of C and gamma, degrees), positive everywhere.
double Quadrant(double c, double g) {
  return 500 * (1 + 0.5 * std::cos(Rad(2 * c)) * std::sin(Rad(g)));
}
double Bilateral0(double c, double g) {
  return 500 * (1 + 0.5 * std::cos(Rad(c)) * std::sin(Rad(g)));
}
double Bilateral90(double c, double g) {
  return 500 * (1 + 0.5 * std::sin(Rad(c)) * std::sin(Rad(g)));
}
double Asymmetric(double c, double g) {
  return 500 * (1 + 0.5 * std::cos(Rad(c)) * std::sin(Rad(g)) +
                0.2 * std::sin(Rad(2 * c)) * std::sin(Rad(g)) + 0.1 * std::cos(Rad(g)));
}

TEST(PhotometryTest, HalfAndQuarterTablesStandForTheFullCircle) {
  struct Case {
    double (*f)(double, double);
    double first, last;
    Photometry::Symmetry symmetry;
  };
  const std::vector<double> gamma = Angles(0, 5, 180);
  for (const Case& k : {Case{Quadrant, 0, 90, Photometry::Symmetry::kQuadrant},
                        Case{Bilateral0, 0, 180, Photometry::Symmetry::kBilateral0},
                        Case{Bilateral90, 90, 270, Photometry::Symmetry::kBilateral90}}) {
    SCOPED_TRACE(::testing::Message() << "C " << k.first << " to " << k.last);
    ASSERT_OK_AND_ASSIGN(Photometry part,
                         ParseIes(IesText(Tabulate(Angles(k.first, 15, k.last), gamma, k.f)), "p"));
    ASSERT_OK_AND_ASSIGN(Photometry full,
                         ParseIes(IesText(Tabulate(Angles(0, 15, 360), gamma, k.f)), "f"));
    EXPECT_EQ(part.symmetry, k.symmetry);
    EXPECT_EQ(full.symmetry, Photometry::Symmetry::kFull);
    for (double c = -180; c <= 540; c += 7.3) {
      for (double g = 0; g <= 180; g += 11.1) {
        ASSERT_NEAR(part.Intensity(c, g), full.Intensity(c, g), 1e-9 * 500) << c << " " << g;
      }
    }
    EXPECT_NEAR(part.Flux(), full.Flux(), 1e-9 * full.Flux());
    EXPECT_NEAR(part.Flux(), BruteFlux(part), 1e-5 * part.Flux());
  }
}

TEST(PhotometryTest, FullCircleWithoutThe360PlaneWrapsThroughZero) {
  const std::vector<double> gamma = Angles(0, 5, 180);
  ASSERT_OK_AND_ASSIGN(Photometry closed,
                       ParseIes(IesText(Tabulate(Angles(0, 15, 360), gamma, Asymmetric)), "a"));
  ASSERT_OK_AND_ASSIGN(Photometry open,
                       ParseIes(IesText(Tabulate(Angles(0, 15, 345), gamma, Asymmetric)), "b"));
  for (double c = 0; c <= 360; c += 2.5) {
    for (double g = 0; g <= 180; g += 7.5) {
      ASSERT_NEAR(open.Intensity(c, g), closed.Intensity(c, g), 1e-9 * 500) << c << " " << g;
    }
  }
  EXPECT_NEAR(open.Flux(), BruteFlux(open), 1e-5 * open.Flux());
  // Against the function the table samples: within the 15 x 5 degree grid's interpolation error.
  double exact = 0;
  for (int i = 0; i < 720; ++i) {
    for (int j = 0; j < 1800; ++j) {
      const double c = (i + 0.5) / 2, g = (j + 0.5) / 10;
      exact += Asymmetric(c, g) * std::sin(Rad(g)) * Rad(0.5) * Rad(0.1);
    }
  }
  EXPECT_NEAR(open.Flux(), exact, 2e-3 * exact);
}

TEST(PhotometryTest, EulumdatGivesWhatIesGivesForEverySymmetry) {
  struct Case {
    int isym;
    double (*f)(double, double);
  };
  const std::vector<double> gamma = Angles(0, 5, 180);
  const std::vector<double> planes = Angles(0, 15, 345);  // Mc = 24, Dc = 15.
  for (const Case& k :
       {Case{0, Asymmetric}, Case{1, [](double, double g) { return 800 * std::cos(Rad(g / 2)); }},
        Case{2, Bilateral0}, Case{3, Bilateral90}, Case{4, Quadrant}}) {
    SCOPED_TRACE(::testing::Message() << "Isym " << k.isym);
    const CandelaTable full = Tabulate(planes, gamma, k.f);
    ASSERT_OK_AND_ASSIGN(Photometry ldt, ParseEulumdat(LdtText(full, k.isym, 3000), "t.ldt"));
    ASSERT_OK_AND_ASSIGN(Photometry ies, ParseIes(IesText(full), "t.ies"));
    EXPECT_EQ(ldt.lamp_lumens, 3000);
    for (double c = 0; c < 360; c += 5) {
      for (double g = 0; g <= 180; g += 5) {
        // Both hold the function's values at the table's angles (cd/klm scaled by 3 klm).
        ASSERT_NEAR(ldt.Intensity(c, g), ies.Intensity(c, g), 1e-9 * 800) << c << " " << g;
      }
    }
    EXPECT_NEAR(ldt.Flux(), ies.Flux(), 1e-9 * ies.Flux());
  }
}

// A file as vendors write it: keywords, CR LF, TILT=INCLUDE, commas, values wrapped anyhow,
// feet, a candela multiplier and a ballast factor.
constexpr char kVendorFile[] =
    "IESNA:LM-63-1995\r\n"
    "[TEST] 12345\r\n"
    "[MANUFAC] Example Lighting\r\n"
    "[LUMINAIRE] 2x2 troffer, prismatic lens\r\n"
    "[MORE] measured at 25 C\r\n"
    "TILT=INCLUDE\r\n"
    "1\r\n"
    "3\r\n"
    "0 45 90\r\n"
    "1.0 0.95 0.9\r\n"
    "2 3000 0.5 5 3 1 1 2.0 -1.0 0.0\r\n"
    "0.9 1.0 64\r\n"
    "0,22.5,45,67.5,90\r\n"
    "0 45\r\n"
    "90\r\n"
    "2000 1800 1400 800 0\r\n"
    "2000 1700 1200 600\r\n"
    "0 2000 1600 1000 400 0\r\n"
    "\x1a";

TEST(PhotometryTest, ReadsAFileAsVendorsWriteIt) {
  ASSERT_OK_AND_ASSIGN(Photometry p, ParseIes(kVendorFile, "troffer.ies"));
  EXPECT_EQ(p.format, "IESNA:LM-63-1995");
  EXPECT_EQ(p.symmetry, Photometry::Symmetry::kQuadrant);
  ASSERT_EQ(p.gamma.size(), 5u);
  ASSERT_EQ(p.c.size(), 3u);
  // Multiplier 0.5 x ballast factor 0.9: the C45 plane's 1700 cd at 22.5 degrees.
  EXPECT_DOUBLE_EQ(p.Intensity(45, 22.5), 1700 * 0.5 * 0.9);
  EXPECT_DOUBLE_EQ(p.Intensity(-45, 22.5), 1700 * 0.5 * 0.9);  // Quadrant symmetry.
  EXPECT_DOUBLE_EQ(p.Intensity(90, 0), 2000 * 0.45);
  EXPECT_EQ(p.lamp_lumens, 6000);
  EXPECT_DOUBLE_EQ(p.width, 2 * 0.3048);    // Feet to metres.
  EXPECT_DOUBLE_EQ(p.length, -1 * 0.3048);  // Negative: as written (LM-63's round opening).
}

// The lines of a small valid file; tests break one.
std::vector<std::string> SmallIes() {
  return {"IESNA:LM-63-2002",
          "[TEST] small",
          "[MANUFAC] none",
          "TILT=NONE",
          "1 -1 1 3 1 1 2 0 0 0",
          "1 1 0",
          "0 45 90",
          "0",
          "100 80 0"};
}
std::string Join(const std::vector<std::string>& lines) { return absl::StrJoin(lines, "\n"); }

TEST(PhotometryTest, IesErrorsNameTheLineAndTheProblem) {
  ASSERT_OK(ParseIes(Join(SmallIes()), "small.ies").status());
  struct Case {
    int line;                 // 1-based line replaced (0: none).
    std::string replacement;  // "<drop>": the line removed.
    std::vector<std::string> expected;
  };
  for (const Case& k : std::vector<Case>{
           {9, "100 abc 0", {"small.ies:9:", "'abc' is not a number"}},
           {9, "<drop>", {"small.ies:8:", "ends before", "candela"}},
           {9, "100 80 0 7", {"small.ies:9:", "'7' after the last candela value"}},
           {9, "100 -80 0", {"small.ies:9:", "negative"}},
           {7, "0 90 45", {"small.ies:7:", "45 follows 90"}},
           {7, "0 45 190", {"small.ies:7:", "outside [0, 180]"}},
           {5, "1 -1 1 3 1 2 2 0 0 0", {"small.ies:5:", "type B", "type C"}},
           {5, "1 -1 1 100000 1 1 2 0 0 0", {"small.ies:5:", "vertical angles 100000"}},
           {5, "1 -1 0 3 1 1 2 0 0 0", {"small.ies:5:", "multiplier 0"}},
           {5, "1 -1 1 3 1 1 3 0 0 0", {"small.ies:5:", "units type 3"}},
           {4, "TILT=lamp.tlt", {"small.ies:4:", "TILT=NONE and TILT=INCLUDE"}},
           {4, "<drop>", {"small.ies:", "no TILT= line"}},
       }) {
    std::vector<std::string> lines = SmallIes();
    if (k.replacement == "<drop>") {
      lines.erase(lines.begin() + (k.line - 1));
    } else {
      lines[k.line - 1] = k.replacement;
    }
    SCOPED_TRACE(Join(lines));
    const absl::Status st = ParseIes(Join(lines), "small.ies").status();
    EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument);
    for (const std::string& word : k.expected) {
      EXPECT_NE(st.message().find(word), absl::string_view::npos) << st.message() << "\n" << word;
    }
  }
  // Horizontal angles that are no symmetry LM-63 knows.
  std::vector<std::string> lines = SmallIes();
  lines[4] = "1 -1 1 3 2 1 2 0 0 0";
  lines[7] = "0 120";
  lines[8] = "100 80 0 100 80 0";
  EXPECT_TRUE(testing::Refused(ParseIes(Join(lines), "small.ies").status(),
                               absl::StatusCode::kInvalidArgument,
                               {"small.ies:8:", "from 0 to 120", "0 to 90, 0 to 180"}));
}

TEST(PhotometryTest, EulumdatErrorsNameTheLineAndTheProblem) {
  const CandelaTable full = Tabulate(Angles(0, 90, 270), Angles(0, 45, 180), Quadrant);
  const std::string good = LdtText(full, 4);
  ASSERT_OK(ParseEulumdat(good, "q.ldt").status());
  std::vector<std::string> lines = absl::StrSplit(good, '\n');
  auto with = [&](int line, const std::string& text) {
    std::vector<std::string> copy = lines;
    copy[line - 1] = text;
    return Join(copy);
  };
  EXPECT_TRUE(testing::Refused(ParseEulumdat(with(4, "four"), "q.ldt").status(),
                               absl::StatusCode::kInvalidArgument,
                               {"q.ldt:4:", "'four' is not a number", "Mc"}));
  EXPECT_TRUE(testing::Refused(ParseEulumdat(with(3, "7"), "q.ldt").status(),
                               absl::StatusCode::kInvalidArgument, {"q.ldt:3:", "Isym 7"}));
  // Lamp flux: line 26 + 2 x 1 set + 1.
  EXPECT_TRUE(testing::Refused(ParseEulumdat(with(29, "0"), "q.ldt").status(),
                               absl::StatusCode::kInvalidArgument, {"q.ldt:29:", "flux is 0"}));
  // The first intensity: after 42 header lines, 4 C angles and 5 gamma angles.
  EXPECT_TRUE(testing::Refused(ParseEulumdat(with(52, "-3"), "q.ldt").status(),
                               absl::StatusCode::kInvalidArgument, {"q.ldt:52:", "negative"}));
  EXPECT_TRUE(testing::Refused(ParseEulumdat(with(49, "30"), "q.ldt").status(),
                               absl::StatusCode::kInvalidArgument,
                               {"q.ldt:49:", "gamma angle 30 follows 45"}));
  std::vector<std::string> cut(lines.begin(), lines.begin() + 50);
  EXPECT_TRUE(testing::Refused(ParseEulumdat(Join(cut), "q.ldt").status(),
                               absl::StatusCode::kInvalidArgument, {"q.ldt:50:", "ends before"}));
}

TEST(PhotometryTest, LoadPhotometryNamesTheFile) {
  EXPECT_TRUE(testing::Refused(LoadPhotometry("/nonexistent/lamp.ies", "lamp.ies").status(),
                               absl::StatusCode::kNotFound, {"lamp.ies"}));
  EXPECT_TRUE(testing::Refused(LoadPhotometry("/etc/hostname").status(),
                               absl::StatusCode::kInvalidArgument, {".ies or .ldt"}));
}

}  // namespace
}  // namespace radiosity
