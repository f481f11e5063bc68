#include "solver/util/json.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace radiosity {

std::string JsonQuote(absl::string_view s) {
  std::string out = "\"";
  for (char ch : s) {
    switch (ch) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\t':
        out += "\\t";
        break;
      case '\r':
        out += "\\r";
        break;
      default:
        if (static_cast<unsigned char>(ch) < 0x20) {
          absl::StrAppendFormat(&out, "\\u%04x", static_cast<int>(ch));
        } else {
          out += ch;
        }
    }
  }
  return out + "\"";
}

std::string JsonNumber(double v) { return std::isfinite(v) ? absl::StrFormat("%.10g", v) : "null"; }

JsonObject& JsonObject::Add(absl::string_view key, absl::string_view text_value) {
  return AddRaw(key, JsonQuote(text_value));
}

JsonObject& JsonObject::Add(absl::string_view key, double value) {
  return AddRaw(key, JsonNumber(value));
}

JsonObject& JsonObject::Add(absl::string_view key, int64_t value) {
  return AddRaw(key, absl::StrCat(value));
}

JsonObject& JsonObject::Add(absl::string_view key, const std::vector<std::string>& values) {
  std::string json = "[";
  for (size_t i = 0; i < values.size(); ++i) {
    absl::StrAppend(&json, i > 0 ? ", " : "", JsonQuote(values[i]));
  }
  return AddRaw(key, json + "]");
}

JsonObject& JsonObject::AddRaw(absl::string_view key, std::string json) {
  members_.emplace_back(std::string(key), std::move(json));
  return *this;
}

std::string JsonObject::Format() const {
  std::string out = "{\n";
  for (size_t i = 0; i < members_.size(); ++i) {
    absl::StrAppend(&out, "  ", JsonQuote(members_[i].first), ": ", members_[i].second,
                    i + 1 < members_.size() ? ",\n" : "\n");
  }
  return out + "}\n";
}

}  // namespace radiosity
