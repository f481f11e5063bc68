// Page tokens (Store::ListScenes, Store::ListJobs): every row is listed once across pages while
// other tenants add rows between them; a token tells nothing of the store's global row numbers
// (it is sealed), is refused for another tenant or when altered, and stays valid when the
// database is opened again.
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "server/store.h"
#include "tests/testing/test_util.h"

namespace radiosity::service {
namespace {

void AddScene(Store& store, const std::string& tenant, const std::string& id) {
  v1::SceneInfo scene;
  scene.set_name("scenes/" + id);
  scene.set_tenant(tenant);
  ASSERT_OK_AND_ASSIGN(auto existing, store.InsertScene(id, scene));
  ASSERT_FALSE(existing.has_value());
}

TEST(StorePagingTest, TokensAreSealedPerTenantAndSurviveReopening) {
  radiosity::testing::TempDir dir;
  const std::string path = dir.File("radiosity.db");
  std::string token;
  {
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> store, Store::Open(path));
    for (int i = 0; i < 3; ++i) AddScene(*store, "alice", "a" + std::to_string(i));

    ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse page, store->ListScenes("alice", 1, ""));
    ASSERT_EQ(page.scenes_size(), 1);
    EXPECT_EQ(page.scenes(0).name(), "scenes/a2");
    token = page.next_page_token();
    ASSERT_FALSE(token.empty());
    int64_t number = 0;
    EXPECT_FALSE(absl::SimpleAtoi(token, &number)) << "a plain row number: " << token;

    // Bob's rows between Alice's pages change neither her token nor what it lists.
    for (int i = 0; i < 5; ++i) AddScene(*store, "bob", "b" + std::to_string(i));
    ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse again, store->ListScenes("alice", 1, ""));
    EXPECT_EQ(again.next_page_token(), token);

    // Bob cannot use Alice's token, nor anyone an altered one.
    absl::Status bob = store->ListScenes("bob", 1, token).status();
    EXPECT_EQ(bob.code(), absl::StatusCode::kInvalidArgument) << bob;
    EXPECT_NE(bob.message().find("page_token"), std::string::npos) << bob;
    std::string altered = token;
    altered[5] = altered[5] == '0' ? '1' : '0';
    EXPECT_EQ(store->ListScenes("alice", 1, altered).status().code(),
              absl::StatusCode::kInvalidArgument);
    v1::ListJobsRequest jobs;
    jobs.set_page_token(token);
    EXPECT_TRUE(store->ListJobs("alice", jobs).ok()) << "a scenes token is a position, as any";
    EXPECT_EQ(store->ListJobs("bob", jobs).status().code(), absl::StatusCode::kInvalidArgument);

    // Bob's own pages: his five, once each, none of Alice's.
    std::vector<std::string> names;
    std::string next;
    do {
      ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse p, store->ListScenes("bob", 2, next));
      for (const auto& s : p.scenes()) names.push_back(s.name());
      next = p.next_page_token();
    } while (!next.empty() && names.size() < 10);
    EXPECT_EQ(names, (std::vector<std::string>{"scenes/b4", "scenes/b3", "scenes/b2", "scenes/b1",
                                               "scenes/b0"}));
  }
  // The key is kept in the database: the token still pages after a restart.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Store> reopened, Store::Open(path));
  ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse rest, reopened->ListScenes("alice", 10, token));
  ASSERT_EQ(rest.scenes_size(), 2);
  EXPECT_EQ(rest.scenes(0).name(), "scenes/a1");
  EXPECT_EQ(rest.scenes(1).name(), "scenes/a0");
  EXPECT_TRUE(rest.next_page_token().empty());
}

}  // namespace
}  // namespace radiosity::service
