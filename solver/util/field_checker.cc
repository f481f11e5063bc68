#include "solver/util/field_checker.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"

namespace radiosity {

namespace {

// Whole numbers as integers (1000001, not 1e+06), others with 9 significant digits.
std::string ValueText(double v) {
  if (std::isfinite(v) && v == std::floor(v) && std::fabs(v) < 9.2e18) {
    return absl::StrCat(static_cast<int64_t>(v));
  }
  return absl::StrFormat("%.9g", v);
}

}  // namespace

void FieldChecker::InBounds(const std::string& key, double value, const Bounds& bounds) {
  if (!bounds.Contains(value))
    Fail(key, absl::StrCat(ValueText(value), " is outside ", bounds.text));
}

void FieldChecker::Positive(const std::string& key, double value) {
  if (!(value > 0 && std::isfinite(value))) {
    Fail(key, absl::StrCat(ValueText(value), " is not a positive number"));
  }
}

void FieldChecker::OneOf(const std::string& key, const std::string& value,
                         const std::vector<std::string>& allowed) {
  for (const std::string& a : allowed) {
    if (value == a) return;
  }
  Fail(key, absl::StrCat("'", value, "' is not one of ", absl::StrJoin(allowed, ", ")));
}

void FieldChecker::Fail(const std::string& key, const std::string& message) {
  if (status_.ok()) status_ = absl::InvalidArgumentError(absl::StrCat(label_(key), ": ", message));
}

void FieldChecker::Check(const absl::Status& status) {
  if (status_.ok()) status_ = status;
}

}  // namespace radiosity
