#include "solver/input/photometry_file.h"

#include <cctype>
#include <cmath>
#include <string>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/str_split.h"
#include "solver/util/file_io.h"

namespace radiosity {
namespace {

constexpr double kFoot = 0.3048;  // Metres.

absl::Status Error(const std::string& name, int line, absl::string_view message) {
  if (line > 0) return absl::InvalidArgumentError(absl::StrCat(name, ":", line, ": ", message));
  return absl::InvalidArgumentError(absl::StrCat(name, ": ", message));
}

// The text's lines, without line ends (CR LF, LF or CR alone), a trailing DOS end-of-file mark
// dropped.
std::vector<absl::string_view> Lines(absl::string_view text) {
  while (!text.empty() && (text.back() == '\x1a' || text.back() == '\0')) text.remove_suffix(1);
  std::vector<absl::string_view> lines;
  size_t start = 0;
  for (size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '\n' || text[i] == '\r') {
      lines.push_back(text.substr(start, i - start));
      if (text[i] == '\r' && i + 1 < text.size() && text[i + 1] == '\n') ++i;
      start = i + 1;
    }
  }
  if (start < text.size()) lines.push_back(text.substr(start));
  return lines;
}

// IES numbers: blanks, tabs and commas separate them, across lines.
class NumberReader {
 public:
  NumberReader(const std::vector<absl::string_view>& lines, size_t first_line,
               const std::string& name)
      : name_(name) {
    for (size_t l = first_line; l < lines.size(); ++l) {
      for (absl::string_view token :
           absl::StrSplit(lines[l], absl::ByAnyChar(" \t,\x1a"), absl::SkipEmpty())) {
        tokens_.push_back({token, static_cast<int>(l + 1)});
      }
    }
  }

  // The next number, named `what` in errors.
  absl::Status Next(absl::string_view what, double* value) {
    if (next_ >= tokens_.size()) {
      return Error(name_, tokens_.empty() ? 0 : tokens_.back().line,
                   absl::StrCat("the file ends before ", what));
    }
    const Token& t = tokens_[next_++];
    if (!absl::SimpleAtod(t.text, value) || !std::isfinite(*value)) {
      return Error(name_, t.line,
                   absl::StrCat("'", t.text.substr(0, 40), "' is not a number (", what, ")"));
    }
    return absl::OkStatus();
  }
  absl::Status NextCount(absl::string_view what, int max, int* count) {
    double v = 0;
    if (absl::Status st = Next(what, &v); !st.ok()) return st;
    if (v != std::floor(v) || v < 1 || v > max) {
      return Error(name_, line(),
                   absl::StrCat(what, " ", v, " is not a whole number in [1, ", max, "]"));
    }
    *count = static_cast<int>(v);
    return absl::OkStatus();
  }
  // `count` numbers, and the line of each when `lines` is not null.
  absl::Status Read(absl::string_view what, int count, std::vector<double>* out,
                    std::vector<int>* lines = nullptr) {
    out->resize(count);
    if (lines) lines->resize(count);
    for (int i = 0; i < count; ++i) {
      if (absl::Status st = Next(what, &(*out)[i]); !st.ok()) return st;
      if (lines) (*lines)[i] = line();
    }
    return absl::OkStatus();
  }
  // The line of the last number read.
  int line() const { return next_ == 0 ? 0 : tokens_[next_ - 1].line; }
  bool done() const { return next_ >= tokens_.size(); }
  const absl::string_view rest() const { return tokens_[next_].text; }
  int rest_line() const { return tokens_[next_].line; }

 private:
  struct Token {
    absl::string_view text;
    int line;
  };
  std::string name_;
  std::vector<Token> tokens_;
  size_t next_ = 0;
};

// Fills p->symmetry and checks the grid; a failure names `line` (where the values ended).
absl::Status Finish(Photometry* p, const std::string& name, int line) {
  const std::string problem = CheckPhotometry(p);
  if (!problem.empty()) return Error(name, line, problem);
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<Photometry> ParseIes(absl::string_view text, const std::string& name) {
  const std::vector<absl::string_view> lines = Lines(text);
  Photometry p;
  p.source = name;
  p.format = "IES LM-63-1986";
  size_t l = 0;
  if (!lines.empty()) {
    const std::string first = absl::AsciiStrToUpper(absl::StripAsciiWhitespace(lines[0]));
    if (absl::StartsWith(first, "IES")) {
      p.format = std::string(absl::StripAsciiWhitespace(lines[0]));
      l = 1;
    }
  }
  // Keyword lines up to TILT=.
  for (; l < lines.size(); ++l) {
    const absl::string_view line = absl::StripAsciiWhitespace(lines[l]);
    if (absl::StartsWithIgnoreCase(line, "TILT")) break;
  }
  if (l >= lines.size()) {
    return Error(name, 0,
                 "no TILT= line: not an IES LM-63 photometric file (keywords, then TILT=NONE, "
                 "then the numbers)");
  }
  const absl::string_view tilt_line = absl::StripAsciiWhitespace(lines[l]);
  const size_t eq = tilt_line.find('=');
  const std::string tilt =
      eq == absl::string_view::npos
          ? ""
          : absl::AsciiStrToUpper(absl::StripAsciiWhitespace(tilt_line.substr(eq + 1)));
  const int tilt_line_number = static_cast<int>(l + 1);
  if (tilt != "NONE" && tilt != "INCLUDE") {
    return Error(name, tilt_line_number,
                 absl::StrCat("'", tilt_line.substr(0, 60),
                              "': only TILT=NONE and TILT=INCLUDE are read (a tilt file beside "
                              "the photometry is not)"));
  }
  NumberReader in(lines, l + 1, name);
  if (tilt == "INCLUDE") {
    double geometry = 0;
    int count = 0;
    std::vector<double> skip;
    if (absl::Status st = in.Next("the lamp-to-luminaire geometry of TILT=INCLUDE", &geometry);
        !st.ok()) {
      return st;
    }
    if (absl::Status st = in.NextCount("the number of tilt angles", kMaxPhotometryAngles, &count);
        !st.ok()) {
      return st;
    }
    if (absl::Status st = in.Read("the tilt angles and multipliers", 2 * count, &skip); !st.ok()) {
      return st;
    }
  }
  double lamps = 0, lumens = 0, multiplier = 0, type = 0, units = 0, width = 0, length = 0,
         height = 0, ballast = 0, factor = 0, watts = 0;
  int nv = 0, nh = 0;
  for (absl::Status st :
       {in.Next("the number of lamps", &lamps), in.Next("the lumens per lamp", &lumens),
        in.Next("the candela multiplier", &multiplier),
        in.NextCount("the number of vertical angles", kMaxPhotometryAngles, &nv),
        in.NextCount("the number of horizontal angles", kMaxPhotometryAngles, &nh)}) {
    if (!st.ok()) return st;
  }
  if (!(multiplier > 0)) {
    return Error(name, in.line(), absl::StrCat("candela multiplier ", multiplier, " is not > 0"));
  }
  if (static_cast<int64_t>(nv) * nh > kMaxPhotometryValues) {
    return Error(name, in.line(),
                 absl::StrCat(nv, " x ", nh, " candela values: more than ", kMaxPhotometryValues));
  }
  if (absl::Status st = in.Next("the photometric type", &type); !st.ok()) return st;
  if (type != 1) {
    return Error(name, in.line(),
                 absl::StrCat("photometric type ", type,
                              type == 2   ? " (type B, floodlights)"
                              : type == 3 ? " (type A, automotive)"
                                          : "",
                              ": only type C (1), that of building luminaires, is read"));
  }
  if (absl::Status st = in.Next("the units type", &units); !st.ok()) return st;
  if (units != 1 && units != 2) {
    return Error(name, in.line(),
                 absl::StrCat("units type ", units, ": expected 1 (feet) or 2 (metres)"));
  }
  for (absl::Status st :
       {in.Next("the luminous opening's width", &width),
        in.Next("the luminous opening's length", &length),
        in.Next("the luminous opening's height", &height), in.Next("the ballast factor", &ballast),
        in.Next("the ballast-lamp photometric factor (future use)", &factor),
        in.Next("the input watts", &watts)}) {
    if (!st.ok()) return st;
  }
  if (!(ballast > 0)) {
    return Error(name, in.line(), absl::StrCat("ballast factor ", ballast, " is not > 0"));
  }
  // LM-63-1995 and earlier: a ballast-lamp photometric factor; 2002 on: "future use", 1.
  if (!(factor > 0)) factor = 1;
  std::vector<int> gamma_lines, c_lines, candela_lines;
  if (absl::Status st = in.Read("the vertical angles", nv, &p.gamma, &gamma_lines); !st.ok()) {
    return st;
  }
  if (absl::Status st = in.Read("the horizontal angles", nh, &p.c, &c_lines); !st.ok()) return st;
  if (absl::Status st = in.Read(absl::StrCat("the ", static_cast<int64_t>(nv) * nh,
                                             " candela values (", nh, " planes of ", nv, ")"),
                                nv * nh, &p.candela, &candela_lines);
      !st.ok()) {
    return st;
  }
  // Each value checked where it stands.
  for (int j = 0; j < nv; ++j) {
    if (std::string problem = CheckPhotometryAngle("vertical", p.gamma, j, 180); !problem.empty()) {
      return Error(name, gamma_lines[j], problem);
    }
  }
  for (int i = 0; i < nh; ++i) {
    if (std::string problem = CheckPhotometryAngle("horizontal", p.c, i, 360); !problem.empty()) {
      return Error(name, c_lines[i], problem);
    }
  }
  for (size_t k = 0; k < p.candela.size(); ++k) {
    if (!(p.candela[k] >= 0)) {
      return Error(name, candela_lines[k],
                   absl::StrCat("candela value ", p.candela[k], " (C ", p.c[k / nv], ", gamma ",
                                p.gamma[k % nv], ") is negative"));
    }
  }
  const int angles_line = c_lines.front();
  if (!in.done()) {
    return Error(name, in.rest_line(),
                 absl::StrCat("'", in.rest().substr(0, 40),
                              "' after the last candela value: do the angle counts (", nv, ", ", nh,
                              ") match the values?"));
  }
  const double scale = multiplier * ballast * factor;
  for (double& v : p.candela) v *= scale;
  p.lamp_lumens = lumens > 0 ? lumens * std::max(1.0, lamps) : 0;
  const double unit = units == 1 ? kFoot : 1.0;
  p.width = width * unit;
  p.length = length * unit;
  // A Type C file's vertical angles may run from 90 to 180 (upward light only), or 0 to 90; the
  // check below refuses angles outside [0, 180].
  if (absl::Status st = Finish(&p, name, angles_line); !st.ok()) return st;
  return p;
}

absl::StatusOr<Photometry> ParseEulumdat(absl::string_view text, const std::string& name) {
  const std::vector<absl::string_view> lines = Lines(text);
  Photometry p;
  p.source = name;
  p.format = "EULUMDAT";
  size_t next = 0;  // The next line to read (0-based).
  auto number = [&](absl::string_view what, double* value) -> absl::Status {
    if (next >= lines.size()) {
      return Error(name, static_cast<int>(lines.size()),
                   absl::StrCat("the file ends before ", what, " (line ", next + 1, ")"));
    }
    std::string t(absl::StripAsciiWhitespace(lines[next++]));
    // Some writers use a decimal comma.
    if (t.find(',') != std::string::npos && t.find('.') == std::string::npos) {
      t[t.find(',')] = '.';
    }
    if (!absl::SimpleAtod(t, value) || !std::isfinite(*value)) {
      return Error(name, static_cast<int>(next),
                   absl::StrCat("'", t.substr(0, 40), "' is not a number (", what, ")"));
    }
    return absl::OkStatus();
  };
  auto count = [&](absl::string_view what, int lo, int hi, int* out) -> absl::Status {
    double v = 0;
    if (absl::Status st = number(what, &v); !st.ok()) return st;
    if (v != std::floor(v) || v < lo || v > hi) {
      return Error(name, static_cast<int>(next),
                   absl::StrCat(what, " ", v, " is not a whole number in [", lo, ", ", hi, "]"));
    }
    *out = static_cast<int>(v);
    return absl::OkStatus();
  };
  auto skip = [&](int n) { next += n; };
  int ityp = 0, isym = 0, mc = 0, ng = 0;
  double dc = 0, dg = 0;
  skip(1);  // Company.
  for (absl::Status st :
       {count("the type indicator Ityp", 0, 3, &ityp), count("the symmetry Isym", 0, 4, &isym),
        count("the number of C planes Mc", 1, kMaxPhotometryAngles, &mc),
        number("the C plane spacing Dc", &dc),
        count("the number of intensities per plane Ng", 2, kMaxPhotometryAngles, &ng),
        number("the intensity spacing Dg", &dg)}) {
    if (!st.ok()) return st;
  }
  skip(5);  // Report number, luminaire name and number, file name, date.
  double dims[9];
  const char* dim_names[9] = {
      "the luminaire's length",  "the luminaire's width",    "the luminaire's height",
      "the luminous length",     "the luminous width",       "the luminous height C0",
      "the luminous height C90", "the luminous height C180", "the luminous height C270"};
  for (int i = 0; i < 9; ++i) {
    if (absl::Status st = number(dim_names[i], &dims[i]); !st.ok()) return st;
  }
  double dff = 0, lorl = 0, conversion = 0, tilt = 0;
  int sets = 0;
  for (absl::Status st : {number("the downward flux fraction DFF", &dff),
                          number("the light output ratio LORL", &lorl),
                          number("the conversion factor for intensities", &conversion),
                          number("the tilt during measurement", &tilt),
                          count("the number of lamp sets", 1, 20, &sets)}) {
    if (!st.ok()) return st;
  }
  skip(2 * sets);  // Numbers and types of lamps.
  double flux = 0;
  for (int s = 0; s < sets; ++s) {
    double f = 0;
    if (absl::Status st = number(absl::StrCat("the luminous flux of lamp set ", s + 1), &f);
        !st.ok()) {
      return st;
    }
    flux += f;
  }
  if (!(flux > 0)) {
    return Error(name, static_cast<int>(next),
                 absl::StrCat("the lamps' flux is ", flux,
                              " lm: intensities in cd/klm cannot be converted to candela"));
  }
  skip(3 * sets);  // Colour temperature, colour rendering, wattage.
  skip(10);        // Direct ratios.
  std::vector<double> c_all(mc), g(ng);
  for (int i = 0; i < mc; ++i) {
    if (absl::Status st = number(absl::StrCat("C angle ", i + 1, " of ", mc), &c_all[i]);
        !st.ok()) {
      return st;
    }
    if (std::string problem = CheckPhotometryAngle("C", c_all, i, 360); !problem.empty()) {
      return Error(name, static_cast<int>(next), problem);
    }
  }
  for (int j = 0; j < ng; ++j) {
    if (absl::Status st = number(absl::StrCat("gamma angle ", j + 1, " of ", ng), &g[j]);
        !st.ok()) {
      return st;
    }
    if (std::string problem = CheckPhotometryAngle("gamma", g, j, 180); !problem.empty()) {
      return Error(name, static_cast<int>(next), problem);
    }
  }
  // The planes given, by the symmetry (EULUMDAT: Mc1..Mc2, 1-based).
  int mc1 = 1, mc2 = mc;
  if (isym == 1) mc2 = 1;
  if (isym == 2) mc2 = mc / 2 + 1;
  if (isym == 3) mc1 = 3 * mc / 4 + 1, mc2 = mc1 + mc / 2;
  if (isym == 4) mc2 = mc / 4 + 1;
  if ((isym >= 3 && mc % 4 != 0) || (isym == 2 && mc % 2 != 0)) {
    return Error(name, 4,
                 absl::StrCat("Mc ", mc, " planes cannot have symmetry Isym ", isym,
                              " (it needs a multiple of ", isym == 2 ? 2 : 4, ")"));
  }
  const int planes = mc2 - mc1 + 1;
  if (static_cast<int64_t>(planes) * ng > kMaxPhotometryValues) {
    return Error(name, 4,
                 absl::StrCat(planes, " x ", ng, " intensities: more than ", kMaxPhotometryValues));
  }
  std::vector<double> values(static_cast<size_t>(planes) * ng);
  for (int i = 0; i < planes; ++i) {
    for (int j = 0; j < ng; ++j) {
      if (absl::Status st = number(absl::StrCat("the intensity of plane ", mc1 + i, " at gamma ",
                                                j < static_cast<int>(g.size()) ? g[j] : 0),
                                   &values[static_cast<size_t>(i) * ng + j]);
          !st.ok()) {
        return st;
      }
      if (values[static_cast<size_t>(i) * ng + j] < 0) {
        return Error(name, static_cast<int>(next),
                     absl::StrCat("intensity ", values[static_cast<size_t>(i) * ng + j],
                                  " cd/klm is negative"));
      }
    }
  }
  const int end_line = static_cast<int>(next);
  const double scale = flux / 1000 * (conversion > 0 ? conversion : 1);
  p.gamma = g;
  auto plane_angle = [&](int one_based) {
    const int k = (one_based - 1) % mc;
    return c_all[k];
  };
  if (isym == 3) {
    // Planes C270 .. C360/0 .. C90: mirrored about the C90-C270 plane (C -> 180 - C) they cover
    // 90 .. 270, the range of the bilateral-90 symmetry, in increasing order.
    std::vector<double> c(planes), candela(values.size());
    for (int i = 0; i < planes; ++i) {
      double a = 180 - plane_angle(mc1 + i);
      c[i] = std::fmod(a + 720, 360.0);
    }
    // c decreases from 270 to 90: reverse.
    for (int i = 0; i < planes; ++i) {
      p.c.push_back(c[planes - 1 - i]);
      for (int j = 0; j < ng; ++j) {
        candela[static_cast<size_t>(i) * ng + j] =
            values[static_cast<size_t>(planes - 1 - i) * ng + j];
      }
    }
    p.candela = std::move(candela);
  } else {
    for (int i = 0; i < planes; ++i) p.c.push_back(plane_angle(mc1 + i));
    p.candela = std::move(values);
  }
  for (double& v : p.candela) v *= scale;
  p.lamp_lumens = flux;
  p.length = dims[3] / 1000;
  p.width = dims[4] > 0 ? dims[4] / 1000 : -dims[3] / 1000;  // 0: round, of diameter length.
  if (absl::Status st = Finish(&p, name, end_line); !st.ok()) return st;
  return p;
}

bool IsPhotometryFile(const std::string& path) {
  return absl::EndsWithIgnoreCase(path, ".ies") || absl::EndsWithIgnoreCase(path, ".ldt");
}

absl::StatusOr<Photometry> LoadPhotometry(const std::string& path, const std::string& name) {
  const std::string shown = name.empty() ? path : name;
  if (!IsPhotometryFile(path)) {
    return absl::InvalidArgumentError(
        absl::StrCat(shown, ": not a photometric file (expected .ies or .ldt)"));
  }
  absl::StatusOr<std::string> text = ReadWholeFile(path);
  if (!text.ok()) {
    return absl::Status(text.status().code(),
                        absl::StrReplaceAll(text.status().message(), {{path, shown}}));
  }
  if (absl::EndsWithIgnoreCase(path, ".ldt")) return ParseEulumdat(*text, shown);
  return ParseIes(*text, shown);
}

absl::StatusOr<Photometry> LoadScenePhotometry(const std::string& dir, const std::string& name,
                                               const std::string& shown_dir) {
  bool safe = !name.empty() && name[0] != '/' && name.find('\\') == std::string::npos;
  for (absl::string_view part : absl::StrSplit(name, '/')) {
    safe = safe && !part.empty() && part != "." && part != "..";
  }
  if (!safe) {
    return absl::InvalidArgumentError(absl::StrCat(
        "'", name, "': the photometric file must be a relative name among the scene's files"));
  }
  absl::StatusOr<Photometry> p = LoadPhotometry(JoinPath(dir, name), JoinPath(shown_dir, name));
  if (p.status().code() == absl::StatusCode::kNotFound) {
    return absl::FailedPreconditionError(
        absl::StrCat(name,
                     " is not among the scene's files (upload it with the scene: radiosity solve "
                     "--luminaire uploads it, the Python client's upload takes extra_files)"));
  }
  return p;
}

}  // namespace radiosity
