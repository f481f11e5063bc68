#include "solver/input/sensors_file.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "solver/input/obj_loader.h"
#include "solver/util/file_io.h"

namespace radiosity {

absl::Status CheckSensorGridName(const std::string& name) {
  const bool ok =
      !name.empty() && name.size() <= 64 && std::all_of(name.begin(), name.end(), [](char c) {
        return absl::ascii_isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' ||
               c == '-';
      });
  if (ok) return absl::OkStatus();
  return absl::InvalidArgumentError(
      absl::StrCat("grid name '", name.substr(0, 80), "' is not 1 to 64 of A-Z a-z 0-9 _ . -"));
}

absl::StatusOr<std::vector<SensorPoint>> ParseSensors(const std::string& text,
                                                      const std::string& source) {
  if (absl::Status s = CheckText(text, source); !s.ok()) return s;
  std::vector<SensorPoint> out;
  std::string grid;
  int line_no = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_no;
    std::vector<absl::string_view> fields =
        absl::StrSplit(line, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (!fields.empty() && fields[0][0] == '#') {
      // "# grid: NAME" (or "#grid: NAME"): the points after it are in grid NAME.
      absl::string_view rest = absl::StripAsciiWhitespace(absl::StripPrefix(line, "#"));
      if (absl::ConsumePrefix(&rest, "grid:")) {
        grid = std::string(absl::StripAsciiWhitespace(rest));
        if (absl::Status st = CheckSensorGridName(grid); !st.ok()) {
          return absl::InvalidArgumentError(absl::StrCat(source, ":", line_no, ": ", st.message()));
        }
      }
      continue;
    }
    if (fields.empty()) continue;
    if (fields.size() != 6) {
      return absl::InvalidArgumentError(
          absl::StrCat(source, ":", line_no, ": expected 6 numbers \"x y z nx ny nz\", found ",
                       fields.size(), " fields"));
    }
    double v[6];
    for (int k = 0; k < 6; ++k) {
      std::string field(fields[k]);
      char* end = nullptr;
      errno = 0;
      v[k] = std::strtod(field.c_str(), &end);
      if (end == field.c_str() || *end != '\0' || !std::isfinite(v[k])) {
        return absl::InvalidArgumentError(absl::StrCat(source, ":", line_no, ": field ", k + 1,
                                                       " '", field, "' is not a finite number"));
      }
    }
    Vec3 n{v[3], v[4], v[5]};
    if (!(Length(n) > 0)) {
      return absl::InvalidArgumentError(absl::StrCat(source, ":", line_no, ": the normal (", v[3],
                                                     ", ", v[4], ", ", v[5], ") has zero length"));
    }
    out.push_back({{v[0], v[1], v[2]}, Normalize(n), grid});
  }
  if (out.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": no sensor points"));
  }
  return out;
}

absl::StatusOr<std::vector<SensorPoint>> LoadSensors(const std::string& path) {
  absl::StatusOr<std::string> text = ReadWholeFile(path, "sensors");
  if (!text.ok()) return text.status();
  return ParseSensors(*text, path);
}

}  // namespace radiosity
