// Writing JSON (RFC 8259) by hand for the small documents the project writes (summary.json, the
// service's log lines and CLI output): string literals, numbers, and an ordered object.
#ifndef RADIOSITY_SOLVER_UTIL_JSON_H_
#define RADIOSITY_SOLVER_UTIL_JSON_H_

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/string_view.h"

namespace radiosity {

// A JSON string literal (quotes included) with the escapes RFC 8259 requires.
std::string JsonQuote(absl::string_view s);
// A JSON number with 10 significant digits, or null when not finite.
std::string JsonNumber(double v);

// An object whose members keep the order they were added in.
class JsonObject {
 public:
  JsonObject& Add(absl::string_view key, absl::string_view text_value);  // A string member.
  JsonObject& Add(absl::string_view key, const char* text_value) {
    return Add(key, absl::string_view(text_value));
  }
  JsonObject& Add(absl::string_view key, double value);
  JsonObject& Add(absl::string_view key, int64_t value);
  JsonObject& Add(absl::string_view key, int value) { return Add(key, int64_t{value}); }
  // A member whose value is already JSON (an array, an object).
  JsonObject& AddRaw(absl::string_view key, std::string json);
  // A string array.
  JsonObject& Add(absl::string_view key, const std::vector<std::string>& values);
  // "{\n  "key": value,\n ...}\n" (indented by two spaces, one member a line).
  std::string Format() const;

 private:
  std::vector<std::pair<std::string, std::string>> members_;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_UTIL_JSON_H_
