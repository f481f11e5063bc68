#include "tests/testing/postgres.h"

#include <libpq-fe.h>
#include <pwd.h>
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"

namespace radiosity::testing {
namespace {

// The newest installed PostgreSQL's programs (/usr/lib/postgresql/VERSION/bin on Debian).
std::string FindBin() {
  std::vector<std::filesystem::path> found;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/usr/lib/postgresql", ec)) {
    if (std::filesystem::exists(entry.path() / "bin" / "pg_ctl")) found.push_back(entry.path());
  }
  if (found.empty()) return "";
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) {
    return std::atoi(a.filename().c_str()) < std::atoi(b.filename().c_str());
  });
  return (found.back() / "bin").string();
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

absl::StatusOr<ThrowawayPostgres*> ThrowawayPostgres::Shared() {
  static std::unique_ptr<ThrowawayPostgres> shared;
  static absl::Status status = [] {
    shared.reset(new ThrowawayPostgres());
    return shared->Start();
  }();
  if (!status.ok()) return status;
  return shared.get();
}

absl::Status ThrowawayPostgres::Start() {
  bin_ = FindBin();
  if (bin_.empty()) {
    return absl::NotFoundError(
        "PostgreSQL is not installed (no /usr/lib/postgresql/*/bin/pg_ctl; bash "
        "deploy/quickstart.sh "
        "test installs Debian's postgresql)");
  }
  char pattern[] = "/tmp/radiosity_pg_XXXXXX";
  if (mkdtemp(pattern) == nullptr) return absl::InternalError("mkdtemp failed");
  dir_ = pattern;
  if (geteuid() == 0) {
    const passwd* nobody = getpwnam("nobody");
    if (nobody == nullptr || chown(dir_.c_str(), nobody->pw_uid, nobody->pw_gid) != 0) {
      return absl::InternalError("cannot give the cluster's directory to user nobody");
    }
    run_as_ = "runuser -u nobody -- ";
  }
  const std::string initdb =
      absl::StrCat(run_as_, bin_, "/initdb -D ", dir_,
                   "/data -U radiosity -A trust -E UTF8 --no-sync > ", dir_, "/initdb.log 2>&1");
  if (std::system(initdb.c_str()) != 0) {
    return absl::InternalError(absl::StrCat("initdb failed: ", ReadFile(dir_ + "/initdb.log")));
  }
  // The socket in dir_, no TCP; fsync off (a test cluster is thrown away).
  const std::string start =
      absl::StrCat(run_as_, bin_, "/pg_ctl -D ", dir_, "/data -l ", dir_, "/server.log -w -o \"-k ",
                   dir_, " -h '' -F\" start > /dev/null 2>&1");
  if (std::system(start.c_str()) != 0) {
    return absl::InternalError(
        absl::StrCat("pg_ctl start failed: ", ReadFile(dir_ + "/server.log")));
  }
  started_ = true;
  return absl::OkStatus();
}

ThrowawayPostgres::~ThrowawayPostgres() {
  if (started_) {
    const std::string stop = absl::StrCat(run_as_, bin_, "/pg_ctl -D ", dir_,
                                          "/data -m immediate -w stop > /dev/null 2>&1");
    (void)std::system(stop.c_str());
  }
  if (!dir_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
}

absl::Status ThrowawayPostgres::Exec(const std::string& uri, const std::string& sql) {
  PGconn* conn = PQconnectdb(uri.c_str());
  absl::Status st;
  if (PQstatus(conn) != CONNECTION_OK) {
    st = absl::UnavailableError(PQerrorMessage(conn));
  } else {
    PGresult* result = PQexec(conn, sql.c_str());
    if (PQresultStatus(result) != PGRES_COMMAND_OK && PQresultStatus(result) != PGRES_TUPLES_OK) {
      st = absl::InternalError(absl::StrCat(sql, ": ", PQresultErrorMessage(result)));
    }
    PQclear(result);
  }
  PQfinish(conn);
  return st;
}

absl::StatusOr<std::string> ThrowawayPostgres::NewDatabase() {
  const std::string name = absl::StrCat("test", getpid(), "_", ++databases_);
  const std::string base = absl::StrCat("?host=", dir_, "&user=radiosity");
  if (absl::Status st = Exec("postgresql:///postgres" + base, "CREATE DATABASE " + name);
      !st.ok()) {
    return st;
  }
  return absl::StrCat("postgresql:///", name, base);
}

}  // namespace radiosity::testing
