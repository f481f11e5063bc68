#include "tests/testing/photometry_files.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace radiosity::testing {

CandelaTable Tabulate(const std::vector<double>& c, const std::vector<double>& gamma,
                      const std::function<double(double, double)>& intensity) {
  CandelaTable t{gamma, c, {}};
  for (double a : c) {
    for (double g : gamma) t.candela.push_back(intensity(a, g));
  }
  return t;
}

std::vector<double> Angles(double first, double step, double last) {
  std::vector<double> out;
  for (int k = 0; first + k * step <= last + 1e-9; ++k) out.push_back(first + k * step);
  return out;
}

namespace {

void AppendValues(std::string* out, const std::vector<double>& values) {
  for (size_t i = 0; i < values.size(); ++i) {
    absl::StrAppendFormat(out, "%.17g%s", values[i],
                          (i + 1) % 10 == 0 || i + 1 == values.size() ? "\n" : " ");
  }
}

}  // namespace

std::string IesText(const CandelaTable& t, double width, double length) {
  std::string s = "IESNA:LM-63-2002\n[TEST] radiosity test table\n[MANUFAC] none\nTILT=NONE\n";
  absl::StrAppend(&s, "1 -1 1 ", t.gamma.size(), " ", t.c.size(), " 1 2 ",
                  absl::StrFormat("%.17g %.17g", width, length), " 0\n1 1 0\n");
  AppendValues(&s, t.gamma);
  AppendValues(&s, t.c);
  AppendValues(&s, t.candela);
  return s;
}

std::string LdtText(const CandelaTable& full, int isym, double lamp_lumens, double length_mm,
                    double width_mm) {
  const int mc = static_cast<int>(full.c.size());
  const int ng = static_cast<int>(full.gamma.size());
  int mc1 = 1, mc2 = mc;
  if (isym == 1) mc2 = 1;
  if (isym == 2) mc2 = mc / 2 + 1;
  if (isym == 3) mc1 = 3 * mc / 4 + 1, mc2 = mc1 + mc / 2;
  if (isym == 4) mc2 = mc / 4 + 1;
  std::string s = "radiosity tests\n1\n";
  absl::StrAppend(&s, isym, "\n", mc, "\n", 360.0 / mc, "\n", ng, "\n",
                  ng > 1 ? full.gamma[1] - full.gamma[0] : 0, "\n");
  s += "report\nluminaire\n1\ntest.ldt\n2026-12-04\n";
  absl::StrAppend(&s, length_mm, "\n", width_mm, "\n", 0, "\n", length_mm, "\n", width_mm, "\n");
  s += "0\n0\n0\n0\n100\n80\n1\n0\n1\n1\nLED\n";
  absl::StrAppend(&s, lamp_lumens, "\n3000\n90\n10\n");
  for (int k = 0; k < 10; ++k) s += "0.5\n";
  for (double a : full.c) absl::StrAppendFormat(&s, "%.17g\n", a);
  for (double g : full.gamma) absl::StrAppendFormat(&s, "%.17g\n", g);
  for (int i = mc1; i <= mc2; ++i) {
    const int plane = (i - 1) % mc;
    for (int j = 0; j < ng; ++j) {
      absl::StrAppendFormat(&s, "%.17g\n",
                            full.candela[static_cast<size_t>(plane) * ng + j] * 1000 / lamp_lumens);
    }
  }
  return s;
}

}  // namespace radiosity::testing
