// Test support (header only, for tests/service_*_test.cc): a real server on 127.0.0.1 with a free
// port and a data directory, plus bounded waiting.
#ifndef RADIOSITY_TESTS_SERVICE_FIXTURE_H_
#define RADIOSITY_TESTS_SERVICE_FIXTURE_H_

#include <chrono>
#include <cstdlib>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "server/server.h"

namespace radiosity::service::testing {

// Options of a test server on 127.0.0.1:0 with the given data directory. Logs are off unless
// RADIOSITY_TEST_LOG names a level.
inline ServerOptions TestServerOptions(const std::string& data_dir) {
  ServerOptions o;
  o.listen = "127.0.0.1:0";
  o.service.data_dir = data_dir;
  o.service.workers = 1;
  o.service.threads_per_job = 2;
  const char* level = std::getenv("RADIOSITY_TEST_LOG");
  o.log_level = level && *level ? level : "off";
  o.shutdown_grace_seconds = 2;
  return o;
}

// A client over TCP to a test server (never the in-process channel: the tests exercise the wire).
inline std::unique_ptr<client::Client> ConnectTo(const Server& server,
                                                 client::ClientOptions options = {}) {
  return std::make_unique<client::Client>(
      client::MakeChannel(absl::StrCat("127.0.0.1:", server.port())), options);
}

// Polls `done` every 10 ms until it holds or `seconds` pass; returns whether it held.
inline bool WaitFor(const std::function<bool()>& done, double seconds) {
  const auto end = std::chrono::steady_clock::now() +
                   std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000));
  while (std::chrono::steady_clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return done();
}

}  // namespace radiosity::service::testing

#endif  // RADIOSITY_TESTS_SERVICE_FIXTURE_H_
