// A throwaway PostgreSQL for the tests of the PostgreSQL store: initdb and pg_ctl (Debian's
// postgresql package) in a temporary directory, listening on a Unix socket there only (no TCP),
// trust authentication, fsync off. PostgreSQL refuses to run as root, so as root the cluster
// belongs to `nobody` and its programs run through runuser. One cluster per test process, made on
// first use and stopped at exit; each test takes a database of its own.
#ifndef RADIOSITY_TESTS_TESTING_POSTGRES_H_
#define RADIOSITY_TESTS_TESTING_POSTGRES_H_

#include <string>

#include "absl/status/statusor.h"

namespace radiosity::testing {

class ThrowawayPostgres {
 public:
  // The process's cluster, started on the first call; NOT_FOUND when PostgreSQL's programs are
  // not installed (the tests skip, saying so), another error when it would not start.
  static absl::StatusOr<ThrowawayPostgres*> Shared();
  ~ThrowawayPostgres();

  // A new, empty database's connection URI (postgresql:///NAME?host=SOCKET_DIR&user=...).
  absl::StatusOr<std::string> NewDatabase();
  // Runs one SQL command as the superuser on the database of `uri`; for tests that alter what
  // the store wrote.
  absl::Status Exec(const std::string& uri, const std::string& sql);
  const std::string& socket_dir() const { return dir_; }

 private:
  ThrowawayPostgres() = default;
  absl::Status Start();
  std::string bin_;     // The directory of initdb and pg_ctl.
  std::string dir_;     // The cluster (dir_/data), its log and its socket.
  std::string run_as_;  // "runuser -u nobody -- " as root, else "".
  int databases_ = 0;
  bool started_ = false;
};

}  // namespace radiosity::testing

#endif  // RADIOSITY_TESTS_TESTING_POSTGRES_H_
