#include "proto/api/names.h"

#include <chrono>
#include <random>

#include "absl/strings/str_format.h"
#include "absl/time/time.h"

namespace radiosity::service {

std::string NewId() {
  static thread_local std::mt19937_64 rng([] {
    std::random_device device;
    return (static_cast<uint64_t>(device()) << 32) ^ device() ^
           static_cast<uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
  }());
  return absl::StrFormat("%012x", rng() & 0xffffffffffffULL);
}

google::protobuf::Timestamp Now() {
  auto now = std::chrono::system_clock::now().time_since_epoch();
  auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now).count();
  google::protobuf::Timestamp t;
  t.set_seconds(ns / 1'000'000'000);
  t.set_nanos(static_cast<int32_t>(ns % 1'000'000'000));
  return t;
}

std::string TimeText(const google::protobuf::Timestamp& t) {
  if (t.seconds() == 0 && t.nanos() == 0) return "";
  absl::Time time = absl::FromUnixSeconds(t.seconds()) + absl::Nanoseconds(t.nanos());
  return absl::FormatTime("%Y-%m-%dT%H:%M:%E3SZ", time, absl::UTCTimeZone());
}

std::string IdFromName(absl::string_view name, absl::string_view collection) {
  absl::string_view id = name;
  size_t slash = name.find('/');
  if (slash != absl::string_view::npos) {
    if (name.substr(0, slash) != collection) return "";
    id = name.substr(slash + 1);
  }
  if (id.empty() || id.size() > 64) return "";
  for (char c : id) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'z') || c == '-')) return "";
  }
  return std::string(id);
}

}  // namespace radiosity::service
