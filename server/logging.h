// Structured logs: one JSON object per line on stderr, through spdlog, e.g.
//   {"time":"2024-05-01T10:00:00.123Z","level":"info","event":"job_started","job":"3f2a..."}
// Job, scene and request ids are passed explicitly as fields.
#ifndef RADIOSITY_SERVER_LOGGING_H_
#define RADIOSITY_SERVER_LOGGING_H_

#include <cstdint>
#include <string>

#include "absl/strings/string_view.h"

namespace radiosity::service {

// Sets the level of the shared logger: "trace", "debug", "info", "warn", "error" or "off".
// Returns false for an unknown level.
bool SetLogLevel(const std::string& level);

// Builds one log line: LogLine("job_started").Str("job", id).Int("attempt", 2).Info();
class LogLine {
 public:
  explicit LogLine(absl::string_view event);
  LogLine& Str(absl::string_view key, absl::string_view value);
  LogLine& Int(absl::string_view key, int64_t value);
  LogLine& Num(absl::string_view key, double value);
  void Info();
  void Warn();
  void Error();
  void Debug();

 private:
  std::string fields_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_LOGGING_H_
