// Validation of option fields: the first failed check becomes INVALID_ARGUMENT naming the field
// by a caller's label ("--tolerance" for the CLI, "solve.tolerance" for the service).
#ifndef RADIOSITY_SOLVER_UTIL_FIELD_CHECKER_H_
#define RADIOSITY_SOLVER_UTIL_FIELD_CHECKER_H_

#include <functional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/util/bounds.h"

namespace radiosity {

class FieldChecker {
 public:
  // `label` turns a field's key into its name in messages.
  explicit FieldChecker(std::function<std::string(const std::string&)> label)
      : label_(std::move(label)) {}

  // "KEY: VALUE is outside [lo, hi]".
  void InBounds(const std::string& key, double value, const Bounds& bounds);
  // "KEY: VALUE is not a positive number".
  void Positive(const std::string& key, double value);
  // "KEY: 'VALUE' is not one of a, b, c".
  void OneOf(const std::string& key, const std::string& value,
             const std::vector<std::string>& allowed);
  // "KEY: MESSAGE", unless an earlier check failed.
  void Fail(const std::string& key, const std::string& message);
  // Adopts `status` (a check done elsewhere) unless an earlier check failed.
  void Check(const absl::Status& status);

  const absl::Status& status() const { return status_; }
  std::string Label(const std::string& key) const { return label_(key); }

 private:
  std::function<std::string(const std::string&)> label_;
  absl::Status status_;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_UTIL_FIELD_CHECKER_H_
