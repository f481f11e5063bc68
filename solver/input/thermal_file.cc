#include "solver/input/thermal_file.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <set>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "solver/input/obj_loader.h"
#include "solver/util/file_io.h"

namespace radiosity {

namespace {

// Splits one CSV line into fields (RFC 4180 quoting); false on an unterminated quote or text after
// a closing quote.
bool SplitCsvLine(absl::string_view line, std::vector<std::string>* fields) {
  fields->clear();
  std::string field;
  size_t k = 0;
  while (true) {
    field.clear();
    if (k < line.size() && line[k] == '"') {
      ++k;
      while (true) {
        if (k >= line.size()) return false;
        if (line[k] == '"') {
          if (k + 1 < line.size() && line[k + 1] == '"') {
            field.push_back('"');
            k += 2;
            continue;
          }
          ++k;
          break;
        }
        field.push_back(line[k++]);
      }
      if (k < line.size() && line[k] != ',') return false;
    } else {
      while (k < line.size() && line[k] != ',') field.push_back(line[k++]);
      field = std::string(absl::StripAsciiWhitespace(field));
    }
    fields->push_back(field);
    if (k >= line.size()) return true;
    ++k;  // The comma.
  }
}

}  // namespace

absl::StatusOr<std::vector<SurfaceThermal>> ParseThermal(const std::string& text,
                                                         const std::string& source) {
  if (absl::Status s = CheckText(text, source); !s.ok()) return s;
  absl::string_view body = text;
  absl::ConsumePrefix(&body, "\xEF\xBB\xBF");  // A UTF-8 byte order mark (spreadsheets).
  std::vector<SurfaceThermal> out;
  std::set<std::string> seen;
  bool header = false;
  int line_no = 0;
  std::vector<std::string> fields;
  for (absl::string_view line : absl::StrSplit(body, '\n')) {
    ++line_no;
    absl::ConsumeSuffix(&line, "\r");
    const absl::string_view bare = absl::StripAsciiWhitespace(line);
    if (bare.empty() || bare[0] == '#') continue;
    const std::string where = absl::StrCat(source, ":", line_no, ": ");
    if (!SplitCsvLine(line, &fields)) {
      return absl::InvalidArgumentError(absl::StrCat(where, "badly quoted field"));
    }
    if (!header) {
      if (fields != std::vector<std::string>{"surface", "emissivity", "temperature"}) {
        return absl::InvalidArgumentError(absl::StrCat(
            where, "the header must be \"surface,emissivity,temperature\", found \"", bare, "\""));
      }
      header = true;
      continue;
    }
    if (fields.size() != 3) {
      return absl::InvalidArgumentError(absl::StrCat(
          where, "expected 3 fields \"surface,emissivity,temperature\", found ", fields.size()));
    }
    SurfaceThermal t;
    t.surface = fields[0];
    if (t.surface.empty()) {
      return absl::InvalidArgumentError(absl::StrCat(where, "the surface name is empty"));
    }
    double v[2];
    for (int k = 0; k < 2; ++k) {
      const std::string& field = fields[k + 1];
      char* end = nullptr;
      errno = 0;
      v[k] = std::strtod(field.c_str(), &end);
      if (field.empty() || end == field.c_str() || *end != '\0' || !std::isfinite(v[k])) {
        return absl::InvalidArgumentError(absl::StrCat(where, k == 0 ? "emissivity" : "temperature",
                                                       " '", field, "' is not a finite number"));
      }
    }
    t.emissivity = v[0];
    t.temperature = v[1];
    if (!(t.emissivity >= 0 && t.emissivity <= 1)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "emissivity ", fields[1], " is outside [0, 1]"));
    }
    if (!(t.temperature >= 0)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "temperature ", fields[2], " K is negative"));
    }
    if (!seen.insert(t.surface).second) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "surface '", t.surface, "' is named twice"));
    }
    out.push_back(std::move(t));
  }
  if (!header) {
    return absl::InvalidArgumentError(
        absl::StrCat(source, ": empty (expected the header \"surface,emissivity,temperature\")"));
  }
  if (out.empty()) return absl::InvalidArgumentError(absl::StrCat(source, ": no surfaces"));
  return out;
}

absl::StatusOr<std::vector<SurfaceThermal>> LoadThermal(const std::string& path) {
  absl::StatusOr<std::string> text = ReadWholeFile(path, "thermal data");
  if (!text.ok()) return text.status();
  return ParseThermal(*text, path);
}

}  // namespace radiosity
