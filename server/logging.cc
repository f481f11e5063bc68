#include "server/logging.h"

#include <cmath>
#include <memory>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/util/json.h"
#include "spdlog/sinks/stdout_sinks.h"
#include "spdlog/spdlog.h"

namespace radiosity::service {
namespace {

spdlog::logger& Logger() {
  static std::shared_ptr<spdlog::logger> logger = [] {
    auto sink = std::make_shared<spdlog::sinks::stderr_sink_mt>();
    auto l = std::make_shared<spdlog::logger>("radiosity-service", sink);
    // The message (%v) is the rest of the object's fields, already JSON.
    l->set_pattern("{\"time\":\"%Y-%m-%dT%H:%M:%S.%eZ\",\"level\":\"%l\",%v}",
                   spdlog::pattern_time_type::utc);
    l->set_level(spdlog::level::info);
    l->flush_on(spdlog::level::info);
    return l;
  }();
  return *logger;
}

}  // namespace

bool SetLogLevel(const std::string& level) {
  static const std::pair<const char*, spdlog::level::level_enum> kLevels[] = {
      {"trace", spdlog::level::trace}, {"debug", spdlog::level::debug},
      {"info", spdlog::level::info},   {"warn", spdlog::level::warn},
      {"error", spdlog::level::err},   {"off", spdlog::level::off}};
  for (const auto& [name, value] : kLevels) {
    if (level == name) {
      Logger().set_level(value);
      return true;
    }
  }
  return false;
}

LogLine::LogLine(absl::string_view event) {
  fields_ = absl::StrCat("\"event\":", JsonQuote(event));
}

LogLine& LogLine::Str(absl::string_view key, absl::string_view value) {
  absl::StrAppend(&fields_, ",", JsonQuote(key), ":", JsonQuote(value));
  return *this;
}

LogLine& LogLine::Int(absl::string_view key, int64_t value) {
  absl::StrAppend(&fields_, ",", JsonQuote(key), ":", value);
  return *this;
}

LogLine& LogLine::Num(absl::string_view key, double value) {
  absl::StrAppend(&fields_, ",", JsonQuote(key), ":",
                  std::isfinite(value) ? absl::StrFormat("%.6g", value) : std::string("null"));
  return *this;
}

void LogLine::Info() { Logger().info("{}", fields_); }
void LogLine::Warn() { Logger().warn("{}", fields_); }
void LogLine::Error() { Logger().error("{}", fields_); }
void LogLine::Debug() { Logger().debug("{}", fields_); }

}  // namespace radiosity::service
