// A database written before tenants (no `tenant` and `bytes` columns) opens with its rows kept:
// they belong to no tenant (""), their bytes count, and request ids still find them.
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <string>

#include "server/sqlite_store.h"
#include "tests/testing/test_util.h"

namespace radiosity::service {
namespace {

void Exec(sqlite3* db, const std::string& sql) {
  char* error = nullptr;
  ASSERT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, &error), SQLITE_OK) << error;
}

void InsertBlob(sqlite3* db, const std::string& sql, const std::string& blob) {
  sqlite3_stmt* stmt = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr), SQLITE_OK);
  sqlite3_bind_blob(stmt, 1, blob.data(), static_cast<int>(blob.size()), SQLITE_TRANSIENT);
  EXPECT_EQ(sqlite3_step(stmt), SQLITE_DONE);
  sqlite3_finalize(stmt);
}

TEST(StoreMigrationTest, RowsWrittenBeforeTenantsBelongToTheOpenTenant) {
  radiosity::testing::TempDir dir;
  const std::string path = dir.File("radiosity.db");
  {
    // The schema of the releases before tenants, with one scene and two jobs.
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
    Exec(db,
         "CREATE TABLE scenes(seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT UNIQUE NOT NULL,"
         "  request_id TEXT NOT NULL, info BLOB NOT NULL);"
         "CREATE INDEX scenes_request ON scenes(request_id);"
         "CREATE TABLE jobs(seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT UNIQUE NOT NULL,"
         "  scene TEXT NOT NULL, request_id TEXT NOT NULL, state INTEGER NOT NULL,"
         "  info BLOB NOT NULL);"
         "CREATE INDEX jobs_request ON jobs(request_id);");
    v1::SceneInfo scene;
    scene.set_name("scenes/s1");
    scene.set_request_id("upload-1");
    scene.set_total_size(1234);
    InsertBlob(db, "INSERT INTO scenes(id, request_id, info) VALUES('s1', 'upload-1', ?)",
               scene.SerializeAsString());
    v1::Job done;
    done.set_name("jobs/j1");
    done.set_scene("scenes/s1");
    done.set_state(v1::JOB_STATE_SUCCEEDED);
    done.add_results()->set_size(100);
    done.add_results()->set_size(20);
    InsertBlob(db,
               "INSERT INTO jobs(id, scene, request_id, state, info) VALUES('j1', 'scenes/s1', "
               "'', 3, ?)",
               done.SerializeAsString());
    v1::Job queued;
    queued.set_name("jobs/j2");
    queued.set_scene("scenes/s1");
    queued.set_state(v1::JOB_STATE_QUEUED);
    InsertBlob(db,
               "INSERT INTO jobs(id, scene, request_id, state, info) VALUES('j2', 'scenes/s1', "
               "'job-2', 1, ?)",
               queued.SerializeAsString());
    sqlite3_close(db);
  }
  for (int open = 0; open < 2; ++open) {  // The second open finds the columns in place.
    absl::StatusOr<std::unique_ptr<SqliteStore>> store = SqliteStore::Open(path);
    ASSERT_TRUE(store.ok()) << store.status();
    absl::StatusOr<TenantUsage> usage = (*store)->Usage("");
    ASSERT_TRUE(usage.ok()) << usage.status();
    EXPECT_EQ(usage->stored_bytes, 1234 + 100 + 20);
    EXPECT_EQ(usage->unfinished_jobs, 1);
    absl::StatusOr<TenantUsage> other = (*store)->Usage("alice");
    ASSERT_TRUE(other.ok());
    EXPECT_EQ(other->stored_bytes, 0);
    absl::StatusOr<v1::ListScenesResponse> scenes = (*store)->ListScenes("", 0, "");
    ASSERT_TRUE(scenes.ok());
    ASSERT_EQ(scenes->scenes_size(), 1);
    EXPECT_EQ(scenes->scenes(0).name(), "scenes/s1");
    absl::StatusOr<v1::ListJobsResponse> jobs = (*store)->ListJobs("", {});
    ASSERT_TRUE(jobs.ok());
    EXPECT_EQ(jobs->jobs_size(), 2);
    absl::StatusOr<std::optional<v1::Job>> found = (*store)->FindJobByRequest("", "job-2");
    ASSERT_TRUE(found.ok() && found->has_value());
    EXPECT_EQ((*found)->name(), "jobs/j2");
    found = (*store)->FindJobByRequest("alice", "job-2");
    ASSERT_TRUE(found.ok());
    EXPECT_FALSE(found->has_value());
  }
}

}  // namespace
}  // namespace radiosity::service
