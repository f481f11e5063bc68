// TLS and tenants (docs/service/security.md): a real server on 127.0.0.1 with certificates
// made by deploy/make-test-pki.sh at test time (openssl; no key is committed) and a tokens file of
// two tenants. Each RPC is tried across tenants; tokens are checked, reloaded and revoked; quotas
// hold per tenant; mutual TLS refuses clients without a certificate of its CA; plaintext off
// loopback needs --insecure; the CLI reaches a TLS server with --tls-ca and --token-file.
#include "server/tenants.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>
#include <thread>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "proto/api/exit_codes.h"
#include "server/server.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using client::ChannelSecurity;
using client::Client;
using service::kServiceName;
using service::Server;
using service::ServerOptions;
using service::TokenTable;
using service::testing::ServiceTest;
using service::testing::TestServerOptions;
using service::testing::WaitFor;
using testing::RunCli;
using testing::SourcePath;
using testing::TempDir;

constexpr char kAliceToken[] = "alice-0123456789abcdef";
constexpr char kBobToken[] = "bob-0123456789abcdef01";
constexpr char kCarolToken[] = "carol-0123456789abcdef";

// Certificates for the whole suite, made once.
class TenantsTest : public ServiceTest {
 protected:
  static void SetUpTestSuite() {
    pki_ = new TempDir();
    const std::string command =
        absl::StrCat("sh '", SourcePath("deploy/make-test-pki.sh"), "' '", pki_->path(), "' alice");
    made_ = std::system(command.c_str()) == 0;
  }
  static void TearDownTestSuite() {
    delete pki_;
    pki_ = nullptr;
  }

  void SetUp() override {
    ASSERT_TRUE(made_) << "deploy/make-test-pki.sh failed (is openssl installed?)";
    tokens_file_ =
        tokens_dir_.Write("tokens", absl::StrCat("# test tenants\n", kAliceToken, " alice\n",
                                                 kBobToken, " bob   # a comment\n\n"));
    ASSERT_NO_FATAL_FAILURE(Start(SecureOptions()));
  }

  ServerOptions SecureOptions() {
    ServerOptions o = TestServerOptions(data_.path());
    o.tls_cert_file = pki_->File("server.pem");
    o.tls_key_file = pki_->File("server.key");
    o.tokens_file = tokens_file_;
    return o;
  }

  // A client of the running server over TLS (verified against the test CA) with `token`.
  std::unique_ptr<Client> As(const std::string& token, ChannelSecurity security = {}) {
    if (security.ca_file.empty()) security.ca_file = pki_->File("ca.pem");
    security.token = token;
    absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
        client::MakeChannel(address(), security);
    EXPECT_TRUE(channel.ok()) << channel.status();
    return std::make_unique<Client>(*channel);
  }

  static TempDir* pki_;
  static bool made_;
  TempDir tokens_dir_;
  std::string tokens_file_;
};

TempDir* TenantsTest::pki_ = nullptr;
bool TenantsTest::made_ = false;

// A NOT_FOUND that says the resource does not exist, as for a name nobody ever had.
::testing::AssertionResult Hidden(const absl::Status& status, const std::string& name) {
  if (status.code() != absl::StatusCode::kNotFound) {
    return ::testing::AssertionFailure() << "expected NOT_FOUND, got " << status;
  }
  if (status.message() != absl::StrCat(name, " does not exist")) {
    return ::testing::AssertionFailure() << "message tells more than absence: " << status;
  }
  return ::testing::AssertionSuccess();
}

TEST_F(TenantsTest, NoTenantSeesOrTouchesAnothersScenesAndJobs) {
  std::unique_ptr<Client> alice = As(kAliceToken);
  std::unique_ptr<Client> bob = As(kBobToken);
  const std::string box = SourcePath("scenes/cornell_box.obj");
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo scene, alice->UploadSceneFile(box, "shared-key"));
  EXPECT_EQ(scene.tenant(), "alice");
  v1::CreateJobRequest request = service::testing::ShortSolve(scene.name(), 1);
  request.set_request_id("job-key");
  ASSERT_OK_AND_ASSIGN(v1::Job job, alice->CreateJob(request));
  EXPECT_EQ(job.tenant(), "alice");
  ASSERT_TRUE(WaitFor(
      [&] {
        absl::StatusOr<v1::Job> j = alice->GetJob(job.name());
        return j.ok() && j->state() == v1::JOB_STATE_SUCCEEDED;
      },
      60));

  // Scenes: Get, List, Download, Delete, and CreateJob on it.
  EXPECT_TRUE(Hidden(bob->GetScene(scene.name()).status(), scene.name()));
  ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse bob_scenes, bob->ListScenes({}));
  EXPECT_EQ(bob_scenes.scenes_size(), 0);
  TempDir got;
  EXPECT_TRUE(Hidden(bob->DownloadScene(scene.name(), got.path()).status(), scene.name()));
  EXPECT_TRUE(Hidden(bob->DeleteScene(scene.name()), scene.name()));
  EXPECT_TRUE(
      Hidden(bob->CreateJob(service::testing::ShortSolve(scene.name(), 2)).status(), scene.name()));
  // Jobs: Get, List, Watch, Download, Cancel, Delete.
  EXPECT_TRUE(Hidden(bob->GetJob(job.name()).status(), job.name()));
  v1::ListJobsRequest all;
  ASSERT_OK_AND_ASSIGN(v1::ListJobsResponse bob_jobs, bob->ListJobs(all));
  EXPECT_EQ(bob_jobs.jobs_size(), 0);
  v1::ListJobsRequest on_scene;
  on_scene.set_scene(scene.name());
  ASSERT_OK_AND_ASSIGN(bob_jobs, bob->ListJobs(on_scene));
  EXPECT_EQ(bob_jobs.jobs_size(), 0);
  EXPECT_TRUE(Hidden(
      bob->Watch(job.name(), 0, false, [](const client::Snapshot&) { return true; }).status(),
      job.name()));
  EXPECT_TRUE(Hidden(bob->DownloadResults(job.name(), got.path()).status(), job.name()));
  EXPECT_TRUE(Hidden(bob->CancelJob(job.name()).status(), job.name()));
  EXPECT_TRUE(Hidden(bob->DeleteJob(job.name()), job.name()));

  // Request ids are per tenant: Bob's retry keys never answer with Alice's resources.
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo bobs, bob->UploadSceneFile(box, "shared-key"));
  EXPECT_NE(bobs.name(), scene.name());
  EXPECT_EQ(bobs.tenant(), "bob");
  v1::CreateJobRequest bob_request = service::testing::ShortSolve(bobs.name(), 1);
  bob_request.set_request_id("job-key");
  ASSERT_OK_AND_ASSIGN(v1::Job bob_job, bob->CreateJob(bob_request));
  EXPECT_NE(bob_job.name(), job.name());
  EXPECT_EQ(bob_job.tenant(), "bob");

  // Alice's resources are intact and hers alone.
  ASSERT_OK_AND_ASSIGN(v1::Job again, alice->GetJob(job.name()));
  EXPECT_EQ(again.state(), v1::JOB_STATE_SUCCEEDED);
  ASSERT_OK_AND_ASSIGN(v1::ListJobsResponse alice_jobs, alice->ListJobs(all));
  ASSERT_EQ(alice_jobs.jobs_size(), 1);
  EXPECT_EQ(alice_jobs.jobs(0).name(), job.name());
  ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse alice_scenes, alice->ListScenes({}));
  ASSERT_EQ(alice_scenes.scenes_size(), 1);
  EXPECT_EQ(alice_scenes.scenes(0).name(), scene.name());
  ASSERT_OK_AND_ASSIGN(std::vector<std::string> files,
                       alice->DownloadResults(job.name(), got.path()));
  EXPECT_FALSE(files.empty());
  // The same retry key from Alice still answers with her own job.
  ASSERT_OK_AND_ASSIGN(v1::Job retried, alice->CreateJob(request));
  EXPECT_EQ(retried.name(), job.name());
}

// Several tenants' calls on one connection (a gateway's): each call is its own token's tenant,
// a call without a token is refused whatever came before on the connection, and a revoked token
// stops at once on connections it used.
TEST_F(TenantsTest, TheTenantIsEachCallsNotTheConnections) {
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo scene,
                       As(kAliceToken)->UploadSceneFile(SourcePath("scenes/cornell_box.obj")));
  ChannelSecurity tls;
  tls.ca_file = pki_->File("ca.pem");
  ASSERT_OK_AND_ASSIGN(std::shared_ptr<grpc::Channel> channel, client::MakeChannel(address(), tls));
  std::unique_ptr<v1::RadiosityService::Stub> stub = v1::RadiosityService::NewStub(channel);
  auto list = [&](const std::string& token, int* count) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    if (!token.empty()) context.AddMetadata("authorization", "Bearer " + token);
    v1::ListScenesResponse response;
    grpc::Status st = stub->ListScenes(&context, {}, &response);
    *count = response.scenes_size();
    return st.error_code();
  };
  int count = 0;
  for (int round = 0; round < 3; ++round) {
    ASSERT_EQ(list(kAliceToken, &count), grpc::StatusCode::OK);
    EXPECT_EQ(count, 1);
    ASSERT_EQ(list(kBobToken, &count), grpc::StatusCode::OK);
    EXPECT_EQ(count, 0) << "Bob sees Alice's scene on a connection Alice used";
    EXPECT_EQ(list("", &count), grpc::StatusCode::UNAUTHENTICATED);
  }
  // Alice revoked: her token stops on this connection, and no call gets her scenes.
  std::ofstream(tokens_file_) << kBobToken << " bob\n";
  EXPECT_TRUE(
      WaitFor([&] { return list(kAliceToken, &count) == grpc::StatusCode::UNAUTHENTICATED; }, 5));
  EXPECT_EQ(list("", &count), grpc::StatusCode::UNAUTHENTICATED);
  ASSERT_EQ(list(kBobToken, &count), grpc::StatusCode::OK);
  EXPECT_EQ(count, 0);
  // Two authorization headers are refused rather than one of them chosen.
  grpc::ClientContext twice;
  twice.AddMetadata("authorization", std::string("Bearer ") + kBobToken);
  twice.AddMetadata("authorization", std::string("Bearer ") + kBobToken);
  v1::ListScenesResponse response;
  EXPECT_EQ(stub->ListScenes(&twice, {}, &response).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  (void)scene;
}

TEST_F(TenantsTest, CallsWithoutAKnownTokenAreRefusedButHealthIsOpen) {
  std::unique_ptr<Client> nobody = As("");
  EXPECT_EQ(nobody->ListJobs({}).status().code(), absl::StatusCode::kUnauthenticated);
  EXPECT_EQ(nobody->UploadSceneFile(SourcePath("scenes/cornell_box.obj")).status().code(),
            absl::StatusCode::kUnauthenticated);
  std::unique_ptr<Client> stranger = As("mallory-0123456789abcdef");
  absl::Status refused = stranger->ListScenes({}).status();
  EXPECT_EQ(refused.code(), absl::StatusCode::kUnauthenticated) << refused;
  // Health checks (load balancers, Kubernetes probes) need no token.
  ASSERT_OK_AND_ASSIGN(bool serving, nobody->CheckHealth(kServiceName));
  EXPECT_TRUE(serving);
  // A plaintext client cannot talk to the TLS port at all.
  client::ClientOptions short_timeout;
  short_timeout.timeout_seconds = 5;
  Client plain(client::MakeChannel(address()), short_timeout);
  EXPECT_EQ(plain.ListJobs({}).status().code(), absl::StatusCode::kUnavailable);
  // Nor can a client that does not trust the server's CA.
  ChannelSecurity wrong_ca;
  wrong_ca.ca_file = pki_->File("other-ca.pem");
  EXPECT_EQ(As(kAliceToken, wrong_ca)->ListJobs({}).status().code(),
            absl::StatusCode::kUnavailable);
}

TEST_F(TenantsTest, TheTokensFileIsReadAgainWhenItChanges) {
  std::unique_ptr<Client> bob = As(kBobToken);
  std::unique_ptr<Client> carol = As(kCarolToken);
  ASSERT_TRUE(bob->ListJobs({}).ok());
  EXPECT_EQ(carol->ListJobs({}).status().code(), absl::StatusCode::kUnauthenticated);
  // Bob's token revoked, Carol's added (a different size, so the change shows at once).
  std::ofstream(tokens_file_) << kAliceToken << " alice\n" << kCarolToken << " carol\n# rotated\n";
  EXPECT_TRUE(WaitFor([&] { return carol->ListJobs({}).ok(); }, 5));
  EXPECT_EQ(bob->ListJobs({}).status().code(), absl::StatusCode::kUnauthenticated);
  // A file that no longer parses keeps the tokens read before.
  std::ofstream(tokens_file_) << "short alice\n";
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  EXPECT_TRUE(carol->ListJobs({}).ok());
  EXPECT_TRUE(As(kAliceToken)->ListJobs({}).ok());
}

TEST_F(TenantsTest, QuotasHoldPerTenant) {
  ServerOptions o = SecureOptions();
  o.service.quotas.max_unfinished_jobs = 1;
  const std::string box = SourcePath("scenes/cornell_box.obj");
  const int64_t box_bytes = static_cast<int64_t>(testing::ReadFile(box).size());
  o.service.quotas.max_stored_bytes = box_bytes * 3 / 2;
  ASSERT_NO_FATAL_FAILURE(Restart(o));
  std::unique_ptr<Client> alice = As(kAliceToken);
  std::unique_ptr<Client> bob = As(kBobToken);
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo a, alice->UploadSceneFile(box));
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo b, bob->UploadSceneFile(box));
  // A second scene would take Alice past her stored bytes; Bob's scene does not count for her.
  TempDir other;
  const std::string copy = other.Write("box2.obj", testing::ReadFile(box) + "# another\n");
  absl::Status full = alice->UploadSceneFile(copy).status();
  EXPECT_EQ(full.code(), absl::StatusCode::kResourceExhausted) << full;
  EXPECT_NE(full.message().find("--tenant-max-stored-mb"), std::string::npos) << full;
  // One unfinished job each.
  ASSERT_OK_AND_ASSIGN(v1::Job running,
                       alice->CreateJob(service::testing::LongSolve(a.name(), 200, 8)));
  absl::Status second = alice->CreateJob(service::testing::LongSolve(a.name(), 200, 8)).status();
  EXPECT_EQ(second.code(), absl::StatusCode::kResourceExhausted) << second;
  EXPECT_NE(second.message().find("--tenant-max-jobs 1"), std::string::npos) << second;
  ASSERT_OK_AND_ASSIGN(v1::Job bobs, bob->CreateJob(service::testing::LongSolve(b.name(), 200, 8)));
  // Once Alice's job has ended (and its results are deleted), she may create another.
  ASSERT_TRUE(alice->CancelJob(running.name()).ok());
  ASSERT_TRUE(bob->CancelJob(bobs.name()).ok());
  EXPECT_TRUE(WaitFor(
      [&] {
        absl::StatusOr<v1::Job> j = alice->GetJob(running.name());
        return j.ok() && j->state() == v1::JOB_STATE_CANCELLED;
      },
      10));
  // (A cancelled job keeps what it computed, which counts towards her stored bytes: deleting it
  // makes room.)
  ASSERT_TRUE(alice->DeleteJob(running.name()).ok());
  ASSERT_OK_AND_ASSIGN(v1::Job next, alice->CreateJob(service::testing::ShortSolve(a.name(), 3)));
  EXPECT_EQ(next.tenant(), "alice");
}

TEST_F(TenantsTest, MutualTlsRefusesClientsWithoutACertificateOfItsCa) {
  ServerOptions o = SecureOptions();
  o.tls_client_ca_file = pki_->File("ca.pem");
  ASSERT_NO_FATAL_FAILURE(Restart(o));
  ChannelSecurity with_cert;
  with_cert.cert_file = pki_->File("client-alice.pem");
  with_cert.key_file = pki_->File("client-alice.key");
  EXPECT_TRUE(As(kAliceToken, with_cert)->ListJobs({}).ok());
  EXPECT_EQ(As(kAliceToken)->ListJobs({}).status().code(), absl::StatusCode::kUnavailable);
  ChannelSecurity intruder;
  intruder.cert_file = pki_->File("other-client.pem");
  intruder.key_file = pki_->File("other-client.key");
  EXPECT_EQ(As(kAliceToken, intruder)->ListJobs({}).status().code(),
            absl::StatusCode::kUnavailable);
}

TEST_F(TenantsTest, OffLoopbackWithoutCredentialsNeedsInsecure) {
  Stop();
  ServerOptions o = TestServerOptions(data_.path());
  o.listen = "0.0.0.0:0";
  absl::StatusOr<std::unique_ptr<Server>> refused = Server::Start(o);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("--insecure"), std::string::npos) << refused.status();
  // TLS alone is no credential; tokens without TLS are refused.
  o.tls_cert_file = pki_->File("server.pem");
  o.tls_key_file = pki_->File("server.key");
  EXPECT_EQ(Server::Start(o).status().code(), absl::StatusCode::kInvalidArgument);
  ServerOptions clear = TestServerOptions(data_.path());
  clear.tokens_file = tokens_file_;
  EXPECT_EQ(Server::Start(clear).status().code(), absl::StatusCode::kInvalidArgument);
  // With --insecure, or with tokens, it starts.
  o.insecure = true;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Server> open, Server::Start(o));
  open->Shutdown();
  open.reset();
  o.insecure = false;
  o.tokens_file = tokens_file_;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Server> secured, Server::Start(o));
  secured->Shutdown();
}

TEST(TokenTableTest, ParseNamesTheLineOfEachProblem) {
  EXPECT_TRUE(TokenTable::Parse("t", "0123456789abcdef0 a\n# c\n\n0123456789abcdef1 a\n").ok());
  auto expect = [](const std::string& text, const std::string& words) {
    absl::StatusOr<std::map<std::string, std::string>> parsed = TokenTable::Parse("tokens", text);
    ASSERT_FALSE(parsed.ok()) << text;
    EXPECT_EQ(parsed.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(parsed.status().message().find(words), std::string::npos) << parsed.status();
  };
  expect("0123456789abcdef0 a\nonly-one-field-here\n", "tokens:2: expected 'TOKEN TENANT'");
  expect("short a\n", "tokens:1: a token must be 16");
  expect("0123456789abcdef0 bad/tenant\n", "tokens:1: tenant 'bad/tenant'");
  expect("0123456789abcdef0 a\n0123456789abcdef0 b\n", "tokens:2: this token is given to two");
}

TEST_F(TenantsTest, TheCliReachesATlsServerWithATokenFile) {
  const std::string token_file = tokens_dir_.Write("alice.token", absl::StrCat(kAliceToken, "\n"));
  const std::string ca = pki_->File("ca.pem");
  auto uploaded = RunCli({"--server", address(), "--tls-ca", ca, "--token-file", token_file,
                          "upload", SourcePath("scenes/cornell_box.obj")});
  ASSERT_EQ(uploaded.exit_code, kExitOk) << uploaded.output;
  auto listed = RunCli(
      {"--server", address(), "--tls-ca", ca, "--token-file", token_file, "--json", "scenes"});
  ASSERT_EQ(listed.exit_code, kExitOk) << listed.output;
  EXPECT_NE(listed.output.find("\"tenant\":\"alice\""), std::string::npos) << listed.output;
  // Without the token: refused, and the message says what is missing.
  auto refused = RunCli({"--server", address(), "--tls-ca", ca, "scenes"});
  EXPECT_NE(refused.exit_code, kExitOk);
  EXPECT_NE(refused.output.find("bearer token"), std::string::npos) << refused.output;
  // A token over plaintext is refused by the CLI before anything is sent.
  auto clear = RunCli({"--server", address(), "--token-file", token_file, "scenes"});
  EXPECT_EQ(clear.exit_code, kExitUsage) << clear.output;
  EXPECT_NE(clear.output.find("only over TLS"), std::string::npos) << clear.output;
}

}  // namespace
}  // namespace radiosity
