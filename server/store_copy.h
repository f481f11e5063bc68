// Moving one server's data directory to replicas: its SQLite store's scenes and jobs into a
// PostgreSQL store, their files into a blob directory (radiosity-server --copy-from,
// docs/service/stores.md).
#ifndef RADIOSITY_SERVER_STORE_COPY_H_
#define RADIOSITY_SERVER_STORE_COPY_H_

#include <atomic>
#include <cstdint>
#include <string>

#include "absl/status/status.h"

namespace radiosity::service {

struct CopyReport {
  int64_t scenes = 0, jobs = 0;                  // Copied now.
  int64_t scenes_present = 0, jobs_present = 0;  // Found already copied (an earlier run).
  int64_t bytes = 0;                             // Of the files copied now.
  std::string ToString() const;
};

// Copies the data directory `from_dir` of a stopped server (its lock is taken for the copy: a
// running server is refused) into the store `to_store` (a store replicas share: PostgreSQL) and
// the blob directory `blob_dir`, oldest rows first, files before the row that names them (each
// directory copied under a temporary name and renamed). The source is only read. Rows already in
// the target with the same id are left as they are, so a copy that was interrupted (`stop`, a
// full disk, a lost connection) is finished by running it again. A scene's files are checked
// against their upload's checksums once copied. Jobs keep their state: one that was running when
// the old server stopped is claimed by a replica and resumes from its checkpoint.
absl::Status CopyDataDir(const std::string& from_dir, const std::string& to_store,
                         const std::string& blob_dir, const std::atomic<bool>* stop,
                         CopyReport* report);

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_STORE_COPY_H_
