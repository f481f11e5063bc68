// What both store backends (server/sqlite_store.h, server/postgres_store.h) compute from rows the
// same way.
#ifndef RADIOSITY_SERVER_STORE_ROWS_H_
#define RADIOSITY_SERVER_STORE_ROWS_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "radiosity/v1/service.pb.h"

namespace radiosity::service {

// "1,3": the states' numbers for an SQL IN list (numbers only, so safe to splice), UNSPECIFIED
// left out; "" when none is left.
inline std::string StateList(const std::vector<v1::JobState>& states) {
  std::vector<int> codes;
  for (v1::JobState s : states) {
    if (s != v1::JOB_STATE_UNSPECIFIED) codes.push_back(static_cast<int>(s));
  }
  return absl::StrJoin(codes, ",");
}

// Bytes a job's results take (what counts towards its tenant's stored bytes).
inline int64_t ResultBytes(const v1::Job& job) {
  int64_t bytes = 0;
  for (const v1::FileInfo& f : job.results()) bytes += f.size();
  return bytes;
}

// The store's claimable states, spliced into its queries as 1 and 2.
static_assert(v1::JOB_STATE_QUEUED == 1 && v1::JOB_STATE_RUNNING == 2);

// What RenewLease and UpdateLeasedJob return when `owner` no longer holds the job.
inline absl::Status LeaseLost(const std::string& id, const std::string& owner) {
  return absl::AbortedError(absl::StrCat("jobs/", id, ": lease lost by ", owner,
                                         " (another worker claimed the job, or it ended)"));
}

// A row's stored message.
template <typename Message>
absl::StatusOr<Message> ParseRow(const std::string& bytes) {
  Message m;
  if (!m.ParseFromString(bytes)) return absl::InternalError("database: a stored row is corrupt");
  return m;
}

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_STORE_ROWS_H_
