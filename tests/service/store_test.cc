// The store's contract (server/store.h), the same tests against both backends: SQLite in a
// temporary directory, and PostgreSQL in a throwaway cluster (tests/testing/postgres.h).
// Rows round-trip; a request id inserts once per tenant even when two store instances (two
// replicas) race; states, counts and usage follow the rows; lists page every row once with
// tokens sealed per tenant that survive reopening; the schema version is recorded and a newer
// one refused; job leases give each job to one worker, expire, lock a late owner out, carry
// cancels, and give jobs back.
#include "server/store.h"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "server/postgres_store.h"
#include "server/sqlite_store.h"
#include "tests/testing/postgres.h"
#include "tests/testing/test_util.h"

namespace radiosity::service {
namespace {

using radiosity::testing::Refused;
using radiosity::testing::TempDir;
using radiosity::testing::ThrowawayPostgres;

// One database of one backend: its --store spec, opened as often as a test likes.
class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string Spec() const = 0;
  // Makes the database claim a schema one newer than this server knows.
  virtual absl::Status BumpSchema() = 0;
  absl::StatusOr<std::unique_ptr<Store>> Open() const { return OpenStore(Spec(), ""); }
};

class SqliteBackend : public Backend {
 public:
  std::string Spec() const override { return "sqlite:" + dir_.path(); }
  absl::Status BumpSchema() override {
    sqlite3* db = nullptr;
    absl::Status st;
    const std::string sql = absl::StrCat("PRAGMA user_version = ", SqliteStore::LatestSchema() + 1);
    if (sqlite3_open(dir_.File("radiosity.db").c_str(), &db) != SQLITE_OK ||
        sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr) != SQLITE_OK) {
      st = absl::InternalError(sqlite3_errmsg(db));
    }
    sqlite3_close(db);
    return st;
  }

 private:
  TempDir dir_;
};

class PostgresBackend : public Backend {
 public:
  PostgresBackend(ThrowawayPostgres* pg, std::string uri) : pg_(pg), uri_(std::move(uri)) {}
  std::string Spec() const override { return uri_; }
  absl::Status BumpSchema() override {
    return pg_->Exec(uri_, absl::StrCat("INSERT INTO schema_migrations(version) VALUES(",
                                        PostgresStore::LatestSchema() + 1, ")"));
  }

 private:
  ThrowawayPostgres* pg_;
  std::string uri_;
};

class StoreTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    if (GetParam() == "sqlite") {
      backend_ = std::make_unique<SqliteBackend>();
    } else {
      absl::StatusOr<ThrowawayPostgres*> pg = ThrowawayPostgres::Shared();
      if (absl::IsNotFound(pg.status())) GTEST_SKIP() << pg.status().message();
      ASSERT_OK(pg);
      ASSERT_OK_AND_ASSIGN(std::string uri, (*pg)->NewDatabase());
      backend_ = std::make_unique<PostgresBackend>(*pg, uri);
    }
    ASSERT_OK_AND_ASSIGN(store_, backend_->Open());
  }

  std::unique_ptr<Backend> backend_;
  std::unique_ptr<Store> store_;
};

// `r`'s value, or `fallback` and a failure naming the error.
template <typename T>
T ValueOr(const absl::StatusOr<T>& r, T fallback) {
  if (r.ok()) return *r;
  ADD_FAILURE() << r.status();
  return fallback;
}

v1::SceneInfo Scene(const std::string& id, const std::string& tenant,
                    const std::string& request_id = "", int64_t bytes = 0) {
  v1::SceneInfo scene;
  scene.set_name("scenes/" + id);
  scene.set_tenant(tenant);
  scene.set_request_id(request_id);
  scene.set_total_size(bytes);
  return scene;
}

v1::Job Job(const std::string& id, const std::string& scene, const std::string& tenant,
            v1::JobState state, const std::string& request_id = "") {
  v1::Job job;
  job.set_name("jobs/" + id);
  job.set_scene(scene);
  job.set_tenant(tenant);
  job.set_state(state);
  job.set_request_id(request_id);
  return job;
}

TEST_P(StoreTest, ScenesAndJobsRoundTrip) {
  const v1::SceneInfo scene = Scene("s1", "alice", "upload-1", 1234);
  ASSERT_OK_AND_ASSIGN(auto existing, store_->InsertScene("s1", scene));
  EXPECT_FALSE(existing.has_value());
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo got, store_->GetScene("s1"));
  EXPECT_EQ(got.SerializeAsString(), scene.SerializeAsString());
  EXPECT_TRUE(Refused(store_->GetScene("nope"), absl::StatusCode::kNotFound, {"scenes/nope"}));
  ASSERT_OK_AND_ASSIGN(auto found, store_->FindSceneByRequest("alice", "upload-1"));
  ASSERT_TRUE(found.has_value());
  EXPECT_EQ(found->name(), "scenes/s1");
  ASSERT_OK_AND_ASSIGN(auto other, store_->FindSceneByRequest("bob", "upload-1"));
  EXPECT_FALSE(other.has_value()) << "request ids are per tenant";
  ASSERT_OK_AND_ASSIGN(auto none, store_->FindSceneByRequest("alice", ""));
  EXPECT_FALSE(none.has_value()) << "an empty request id finds nothing";

  v1::Job job = Job("j1", "scenes/s1", "alice", v1::JOB_STATE_QUEUED, "job-1");
  ASSERT_OK_AND_ASSIGN(auto existing_job, store_->InsertJob("j1", job));
  EXPECT_FALSE(existing_job.has_value());
  job.set_state(v1::JOB_STATE_SUCCEEDED);
  job.add_results()->set_size(100);
  ASSERT_OK(store_->UpdateJob("j1", job));
  ASSERT_OK_AND_ASSIGN(v1::Job got_job, store_->GetJob("j1"));
  EXPECT_EQ(got_job.SerializeAsString(), job.SerializeAsString());
  EXPECT_TRUE(Refused(store_->GetJob("nope"), absl::StatusCode::kNotFound, {"jobs/nope"}));
  ASSERT_OK_AND_ASSIGN(auto found_job, store_->FindJobByRequest("alice", "job-1"));
  ASSERT_TRUE(found_job.has_value());
  EXPECT_EQ(found_job->state(), v1::JOB_STATE_SUCCEEDED);

  ASSERT_OK(store_->DeleteJob("j1"));
  EXPECT_EQ(store_->GetJob("j1").status().code(), absl::StatusCode::kNotFound);
  ASSERT_OK(store_->DeleteScene("s1"));
  EXPECT_EQ(store_->GetScene("s1").status().code(), absl::StatusCode::kNotFound);
}

TEST_P(StoreTest, ARequestIdInsertsOncePerTenantWhenReplicasRace) {
  // Two instances of the store on one database (two replicas), four threads each, all inserting
  // one tenant's request: one insert, and every other call returns that row.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> second, backend_->Open());
  std::atomic<int> inserted{0};
  std::vector<std::string> seen(8);
  std::vector<std::thread> threads;
  for (int t = 0; t < 8; ++t) {
    threads.emplace_back([&, t] {
      Store& store = t % 2 ? *second : *store_;
      const std::string id = absl::StrCat("s", t);
      absl::StatusOr<std::optional<v1::SceneInfo>> r =
          store.InsertScene(id, Scene(id, "alice", "upload-x"));
      if (!r.ok()) {
        seen[t] = "error: " + r.status().ToString();
      } else if (!r->has_value()) {
        ++inserted;
        seen[t] = "scenes/" + id;
      } else {
        seen[t] = (*r)->name();
      }
    });
  }
  for (auto& t : threads) t.join();
  EXPECT_EQ(inserted.load(), 1);
  EXPECT_EQ(std::set<std::string>(seen.begin(), seen.end()).size(), 1u)
      << "every call names the one row: " << seen[0] << ", " << seen[1];
  ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse list, store_->ListScenes("alice", 100, ""));
  EXPECT_EQ(list.scenes_size(), 1);
  // Another tenant's same request id is another request.
  ASSERT_OK_AND_ASSIGN(auto bobs, second->InsertScene("b", Scene("b", "bob", "upload-x")));
  EXPECT_FALSE(bobs.has_value());
  // Jobs alike.
  ASSERT_OK_AND_ASSIGN(auto first_job, store_->InsertJob("j1", Job("j1", "scenes/b", "bob",
                                                                   v1::JOB_STATE_QUEUED, "job-x")));
  EXPECT_FALSE(first_job.has_value());
  ASSERT_OK_AND_ASSIGN(auto again, second->InsertJob("j2", Job("j2", "scenes/b", "bob",
                                                               v1::JOB_STATE_QUEUED, "job-x")));
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->name(), "jobs/j1");
  // Without a request id, no deduplication.
  for (const char* id : {"j3", "j4"}) {
    ASSERT_OK_AND_ASSIGN(auto r,
                         store_->InsertJob(id, Job(id, "scenes/b", "bob", v1::JOB_STATE_QUEUED)));
    EXPECT_FALSE(r.has_value());
  }
}

TEST_P(StoreTest, StatesCountsAndUsageFollowTheRows) {
  ASSERT_OK(store_->InsertScene("s1", Scene("s1", "alice", "", 1000)).status());
  ASSERT_OK(store_->InsertScene("s2", Scene("s2", "bob", "", 20)).status());
  const v1::JobState states[] = {v1::JOB_STATE_QUEUED, v1::JOB_STATE_RUNNING,
                                 v1::JOB_STATE_SUCCEEDED, v1::JOB_STATE_QUEUED};
  for (int i = 0; i < 4; ++i) {
    const std::string id = absl::StrCat("j", i);
    ASSERT_OK(store_->InsertJob(id, Job(id, "scenes/s1", "alice", states[i])).status());
  }
  ASSERT_OK(store_->InsertJob("b1", Job("b1", "scenes/s2", "bob", v1::JOB_STATE_RUNNING)).status());
  v1::Job done = Job("j2", "scenes/s1", "alice", v1::JOB_STATE_SUCCEEDED);
  done.add_results()->set_size(300);
  done.add_results()->set_size(7);
  ASSERT_OK(store_->UpdateJob("j2", done));

  ASSERT_OK_AND_ASSIGN(std::vector<v1::Job> unfinished,
                       store_->JobsInStates({v1::JOB_STATE_QUEUED, v1::JOB_STATE_RUNNING}));
  std::vector<std::string> names;
  for (const auto& j : unfinished) names.push_back(j.name());
  EXPECT_EQ(names, (std::vector<std::string>{"jobs/j0", "jobs/j1", "jobs/j3", "jobs/b1"}))
      << "oldest first";
  ASSERT_OK_AND_ASSIGN(std::vector<v1::Job> nothing, store_->JobsInStates({}));
  EXPECT_TRUE(nothing.empty());

  ASSERT_OK_AND_ASSIGN(int64_t queued, store_->CountJobs("scenes/s1", {v1::JOB_STATE_QUEUED}));
  EXPECT_EQ(queued, 2);
  ASSERT_OK_AND_ASSIGN(int64_t all, store_->CountJobs("scenes/s1", {}));
  EXPECT_EQ(all, 4);
  // Every scene's (the replicas' queue).
  ASSERT_OK_AND_ASSIGN(int64_t running, store_->CountJobs("", {v1::JOB_STATE_RUNNING}));
  EXPECT_EQ(running, 2);
  ASSERT_OK_AND_ASSIGN(int64_t every, store_->CountJobs("", {}));
  EXPECT_EQ(every, 5);

  ASSERT_OK_AND_ASSIGN(TenantUsage alice, store_->Usage("alice"));
  EXPECT_EQ(alice.unfinished_jobs, 3);
  EXPECT_EQ(alice.stored_bytes, 1000 + 300 + 7);
  ASSERT_OK_AND_ASSIGN(TenantUsage bob, store_->Usage("bob"));
  EXPECT_EQ(bob.unfinished_jobs, 1);
  EXPECT_EQ(bob.stored_bytes, 20);
  ASSERT_OK_AND_ASSIGN(TenantUsage nobody, store_->Usage("carol"));
  EXPECT_EQ(nobody.unfinished_jobs, 0);
  EXPECT_EQ(nobody.stored_bytes, 0);
  ASSERT_OK_AND_ASSIGN(int64_t total, store_->TotalBytes());
  EXPECT_EQ(total, 1000 + 20 + 300 + 7);
}

TEST_P(StoreTest, JobListsFilterAndPageEveryRowOnce) {
  for (int i = 0; i < 23; ++i) {
    const std::string id = absl::StrCat("j", i);
    const std::string tenant = i % 3 == 0 ? "bob" : "alice";
    ASSERT_OK(store_
                  ->InsertJob(id, Job(id, i % 2 ? "scenes/a" : "scenes/b", tenant,
                                      i % 4 == 0 ? v1::JOB_STATE_SUCCEEDED : v1::JOB_STATE_QUEUED))
                  .status());
  }
  for (bool filtered : {false, true}) {
    std::vector<std::string> want;
    for (int i = 22; i >= 0; --i) {
      if (i % 3 == 0) continue;
      if (filtered && !(i % 2 && i % 4 != 0)) continue;
      want.push_back(absl::StrCat("jobs/j", i));
    }
    std::vector<std::string> got;
    v1::ListJobsRequest request;
    request.set_page_size(4);
    if (filtered) {
      request.set_scene("scenes/a");
      request.add_states(v1::JOB_STATE_QUEUED);
    }
    do {
      ASSERT_OK_AND_ASSIGN(v1::ListJobsResponse page, store_->ListJobs("alice", request));
      EXPECT_LE(page.jobs_size(), 4);
      for (const auto& j : page.jobs()) got.push_back(j.name());
      request.set_page_token(page.next_page_token());
    } while (!request.page_token().empty() && got.size() < 50);
    EXPECT_EQ(got, want) << (filtered ? "scene and state filtered" : "all of alice's");
  }
}

TEST_P(StoreTest, PageTokensAreSealedPerTenantAndSurviveReopening) {
  for (int i = 0; i < 3; ++i) {
    ASSERT_OK(
        store_->InsertScene(absl::StrCat("a", i), Scene(absl::StrCat("a", i), "alice")).status());
  }
  ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse page, store_->ListScenes("alice", 1, ""));
  ASSERT_EQ(page.scenes_size(), 1);
  EXPECT_EQ(page.scenes(0).name(), "scenes/a2");
  const std::string token = page.next_page_token();
  ASSERT_FALSE(token.empty());
  int64_t number = 0;
  EXPECT_FALSE(absl::SimpleAtoi(token, &number)) << "a plain row number: " << token;

  // Bob's rows between Alice's pages change neither her token nor what it lists.
  for (int i = 0; i < 5; ++i) {
    ASSERT_OK(
        store_->InsertScene(absl::StrCat("b", i), Scene(absl::StrCat("b", i), "bob")).status());
  }
  ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse again, store_->ListScenes("alice", 1, ""));
  EXPECT_EQ(again.next_page_token(), token);
  // Bob cannot use Alice's token, nor anyone an altered one.
  EXPECT_TRUE(Refused(store_->ListScenes("bob", 1, token), absl::StatusCode::kInvalidArgument,
                      {"page_token"}));
  std::string altered = token;
  altered[5] = altered[5] == '0' ? '1' : '0';
  EXPECT_EQ(store_->ListScenes("alice", 1, altered).status().code(),
            absl::StatusCode::kInvalidArgument);
  v1::ListJobsRequest jobs;
  jobs.set_page_token(token);
  EXPECT_OK(store_->ListJobs("alice", jobs)) << "a scenes token is a position, as any";
  EXPECT_EQ(store_->ListJobs("bob", jobs).status().code(), absl::StatusCode::kInvalidArgument);

  // The key is kept in the database: the token pages on another instance (a restart, or
  // another replica).
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> reopened, backend_->Open());
  ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse rest, reopened->ListScenes("alice", 10, token));
  ASSERT_EQ(rest.scenes_size(), 2);
  EXPECT_EQ(rest.scenes(0).name(), "scenes/a1");
  EXPECT_EQ(rest.scenes(1).name(), "scenes/a0");
  EXPECT_TRUE(rest.next_page_token().empty());
}

TEST_P(StoreTest, ClaimsGiveEachJobToOneWorkerAcrossReplicas) {
  // Two store instances (two replicas), four workers each, claiming until the queue is empty and
  // ending each job they claim: every job is claimed once, and nothing is left leased.
  constexpr int kJobs = 200;
  for (int i = 0; i < kJobs; ++i) {
    const std::string id = absl::StrCat("j", i);
    ASSERT_OK(store_->InsertJob(id, Job(id, "scenes/s", "", v1::JOB_STATE_QUEUED)).status());
  }
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> second, backend_->Open());
  std::mutex mu;
  std::vector<std::string> claimed, errors;
  std::vector<std::thread> workers;
  for (int w = 0; w < 8; ++w) {
    workers.emplace_back([&, w] {
      Store& store = w % 2 ? *second : *store_;
      const std::string owner = absl::StrCat("worker-", w);
      for (;;) {
        absl::StatusOr<std::optional<Store::Claim>> claim = store.ClaimJob(owner, absl::Minutes(1));
        absl::Status st = claim.status();
        if (st.ok() && !claim->has_value()) return;
        if (st.ok()) {
          v1::Job job = (*claim)->job;
          job.set_state(v1::JOB_STATE_SUCCEEDED);
          st = store.UpdateLeasedJob(job.name().substr(5), owner, job);  // After "jobs/".
        }
        std::lock_guard<std::mutex> lock(mu);
        if (!st.ok()) {
          errors.push_back(st.ToString());
          return;
        }
        claimed.push_back((*claim)->job.name());
      }
    });
  }
  for (auto& w : workers) w.join();
  EXPECT_TRUE(errors.empty()) << errors.front();
  EXPECT_EQ(claimed.size(), static_cast<size_t>(kJobs));
  EXPECT_EQ(std::set<std::string>(claimed.begin(), claimed.end()).size(),
            static_cast<size_t>(kJobs))
      << "a job was claimed twice";
  ASSERT_OK_AND_ASSIGN(std::vector<v1::Job> done, store_->JobsInStates({v1::JOB_STATE_SUCCEEDED}));
  EXPECT_EQ(done.size(), static_cast<size_t>(kJobs));
  EXPECT_EQ(ValueOr(store_->CountLeased(), int64_t{-1}), 0);
  ASSERT_OK_AND_ASSIGN(auto none, second->ClaimJob("late", absl::Minutes(1)));
  EXPECT_FALSE(none.has_value());
}

TEST_P(StoreTest, ClaimsTakeTheOldestJobFirst) {
  for (const char* id : {"a", "b", "c"}) {
    ASSERT_OK(store_->InsertJob(id, Job(id, "scenes/s", "", v1::JOB_STATE_QUEUED)).status());
  }
  ASSERT_OK(store_->UpdateJob("a", Job("a", "scenes/s", "", v1::JOB_STATE_CANCELLED)));
  for (const char* expected : {"jobs/b", "jobs/c"}) {
    ASSERT_OK_AND_ASSIGN(auto claim, store_->ClaimJob("w", absl::Minutes(1)));
    ASSERT_TRUE(claim.has_value());
    EXPECT_EQ(claim->job.name(), expected);
  }
}

TEST_P(StoreTest, AnExpiredLeaseIsClaimedAgainAndLocksItsOldOwnerOut) {
  ASSERT_OK(store_->InsertJob("j", Job("j", "scenes/s", "", v1::JOB_STATE_QUEUED)).status());
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> other, backend_->Open());
  ASSERT_OK_AND_ASSIGN(auto a, store_->ClaimJob("a", absl::Minutes(1)));
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->job.state(), v1::JOB_STATE_QUEUED);
  v1::Job running = a->job;
  running.set_state(v1::JOB_STATE_RUNNING);
  running.set_attempts(1);
  ASSERT_OK(store_->UpdateLeasedJob("j", "a", running));
  // Held: nobody else gets it.
  ASSERT_OK_AND_ASSIGN(auto held, other->ClaimJob("b", absl::Minutes(1)));
  EXPECT_FALSE(held.has_value());
  EXPECT_EQ(ValueOr(store_->CountLeased(), int64_t{-1}), 1);
  ASSERT_OK_AND_ASSIGN(bool cancel, store_->RenewLease("j", "a", absl::Minutes(1)));
  EXPECT_FALSE(cancel);

  // Its worker stops renewing (here: renews for a millisecond, and is silent after).
  ASSERT_OK(store_->RenewLease("j", "a", absl::Milliseconds(1)).status());
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_EQ(ValueOr(store_->CountLeased(), int64_t{-1}), 0);
  ASSERT_OK_AND_ASSIGN(auto b, other->ClaimJob("b", absl::Minutes(1)));
  ASSERT_TRUE(b.has_value());
  EXPECT_EQ(b->job.SerializeAsString(), running.SerializeAsString()) << "as its last owner left it";

  // The old owner can neither renew nor write: nothing it writes lands.
  EXPECT_TRUE(Refused(store_->RenewLease("j", "a", absl::Minutes(1)), absl::StatusCode::kAborted,
                      {"jobs/j", "lease lost"}));
  v1::Job late = running;
  late.set_state(v1::JOB_STATE_SUCCEEDED);
  EXPECT_TRUE(
      Refused(store_->UpdateLeasedJob("j", "a", late), absl::StatusCode::kAborted, {"lease lost"}));
  EXPECT_EQ(ValueOr(store_->GetJob("j"), v1::Job()).state(), v1::JOB_STATE_RUNNING);

  // The new owner ends it; the lease ends with it.
  v1::Job ended = running;
  ended.set_state(v1::JOB_STATE_FAILED);
  ASSERT_OK(other->UpdateLeasedJob("j", "b", ended));
  EXPECT_EQ(ValueOr(store_->GetJob("j"), v1::Job()).state(), v1::JOB_STATE_FAILED);
  EXPECT_TRUE(Refused(other->RenewLease("j", "b", absl::Minutes(1)), absl::StatusCode::kAborted,
                      {"lease lost"}));
  EXPECT_EQ(ValueOr(store_->CountLeased(), int64_t{-1}), 0);
  ASSERT_OK_AND_ASSIGN(auto none, store_->ClaimJob("c", absl::Minutes(1)));
  EXPECT_FALSE(none.has_value());
}

TEST_P(StoreTest, ACancelReachesTheHolderAndAJobGivenBackIsClaimedAgain) {
  for (const char* id : {"j1", "j2", "j3"}) {
    ASSERT_OK(store_->InsertJob(id, Job(id, "scenes/s", "", v1::JOB_STATE_QUEUED)).status());
  }
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> other, backend_->Open());
  // A cancel asked on one replica reaches the holder on another at its next renewal.
  ASSERT_OK_AND_ASSIGN(auto j1, store_->ClaimJob("a", absl::Minutes(1)));
  ASSERT_TRUE(j1.has_value());
  EXPECT_FALSE(j1->cancel_requested);
  EXPECT_FALSE(ValueOr(store_->RenewLease("j1", "a", absl::Minutes(1)), true));
  ASSERT_OK(other->RequestCancel("j1"));
  EXPECT_TRUE(ValueOr(store_->RenewLease("j1", "a", absl::Minutes(1)), false));
  // The job ended by the API (UpdateJob): its lease ends with it, and the holder can neither
  // renew nor write it back.
  v1::Job cancelled = j1->job;
  cancelled.set_state(v1::JOB_STATE_CANCELLED);
  ASSERT_OK(other->UpdateJob("j1", cancelled));
  EXPECT_EQ(ValueOr(store_->CountLeased(), int64_t{-1}), 0);
  EXPECT_TRUE(Refused(store_->RenewLease("j1", "a", absl::Minutes(1)), absl::StatusCode::kAborted,
                      {"lease lost"}));
  v1::Job revived = j1->job;
  revived.set_state(v1::JOB_STATE_RUNNING);
  EXPECT_TRUE(Refused(store_->UpdateLeasedJob("j1", "a", revived), absl::StatusCode::kAborted,
                      {"lease lost"}));
  EXPECT_EQ(ValueOr(store_->GetJob("j1"), v1::Job()).state(), v1::JOB_STATE_CANCELLED);
  EXPECT_TRUE(Refused(other->RequestCancel("nope"), absl::StatusCode::kNotFound, {"jobs/nope"}));

  // A job given back (QUEUED, say by a server draining for shutdown) is claimable at once.
  ASSERT_OK_AND_ASSIGN(auto j2, store_->ClaimJob("a", absl::Minutes(1)));
  ASSERT_TRUE(j2.has_value());
  EXPECT_EQ(j2->job.name(), "jobs/j2");
  ASSERT_OK(store_->UpdateLeasedJob("j2", "a", j2->job));
  ASSERT_OK_AND_ASSIGN(auto again, other->ClaimJob("b", absl::Minutes(1)));
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->job.name(), "jobs/j2");

  // A cancel asked before the claim comes with it.
  ASSERT_OK(store_->RequestCancel("j3"));
  ASSERT_OK_AND_ASSIGN(auto j3, other->ClaimJob("b", absl::Minutes(1)));
  ASSERT_TRUE(j3.has_value());
  EXPECT_EQ(j3->job.name(), "jobs/j3");
  EXPECT_TRUE(j3->cancel_requested);
}

// ClaimJobById (how a cancel on any replica ends a waiting job at once): only that job, only
// while nobody holds an unexpired lease on it, never once it has ended.
TEST_P(StoreTest, AClaimByIdTakesThatJobOnlyWhenNobodyHoldsIt) {
  for (const char* id : {"j1", "j2"}) {
    ASSERT_OK(store_->InsertJob(id, Job(id, "scenes/s", "", v1::JOB_STATE_QUEUED)).status());
  }
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> other, backend_->Open());
  // Not the oldest: the one named.
  ASSERT_OK_AND_ASSIGN(auto j2, store_->ClaimJobById("j2", "a", absl::Minutes(1)));
  ASSERT_TRUE(j2.has_value());
  EXPECT_EQ(j2->job.name(), "jobs/j2");
  // Held: not for anyone else, by id or otherwise.
  ASSERT_OK_AND_ASSIGN(auto held, other->ClaimJobById("j2", "b", absl::Minutes(1)));
  EXPECT_FALSE(held.has_value());
  ASSERT_OK_AND_ASSIGN(auto next, other->ClaimJob("b", absl::Minutes(1)));
  ASSERT_TRUE(next.has_value());
  EXPECT_EQ(next->job.name(), "jobs/j1");
  // Its holder's lease runs out: claimable by id again.
  ASSERT_OK(store_->RenewLease("j2", "a", absl::Milliseconds(1)).status());
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  ASSERT_OK_AND_ASSIGN(auto taken, other->ClaimJobById("j2", "b", absl::Minutes(1)));
  ASSERT_TRUE(taken.has_value());
  // Ended (the lease with it): never claimed again.
  v1::Job ended = taken->job;
  ended.set_state(v1::JOB_STATE_CANCELLED);
  ASSERT_OK(other->UpdateLeasedJob("j2", "b", ended));
  ASSERT_OK_AND_ASSIGN(auto none, store_->ClaimJobById("j2", "c", absl::Minutes(1)));
  EXPECT_FALSE(none.has_value());
  ASSERT_OK_AND_ASSIGN(auto absent, store_->ClaimJobById("nope", "c", absl::Minutes(1)));
  EXPECT_FALSE(absent.has_value());
  EXPECT_EQ(ValueOr(store_->CountLeased(), int64_t{-1}), 1);  // j1, still b's.
}

TEST_P(StoreTest, TheSchemaVersionIsRecordedAndANewerOneRefused) {
  const int latest =
      GetParam() == "sqlite" ? SqliteStore::LatestSchema() : PostgresStore::LatestSchema();
  EXPECT_EQ(store_->SchemaVersion(), latest);
  ASSERT_OK(store_->InsertScene("s1", Scene("s1", "")).status());
  store_.reset();
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> reopened, backend_->Open());
  EXPECT_EQ(reopened->SchemaVersion(), latest) << "no migration runs twice";
  EXPECT_OK(reopened->GetScene("s1"));
  reopened.reset();
  ASSERT_OK(backend_->BumpSchema());
  EXPECT_TRUE(Refused(backend_->Open(), absl::StatusCode::kFailedPrecondition,
                      {"schema version", "newer"}));
}

INSTANTIATE_TEST_SUITE_P(Backends, StoreTest, ::testing::Values("sqlite", "postgresql"),
                         [](const auto& param_info) { return param_info.param; });

TEST_P(StoreTest, OneServerClaimsTheStore) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> second, backend_->Open());
  ASSERT_OK(store_->ClaimExclusive());
  EXPECT_TRUE(Refused(second->ClaimExclusive(), absl::StatusCode::kFailedPrecondition,
                      {"another radiosity-server"}));
  store_.reset();  // It closes (its connection or lock file), and the claim with it.
  EXPECT_OK(second->ClaimExclusive());
}

TEST(PostgresStoreTest, AReconnectedServerTakesItsClaimBackBeforeItsNextQuery) {
  absl::StatusOr<ThrowawayPostgres*> pg = ThrowawayPostgres::Shared();
  if (absl::IsNotFound(pg.status())) GTEST_SKIP() << pg.status().message();
  ASSERT_OK(pg);
  ASSERT_OK_AND_ASSIGN(std::string uri, (*pg)->NewDatabase());
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> server, OpenStore(uri, ""));
  ASSERT_OK(server->ClaimExclusive());
  // Its session ends (a PostgreSQL restart, an administrator): the claim goes with it.
  ASSERT_OK((*pg)->Exec(uri,
                        "SELECT pg_terminate_backend(pid) FROM pg_stat_activity"
                        " WHERE datname = current_database() AND pid <> pg_backend_pid()"));
  // The next query reconnects and takes the claim again before it runs...
  EXPECT_EQ(server->GetJob("nope").status().code(), absl::StatusCode::kNotFound);
  // ...so another server is still refused.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> other, OpenStore(uri, ""));
  EXPECT_TRUE(Refused(other->ClaimExclusive(), absl::StatusCode::kFailedPrecondition,
                      {"another radiosity-server"}));
}

TEST(OpenStoreTest, SpecsAreReadOrRefusedByName) {
  TempDir dir;
  EXPECT_TRUE(Refused(OpenStore("mysql://x", dir.path()), absl::StatusCode::kInvalidArgument,
                      {"mysql://x", "sqlite:DIR", "postgresql://"}));
  // The default: SQLite in the data directory.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> store, OpenStore("", dir.path()));
  EXPECT_EQ(store->ToString(), "sqlite:" + dir.File("radiosity.db"));
  store.reset();
  // file:PATH holds the spec (a mounted secret), its line's spaces and newline trimmed.
  TempDir other;
  const std::string secret = dir.Write("store.secret", " sqlite:" + other.path() + " \n");
  ASSERT_OK_AND_ASSIGN(store, OpenStore("file:" + secret, dir.path()));
  EXPECT_EQ(store->ToString(), "sqlite:" + other.File("radiosity.db"));
  EXPECT_TRUE(Refused(OpenStore("file:" + dir.File("absent"), dir.path()),
                      absl::StatusCode::kInvalidArgument, {"absent"}));
  // A secret mounted empty is refused, not read as the default SQLite.
  const std::string empty = dir.Write("empty.secret", "\n");
  EXPECT_TRUE(Refused(OpenStore("file:" + empty, dir.path()), absl::StatusCode::kInvalidArgument,
                      {"empty.secret", "empty"}));
  // A PostgreSQL that is not there: UNAVAILABLE, naming the address without its password.
  absl::StatusOr<std::unique_ptr<Store>> pg =
      OpenStore("postgresql://radiosity:hunter2@/nodb?host=" + dir.File("nosocket"), dir.path());
  EXPECT_TRUE(Refused(pg, absl::StatusCode::kUnavailable, {"cannot connect", "***"}));
  EXPECT_EQ(pg.status().message().find("hunter2"), std::string::npos) << pg.status();
}

TEST(OpenStoreTest, PasswordsAreHidden) {
  EXPECT_EQ(HidePassword("postgresql://u:secret@db.example/radiosity?sslmode=require"),
            "postgresql://u:***@db.example/radiosity?sslmode=require");
  EXPECT_EQ(HidePassword("postgres://u@h/d?password=secret&sslmode=verify-full"),
            "postgres://u@h/d?password=***&sslmode=verify-full");
  EXPECT_EQ(HidePassword("postgresql://u@h/d"), "postgresql://u@h/d");
  // A password with '?' (libpq reads up to '@'), a misspelt scheme, libpq's key=value form.
  EXPECT_EQ(HidePassword("postgresql://u:se?cret@h/d"), "postgresql://u:***@h/d");
  EXPECT_EQ(HidePassword("postgre://u:secret@h/d"), "postgre://u:***@h/d");
  EXPECT_EQ(HidePassword("host=db password=secret user=u"), "host=db password=*** user=u");
  EXPECT_EQ(HidePassword("password = 'se cret' host=db"), "password = *** host=db");
}

}  // namespace
}  // namespace radiosity::service
