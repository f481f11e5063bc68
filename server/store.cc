#include "server/store.h"

#include <fstream>
#include <regex>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "server/postgres_store.h"
#include "server/sqlite_store.h"

namespace radiosity::service {

std::string HidePassword(const std::string& uri) {
  // SCHEME://user:PASSWORD@host/... (any scheme: a misspelt one is echoed in its error),
  // ...?password=PASSWORD&... and libpq's key=value form (password=PASSWORD or 'PASS WORD').
  static const std::regex kUserInfo(R"(^([A-Za-z][A-Za-z0-9+.-]*://[^:/@]*:)[^@/]*@)");
  static const std::regex kParameter(R"(((?:^|[?&\s])password\s*=\s*)('(?:[^'\\]|\\.)*'|[^&\s]*))");
  std::string hidden = std::regex_replace(uri, kUserInfo, "$1***@");
  return std::regex_replace(hidden, kParameter, "$1***");
}

absl::StatusOr<std::unique_ptr<Store>> OpenStore(const std::string& spec,
                                                 const std::string& data_dir) {
  std::string s = spec;
  if (absl::StartsWith(s, "file:")) {
    const std::string path(absl::StripPrefix(s, "file:"));
    std::ifstream in(path);
    if (!in || !std::getline(in, s)) {
      return absl::InvalidArgumentError(
          absl::StrCat("--store ", spec, ": cannot read a store's address from ", path));
    }
    s = std::string(absl::StripAsciiWhitespace(s));
    if (s.empty()) {
      // Not the default SQLite: a secret mounted empty must not quietly move the jobs.
      return absl::InvalidArgumentError(
          absl::StrCat("--store ", spec, ": the first line of ", path, " is empty"));
    }
    if (absl::StartsWith(s, "file:")) {
      return absl::InvalidArgumentError(
          absl::StrCat("--store ", spec, ": ", path, " names another file, not a store"));
    }
  }
  absl::StatusOr<std::unique_ptr<Store>> store;
  if (s.empty() || absl::StartsWith(s, "sqlite:")) {
    std::string dir(absl::StripPrefix(s, "sqlite:"));
    if (s.empty()) dir = data_dir;
    if (dir.empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat("--store ", spec, ": name the SQLite database's directory (sqlite:DIR)"));
    }
    absl::StatusOr<std::unique_ptr<SqliteStore>> sqlite = SqliteStore::Open(dir + "/radiosity.db");
    if (!sqlite.ok()) return sqlite.status();
    return std::unique_ptr<Store>(*std::move(sqlite));
  }
  if (absl::StartsWith(s, "postgresql://") || absl::StartsWith(s, "postgres://")) {
    absl::StatusOr<std::unique_ptr<PostgresStore>> pg = PostgresStore::Open(s);
    if (!pg.ok()) return pg.status();
    return std::unique_ptr<Store>(*std::move(pg));
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "--store ", HidePassword(s), ": not a store; use sqlite:DIR, postgresql://... or file:PATH"));
}

}  // namespace radiosity::service
