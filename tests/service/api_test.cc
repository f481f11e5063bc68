// The service against a real server on 127.0.0.1 (a free port), through the client library:
// upload + solve + snapshots, equality with a local solve of the same seed, validation errors that
// leave the server serving, idempotent uploads, paging. Status codes are asserted, not messages
// (except where the message is the contract: it names the file and the problem).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <thread>
#include <tuple>
#include <vector>

#include "client/client.h"
#include "proto/api/spec.h"
#include "server/server.h"
#include "server/snapshots.h"
#include "solver/input/scene_files.h"
#include "solver/methods/registry.h"
#include "solver/pipeline/job.h"
#include "solver/results/camera.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

// These tests check that the deprecated string fields still work, alone and beside their enums.
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"

namespace radiosity {
namespace {

using client::Client;
using client::Snapshot;
using testing::ReadFile;
using testing::SourcePath;
using testing::TempDir;

class ServiceApiTest : public service::testing::ServiceTest {};

// A spec whose solve takes long enough (about a second) to be seen converging.
JobSpec ConvergingSpec() {
  JobSpec spec;
  spec.mesh.max_elements = 1000;
  spec.solve.rays_per_element = 1000;
  spec.solve.seed = 7;
  spec.solve.threads = 2;
  spec.width = spec.height = 16;
  return spec;
}

TEST_F(ServiceApiTest, UploadSolveWatchAndMatchTheLocalSolve) {
  const std::string path = SourcePath("scenes/cornell_box.obj");
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo scene, client_->UploadSceneFile(path));
  ASSERT_EQ(scene.files_size(), 2);  // The OBJ and the MTL it names.
  EXPECT_EQ(scene.files(1).name(), "cornell_box.mtl");
  EXPECT_EQ(scene.surfaces(), 8);
  EXPECT_TRUE(scene.has_emitter());

  const JobSpec spec = ConvergingSpec();
  v1::CreateJobRequest request;
  request.set_scene(scene.name());
  *request.mutable_solve() = service::ToSolveSpec(spec, /*snapshot_interval=*/0.01);
  absl::StatusOr<v1::Job> job = client_->CreateJob(request);
  ASSERT_TRUE(job.ok()) << job.status();
  EXPECT_EQ(job->state(), v1::JOB_STATE_QUEUED);

  std::vector<Snapshot> seen;
  absl::StatusOr<Snapshot> last =
      client_->Watch(job->name(), 0, /*progress_only=*/false, [&](const Snapshot& s) {
        seen.push_back(s);
        return true;
      });
  ASSERT_TRUE(last.ok()) << last.status();
  ASSERT_TRUE(last->final);
  EXPECT_EQ(last->state, v1::JOB_STATE_SUCCEEDED);
  ASSERT_GE(seen.size(), 3u);
  for (size_t i = 1; i < seen.size(); ++i) {
    EXPECT_GT(seen[i].sequence, seen[i - 1].sequence);
    // Progressive refinement only ever lowers the unshot power (Shirley 6.2; no overshooting).
    EXPECT_LE(seen[i].progress.unshot_fraction(), seen[i - 1].progress.unshot_fraction() + 1e-12);
    EXPECT_GE(seen[i].progress.rays(), seen[i - 1].progress.rays());
  }
  EXPECT_LT(seen.back().progress.unshot_fraction(), seen.front().progress.unshot_fraction());
  EXPECT_LT(last->progress.unshot_fraction(), 1e-3);
  for (const Snapshot& s : seen) {
    if (s.elements > 0 && !s.radiosity.empty()) {
      EXPECT_EQ(s.radiosity.size(), 6u * static_cast<size_t>(s.elements));
    }
  }

  TempDir out;
  absl::StatusOr<std::vector<std::string>> files =
      client_->DownloadResults(job->name(), out.path());
  ASSERT_TRUE(files.ok()) << files.status();
  std::map<std::string, bool> has;
  for (const auto& f : *files) has[f] = true;
  for (const char* f :
       {"elements.csv", "summary.json", "mesh.ply", "mesh.glb", "image.exr", "image.png"}) {
    EXPECT_TRUE(has[f]) << f;
  }

  // The same job solved here, without the service: identical elements and radiosity.
  absl::StatusOr<Scene> local_scene = LoadSceneFile(path, nullptr);
  ASSERT_TRUE(local_scene.ok());
  TempDir local;
  absl::StatusOr<JobResult> result = RunJob(*local_scene, spec, local.path(), nullptr, {});
  ASSERT_TRUE(result.ok()) << result.status();
  std::string remote_csv = ReadFile(out.File("elements.csv"));
  ASSERT_FALSE(remote_csv.empty());
  EXPECT_EQ(remote_csv, ReadFile(local.File("elements.csv")));
  EXPECT_EQ(last->radiosity, service::PackRadiosity(result->solution)->data());
}

TEST_F(ServiceApiTest, BadScenesAreInvalidArgumentAndTheServerKeepsServing) {
  TempDir dir;
  dir.Write("bad.mtl", "newmtl lamp\nKd 0.5 0.5 0.5\nKe 1 1 1\n");
  std::string bad =
      dir.Write("bad.obj", "mtllib bad.mtl\nv 0 0 0\nv 1 nan 0\nv 1 1 0\nusemtl lamp\nf 1 2 3\n");
  absl::StatusOr<v1::SceneInfo> info = client_->UploadSceneFile(bad);
  ASSERT_EQ(info.status().code(), absl::StatusCode::kInvalidArgument);
  // The message names the client's file and line, not the server's copy.
  EXPECT_NE(info.status().message().find(bad + ":3:"), std::string::npos) << info.status();

  // A material library outside the scene's directory is refused before anything reads it.
  std::string escape = dir.Write(
      "escape.obj", "mtllib /etc/passwd\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl lamp\nf 1 2 3\n");
  EXPECT_EQ(client_->UploadSceneFile(escape).status().code(), absl::StatusCode::kInvalidArgument);

  // Wrong checksum, unsafe name, chunk over 1 MiB, chunk before the header.
  std::string good = SourcePath("scenes/furnace.json");
  absl::StatusOr<client::SceneFiles> files = client::CollectSceneFiles(good, "r1");
  ASSERT_TRUE(files.ok());
  client::SceneFiles corrupt = *files;
  corrupt.header.mutable_files(0)->set_sha256(std::string(64, '0'));
  EXPECT_EQ(client_->Upload(corrupt).status().code(), absl::StatusCode::kInvalidArgument);

  v1::UploadSceneRequest header;
  *header.mutable_header() = files->header;
  header.mutable_header()->set_request_id("");
  header.mutable_header()->mutable_files(0)->set_name("../furnace.json");
  EXPECT_EQ(RawUpload({header}).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  header.mutable_header()->mutable_files(0)->set_name("furnace.json");
  header.mutable_header()->mutable_files(0)->set_size((1 << 20) + 1);
  v1::UploadSceneRequest big;
  big.mutable_chunk()->set_file("furnace.json");
  big.mutable_chunk()->set_data(std::string((1 << 20) + 1, ' '));
  EXPECT_EQ(RawUpload({header, big}).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(RawUpload({big}).error_code(), grpc::StatusCode::INVALID_ARGUMENT);

  // Bad job requests.
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo furnace, client_->UploadSceneFile(good));
  v1::CreateJobRequest request;
  request.set_scene(furnace.name());
  request.mutable_solve()->set_tolerance(2);
  EXPECT_EQ(client_->CreateJob(request).status().code(), absl::StatusCode::kInvalidArgument);
  request.mutable_solve()->set_tolerance(0);
  request.mutable_solve()->set_camera("eye=1,2");
  EXPECT_EQ(client_->CreateJob(request).status().code(), absl::StatusCode::kInvalidArgument);
  request.mutable_solve()->set_camera("");
  request.mutable_solve()->mutable_mesh()->set_element_size(1e-7);
  EXPECT_EQ(client_->CreateJob(request).status().code(), absl::StatusCode::kInvalidArgument);
  request.set_scene("scenes/doesnotexist");
  request.mutable_solve()->mutable_mesh()->set_element_size(0);
  EXPECT_EQ(client_->CreateJob(request).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(client_->GetJob("jobs/doesnotexist").status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(client_->GetJob("scenes/x").status().code(), absl::StatusCode::kInvalidArgument);

  // A scene without an emitter uploads, but cannot be solved.
  std::string dark =
      dir.Write("dark.json",
                R"({"materials":[{"name":"m","reflectance":{"r":0.5,"g":0.5,"b":0.5}}],
          "surfaces":[{"name":"s","material":"m","vertices":[0,0,0,1,0,0,1,1,0],
                       "faces":[{"indices":[0,1,2]}]}]})");
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo dark_scene, client_->UploadSceneFile(dark));
  EXPECT_FALSE(dark_scene.has_emitter());
  request.set_scene(dark_scene.name());
  EXPECT_EQ(client_->CreateJob(request).status().code(), absl::StatusCode::kFailedPrecondition);

  // Still serving, and still solving.
  absl::StatusOr<bool> serving = client_->CheckHealth(service::kServiceName);
  ASSERT_TRUE(serving.ok()) << serving.status();
  EXPECT_TRUE(*serving);
  request.set_scene(furnace.name());
  request.mutable_solve()->set_max_rays(20000);
  absl::StatusOr<v1::Job> job = client_->CreateJob(request);
  ASSERT_TRUE(job.ok()) << job.status();
  absl::StatusOr<Snapshot> last = client_->Watch(job->name(), 0, true, nullptr);
  ASSERT_TRUE(last.ok()) << last.status();
  EXPECT_EQ(last->state, v1::JOB_STATE_SUCCEEDED);
}

TEST_F(ServiceApiTest, UploadsAreIdempotentAndListsArePaged) {
  const std::string path = SourcePath("scenes/furnace.json");
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo first, client_->UploadSceneFile(path));
  // Same content, same derived request id.
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo again, client_->UploadSceneFile(path));
  EXPECT_EQ(first.name(), again.name());

  absl::StatusOr<client::SceneFiles> files = client::CollectSceneFiles(path, "key-1");
  ASSERT_TRUE(files.ok());
  absl::StatusOr<v1::SceneInfo> a = client_->Upload(*files);
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_NE(a->name(), first.name());
  // The same key for other content is refused.
  absl::StatusOr<client::SceneFiles> other =
      client::CollectSceneFiles(SourcePath("scenes/cornell_box.obj"), "key-1");
  ASSERT_TRUE(other.ok());
  EXPECT_EQ(client_->Upload(*other).status().code(), absl::StatusCode::kAlreadyExists);

  // A header with only_if_stored answers from itself: the stored scene, or NOT_FOUND (which is
  // an answer, not a failed call: the error count does not move).
  v1::UploadSceneRequest probe;
  *probe.mutable_header() = files->header;
  probe.mutable_header()->set_only_if_stored(true);
  EXPECT_TRUE(RawUpload({probe}).ok());
  probe.mutable_header()->set_request_id("key-never-used");
  const int64_t errors = server_->metrics().request_errors;
  const grpc::Status missing = RawUpload({probe});
  EXPECT_EQ(missing.error_code(), grpc::StatusCode::NOT_FOUND) << missing.error_message();
  EXPECT_NE(missing.error_message().find("key-never-used"), std::string::npos);
  EXPECT_EQ(server_->metrics().request_errors, errors);

  // Jobs with a request id are created once.
  v1::CreateJobRequest request;
  request.set_scene(first.name());
  request.mutable_solve()->set_max_rays(1000);
  request.mutable_solve()->set_skip_image(true);
  request.set_request_id("job-key");
  absl::StatusOr<v1::Job> j1 = client_->CreateJob(request);
  absl::StatusOr<v1::Job> j2 = client_->CreateJob(request);
  ASSERT_TRUE(j1.ok() && j2.ok()) << j1.status() << j2.status();
  EXPECT_EQ(j1->name(), j2->name());
  // The same key for a different request (another budget, another scene, a view-factor job) is
  // refused naming the job it was used for, never answered with that job.
  v1::CreateJobRequest changed = request;
  changed.mutable_solve()->set_max_rays(2000);
  v1::CreateJobRequest elsewhere = request;
  elsewhere.set_scene(a->name());
  v1::CreateJobRequest view_factor = request;
  view_factor.mutable_view_factor();
  for (const v1::CreateJobRequest& r : {changed, elsewhere, view_factor}) {
    absl::StatusOr<v1::Job> reused = client_->CreateJob(r);
    ASSERT_FALSE(reused.ok());
    EXPECT_EQ(reused.status().code(), absl::StatusCode::kAlreadyExists) << reused.status();
    EXPECT_NE(reused.status().message().find(j1->name()), std::string::npos) << reused.status();
  }
  request.set_request_id("");
  absl::StatusOr<v1::Job> j3 = client_->CreateJob(request);
  ASSERT_TRUE(j3.ok());
  ASSERT_TRUE(client_->Watch(j3->name(), 0, true, nullptr).ok());
  // Resumed at and past the end of the ended job, the raw stream (without the client's fallback)
  // says once more how it ended, progress only.
  ASSERT_OK_AND_ASSIGN(v1::Job ended, client_->GetJob(j3->name()));
  ASSERT_GT(ended.last_sequence(), 0);
  for (int64_t after : {ended.last_sequence(), ended.last_sequence() + 100}) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    v1::WatchJobRequest watch;
    watch.set_name(j3->name());
    watch.set_after_sequence(after);
    auto reader = client_->stub().WatchJob(&context, watch);
    std::vector<v1::WatchJobResponse> messages;
    for (v1::WatchJobResponse m; reader->Read(&m);) messages.push_back(m);
    EXPECT_TRUE(reader->Finish().ok());
    ASSERT_EQ(messages.size(), 1u) << "after " << after;
    EXPECT_TRUE(messages[0].final());
    EXPECT_EQ(messages[0].state(), v1::JOB_STATE_SUCCEEDED);
    EXPECT_EQ(messages[0].sequence(), ended.last_sequence());
    EXPECT_EQ(messages[0].progress().rays(), ended.progress().rays());
    EXPECT_EQ(messages[0].radiosity_size(), 0);
  }

  // Scenes and jobs page one at a time, newest first, each once.
  std::vector<std::string> names;
  v1::ListScenesRequest scenes;
  scenes.set_page_size(1);
  for (int page = 0; page < 10; ++page) {
    absl::StatusOr<v1::ListScenesResponse> list = client_->ListScenes(scenes);
    ASSERT_TRUE(list.ok()) << list.status();
    ASSERT_LE(list->scenes_size(), 1);
    for (const auto& s : list->scenes()) names.push_back(s.name());
    if (list->next_page_token().empty()) break;
    scenes.set_page_token(list->next_page_token());
  }
  ASSERT_EQ(names.size(), 2u);
  EXPECT_EQ(names[0], a->name());
  EXPECT_EQ(names[1], first.name());

  v1::ListJobsRequest jobs;
  jobs.set_page_size(1);
  jobs.add_states(v1::JOB_STATE_SUCCEEDED);
  std::vector<std::string> succeeded;
  for (int page = 0; page < 10; ++page) {
    absl::StatusOr<v1::ListJobsResponse> list = client_->ListJobs(jobs);
    ASSERT_TRUE(list.ok()) << list.status();
    for (const auto& j : list->jobs()) succeeded.push_back(j.name());
    if (list->next_page_token().empty()) break;
    jobs.set_page_token(list->next_page_token());
  }
  // One worker runs jobs in order: j1 (= j2) ended before j3.
  EXPECT_EQ(succeeded, (std::vector<std::string>{j3->name(), j1->name()}));
  EXPECT_EQ(client_
                ->ListJobs([] {
                  v1::ListJobsRequest r;
                  r.set_page_token("garbage");
                  return r;
                }())
                .status()
                .code(),
            absl::StatusCode::kInvalidArgument);
  ASSERT_TRUE(client_->Watch(j1->name(), 0, true, nullptr).ok());
}

// A multi-file glTF (the JSON, its buffer and a texture in a subfolder) is uploaded with the
// files it names, read back by the server confined to the upload, and solved; a PLY's vertex
// colours are read when the upload asks for them.
TEST_F(ServiceApiTest, ModelsUploadWithTheFilesTheyNameAndSolve) {
  const std::string model = "/usr/share/assimp/models/glTF2/BoxTextured-glTF";
  if (!std::filesystem::exists(model + "/BoxTextured.gltf")) {
    GTEST_SKIP() << model << " is absent: install the Debian package assimp-testmodels";
  }
  TempDir dir;
  std::filesystem::create_directory(dir.File("textures"));
  std::string gltf = ReadFile(model + "/BoxTextured.gltf");
  const size_t at = gltf.find("\"CesiumLogoFlat.png\"");
  ASSERT_NE(at, std::string::npos);
  gltf.replace(at, 20, "\"textures/logo.png\"");
  const std::string path = dir.Write("box.gltf", gltf);
  std::filesystem::copy_file(model + "/BoxTextured0.bin", dir.File("BoxTextured0.bin"));
  std::filesystem::copy_file(model + "/CesiumLogoFlat.png", dir.File("textures/logo.png"));

  ASSERT_OK_AND_ASSIGN(v1::SceneInfo scene, client_->UploadSceneFile(path));
  EXPECT_EQ(scene.format(), v1::SCENE_FORMAT_MODEL);
  ASSERT_EQ(scene.files_size(), 3);
  EXPECT_EQ(scene.files(1).name(), "BoxTextured0.bin");
  EXPECT_EQ(scene.files(2).name(), "textures/logo.png");
  EXPECT_EQ(scene.faces(), 12);
  // The texture was read (no "left out" warning): its colours split the box into surfaces.
  for (const std::string& w : scene.warnings())
    EXPECT_EQ(w.find("left out"), std::string::npos) << w;
  absl::StatusOr<Scene> local = LoadSceneFile(path, nullptr);
  ASSERT_OK(local);
  EXPECT_EQ(scene.surfaces(), static_cast<int64_t>(local->surfaces.size()));
  EXPECT_GT(scene.surfaces(), 1);

  v1::CreateJobRequest request;
  request.set_scene(scene.name());
  request.mutable_solve()->set_max_rays(20000);
  request.mutable_solve()->set_skip_image(true);
  v1::EmitOverride* emit = request.mutable_solve()->add_emit();
  emit->set_name(local->surfaces[0].name);
  emit->set_r(1);
  emit->set_g(1);
  emit->set_b(1);
  ASSERT_OK_AND_ASSIGN(v1::Job job, client_->CreateJob(request));
  ASSERT_OK_AND_ASSIGN(Snapshot last, client_->Watch(job.name(), 0, true, nullptr));
  EXPECT_EQ(last.state, v1::JOB_STATE_SUCCEEDED);

  // Without the buffer the upload is refused, naming the model and the missing file.
  std::filesystem::remove(dir.File("BoxTextured0.bin"));
  absl::StatusOr<v1::SceneInfo> missing = client_->UploadSceneFile(path, "other-key");
  EXPECT_TRUE(testing::Refused(missing, absl::StatusCode::kInvalidArgument,
                               {"box.gltf", "BoxTextured0.bin"}));

  const std::string ply = testing::SourcePath("tests/data/vertex_colours.ply");
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo plain, client_->UploadSceneFile(ply));
  client::SceneReadOptions with_colours;
  with_colours.vertex_colors = true;
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo coloured, client_->UploadSceneFile(ply, "", with_colours));
  EXPECT_NE(plain.name(), coloured.name());
  EXPECT_FALSE(plain.vertex_colors());
  EXPECT_TRUE(coloured.vertex_colors());
  EXPECT_EQ(plain.surfaces(), 1);
  EXPECT_EQ(coloured.surfaces(), 2);
}

TEST(SolveSpecTest, EmitOverridesSurviveTheProtoAndBadOnesNameTheirField) {
  JobSpec spec;
  spec.emit = {{"lamp", Rgb(1, 2, 3)}, {"floor", Rgb::Gray(0.5)}};
  absl::StatusOr<JobSpec> back = service::ToJobSpec(service::ToSolveSpec(spec, 0.1));
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->emit.size(), 2u);
  EXPECT_EQ(back->emit[0].name, "lamp");
  EXPECT_EQ(back->emit[0].exitance, Rgb(1, 2, 3));
  EXPECT_EQ(back->emit[1].exitance, Rgb::Gray(0.5));
  v1::SolveSpec bad;
  v1::EmitOverride* e = bad.add_emit();
  e->set_name("lamp");
  e->set_g(-1);
  absl::StatusOr<JobSpec> refused = service::ToJobSpec(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("solve.emit[0]"), std::string::npos)
      << refused.status();
}

TEST(SolveSpecTest, SkySurvivesTheProtoAndBadOnesNameTheirField) {
  JobSpec spec;
  spec.solve.sky.model = "overcast";
  spec.solve.sky.irradiance = Rgb(100, 110, 120);
  spec.solve.sky.up = Vec3(0, 0, 1);
  spec.solve.sky.samples = 64;
  ASSERT_OK_AND_ASSIGN(JobSpec back, service::ToJobSpec(service::ToSolveSpec(spec, 0.1)));
  EXPECT_EQ(back.solve.sky.model, "overcast");
  EXPECT_EQ(back.solve.sky.irradiance, Rgb(100, 110, 120));
  EXPECT_EQ(back.solve.sky.up, Vec3(0, 0, 1));
  EXPECT_EQ(back.solve.sky.samples, 64);
  // No sky on the wire is no sky.
  ASSERT_OK_AND_ASSIGN(JobSpec none, service::ToJobSpec(v1::SolveSpec()));
  EXPECT_FALSE(none.solve.sky.enabled());
  v1::SolveSpec bad;
  bad.mutable_sky()->set_model("overcast");
  bad.set_method("jacobi");
  bad.mutable_sky()->set_r(1);
  EXPECT_TRUE(testing::Refused(service::ToJobSpec(bad), absl::StatusCode::kInvalidArgument,
                               {"solve.sky.model", "progressive"}));
  bad.set_method("progressive");
  bad.mutable_sky()->set_r(0);
  EXPECT_TRUE(testing::Refused(service::ToJobSpec(bad), absl::StatusCode::kInvalidArgument,
                               {"solve.sky.model", "irradiance > 0"}));
}

// The enums of service.proto and the deprecated strings they replace are one value: either form
// sets it, both must agree, an undefined number is refused naming its field, and the CLI's specs
// carry both (older servers read the strings).
TEST(SolveSpecTest, EnumsAndTheirDeprecatedStringsAreOneValue) {
  // Every method of the registry, and "auto", has its enum.
  std::vector<std::string> names = {"auto"};
  for (const MethodInfo& m : Methods()) names.push_back(m.name);
  for (const std::string& name : names) {
    const v1::SolveMethod e = service::SolveMethodOf(name);
    EXPECT_NE(e, v1::SOLVE_METHOD_UNSPECIFIED) << name;
    EXPECT_EQ(service::SolveMethodName(e), name);
    v1::SolveSpec only_enum;
    only_enum.set_solve_method(e);
    ASSERT_OK_AND_ASSIGN(JobSpec spec, service::ToJobSpec(only_enum));
    EXPECT_EQ(spec.solve.method, name);
  }
  v1::SolveSpec s;
  s.set_solve_method(v1::SOLVE_METHOD_PROGRESSIVE);
  s.set_shooting_start(v1::SHOOTING_UNIFORM);
  s.mutable_formfactor()->set_sampling_pattern(v1::SAMPLING_RANDOM);
  s.mutable_view()->mutable_eye()->set_x(0.25);
  s.mutable_view()->mutable_eye()->set_y(1);
  s.mutable_view()->mutable_eye()->set_z(-3);
  s.mutable_view()->set_fov_degrees(30);
  ASSERT_OK_AND_ASSIGN(JobSpec spec, service::ToJobSpec(s));
  EXPECT_EQ(spec.solve.method, "progressive");
  EXPECT_FALSE(spec.solve.weighted_shooting);
  EXPECT_EQ(spec.solve.formfactor.sampling, "random");
  ASSERT_OK_AND_ASSIGN(Camera camera, ParseCamera(spec.camera, Camera()));
  EXPECT_EQ(camera.eye, Vec3(0.25, 1, -3));
  EXPECT_EQ(camera.fov, 30);
  EXPECT_EQ(camera.look, Camera().look);  // Unset: the default view's.

  // Back to the wire (as the CLI sends it): both forms, which read back the same.
  const v1::SolveSpec wire = service::ToSolveSpec(spec, 0.1);
  EXPECT_EQ(wire.method(), "progressive");
  EXPECT_EQ(wire.solve_method(), v1::SOLVE_METHOD_PROGRESSIVE);
  EXPECT_EQ(wire.shooting(), "uniform");
  EXPECT_EQ(wire.shooting_start(), v1::SHOOTING_UNIFORM);
  EXPECT_EQ(wire.formfactor().estimator(), v1::ESTIMATOR_MONTECARLO);
  EXPECT_EQ(wire.formfactor().sampling_pattern(), v1::SAMPLING_RANDOM);
  EXPECT_TRUE(wire.view().has_fov_degrees());
  EXPECT_EQ(wire.view().eye().x(), 0.25);
  EXPECT_FALSE(wire.view().has_look());

  // Both forms set, disagreeing: refused naming both fields.
  v1::SolveSpec both = s;
  both.set_method("jacobi");
  EXPECT_TRUE(testing::Refused(service::ToJobSpec(both), absl::StatusCode::kInvalidArgument,
                               {"solve.method 'jacobi'", "solve.solve_method", "disagree"}));
  both = s;
  both.set_camera("eye=0.25,1,-3 fov=31");
  EXPECT_TRUE(testing::Refused(service::ToJobSpec(both), absl::StatusCode::kInvalidArgument,
                               {"solve.camera", "solve.view", "not the same camera"}));
  both.set_camera("fov=30 eye=0.25,1,-3");  // The same camera, written otherwise: agrees.
  EXPECT_OK(service::ToJobSpec(both).status());
  // A camera given as `view` alone is named so in errors, NaN included.
  v1::SolveSpec bad_view;
  bad_view.mutable_view()->set_fov_degrees(0);
  EXPECT_TRUE(testing::Refused(service::ToJobSpec(bad_view), absl::StatusCode::kInvalidArgument,
                               {"solve.view", "fov"}));
  bad_view.mutable_view()->set_fov_degrees(std::nan(""));
  EXPECT_TRUE(testing::Refused(service::ToJobSpec(bad_view), absl::StatusCode::kInvalidArgument,
                               {"solve.view"}));
  both = s;
  both.mutable_formfactor()->set_sampling("sobol");
  EXPECT_TRUE(testing::Refused(service::ToJobSpec(both), absl::StatusCode::kInvalidArgument,
                               {"solve.formfactor.sampling 'sobol'", "sampling_pattern"}));
  // A number service.proto does not define.
  v1::SolveSpec undefined;
  undefined.set_solve_method(static_cast<v1::SolveMethod>(99));
  EXPECT_TRUE(testing::Refused(service::ToJobSpec(undefined), absl::StatusCode::kInvalidArgument,
                               {"solve.solve_method", "99"}));

  v1::ViewFactorSpec vf;
  vf.set_estimator(v1::ESTIMATOR_MONTECARLO);
  vf.set_sampling_pattern(v1::SAMPLING_HALTON);
  ASSERT_OK_AND_ASSIGN(ViewFactorOptions options, service::ToViewFactorOptions(vf));
  EXPECT_EQ(options.method, "montecarlo");
  EXPECT_EQ(options.sampling, "halton");
  vf.add_from_surfaces("floor");
  vf.add_from_surfaces("wall");
  ASSERT_OK_AND_ASSIGN(options, service::ToViewFactorOptions(vf));
  EXPECT_EQ(options.from, (std::vector<std::string>{"floor", "wall"}));
  EXPECT_EQ(service::ToViewFactorSpec(options).from_surfaces_size(), 2);
  vf.set_enforce("closure");
  EXPECT_TRUE(testing::Refused(service::ToViewFactorOptions(vf), absl::StatusCode::kInvalidArgument,
                               {"view_factor.enforce", "view_factor.from_surfaces"}));
  vf.set_enforce("");
  vf.set_method("hemicube");
  EXPECT_TRUE(testing::Refused(service::ToViewFactorOptions(vf), absl::StatusCode::kInvalidArgument,
                               {"view_factor.method", "view_factor.estimator"}));
}

// A view-factor job with thermal data (the exchange job): in the closed unit cube with one hot
// wall the hot wall loses what the others gain (energy), the Gebhart factors close (every row
// sums to 1) and are reciprocal, and the results hold exchange.csv and gebhart.csv.
TEST_F(ServiceApiTest, ViewFactorJobComputesRadiativeExchange) {
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo scene,
                       client_->UploadSceneFile(testing::SourcePath("scenes/furnace.json")));
  v1::CreateJobRequest request;
  request.set_scene(scene.name());
  v1::ViewFactorSpec* vf = request.mutable_view_factor();
  vf->set_estimator(v1::ESTIMATOR_MONTECARLO);
  vf->set_rays_per_surface(20000);
  vf->set_enforce("closure");
  for (const auto& [name, eps, t] :
       {std::tuple<const char*, double, double>{"x0", 1.0, 1000}, {"*", 0.4, 300}}) {
    v1::SurfaceThermal* th = vf->add_thermal();
    th->set_surface(name);
    th->set_emissivity(eps);
    th->set_temperature(t);
  }
  ASSERT_OK_AND_ASSIGN(v1::Job job, client_->CreateJob(request));
  ASSERT_TRUE(client_->Watch(job.name(), 0, true, nullptr).ok());
  ASSERT_OK_AND_ASSIGN(v1::Job ended, client_->GetJob(job.name()));
  ASSERT_EQ(ended.state(), v1::JOB_STATE_SUCCEEDED) << ended.error().message();
  std::vector<std::string> files;
  for (const v1::FileInfo& f : ended.results()) files.push_back(f.name());
  EXPECT_THAT(files, ::testing::IsSupersetOf({"viewfactors.mtx", "exchange.csv", "gebhart.csv"}));
  const v1::ViewFactorResult& r = ended.view_factor_result();
  ASSERT_EQ(r.exchange_size(), r.surfaces_size());
  double net = 0, hot = 0;
  for (const v1::SurfaceExchange& e : r.exchange()) {
    net += e.net();
    if (e.surface() == "x0") hot = e.net();
    EXPECT_EQ(e.emissivity(), e.surface() == "x0" ? 1.0 : 0.4) << e.surface();
  }
  EXPECT_GT(hot, 0);
  EXPECT_NEAR(net, 0, 1e-9 * hot);
  EXPECT_LT(r.gebhart_max_closure_error(), 1e-9);
  EXPECT_LT(r.gebhart_max_reciprocity_error(), 1e-9);
  testing::TempDir out;
  ASSERT_OK_AND_ASSIGN(std::vector<std::string> got,
                       client_->DownloadResults(job.name(), out.path(), "exchange.csv"));
  EXPECT_EQ(testing::ReadCsv(out.File("exchange.csv")).rows.size(), 6u);
}

// A job asked for with the enums and retried with the strings is the same request; Job.solve
// carries both forms, and Job.solve_method says what ran.
TEST_F(ServiceApiTest, EnumsAndStringsAreTheSameRequest) {
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo scene,
                       client_->UploadSceneFile(testing::SourcePath("scenes/cornell_box.obj")));
  v1::CreateJobRequest with_enums;
  with_enums.set_scene(scene.name());
  with_enums.set_request_id("enums");
  with_enums.mutable_solve()->set_solve_method(v1::SOLVE_METHOD_PROGRESSIVE);
  with_enums.mutable_solve()->set_max_rays(20000);
  with_enums.mutable_solve()->set_skip_image(true);
  v1::CreateJobRequest with_strings = with_enums;
  with_strings.mutable_solve()->clear_solve_method();
  with_strings.mutable_solve()->set_method("progressive");
  ASSERT_OK_AND_ASSIGN(v1::Job first, client_->CreateJob(with_enums));
  ASSERT_OK_AND_ASSIGN(v1::Job again, client_->CreateJob(with_strings));
  EXPECT_EQ(first.name(), again.name());
  EXPECT_EQ(first.solve().method(), "progressive");
  EXPECT_EQ(first.solve().solve_method(), v1::SOLVE_METHOD_PROGRESSIVE);
  // The same camera in the other form or another spelling, and defaults unset or spelt out,
  // are the same request.
  v1::CreateJobRequest as_text = with_enums;
  as_text.set_request_id("camera");
  as_text.mutable_solve()->set_camera("fov=39.0 eye=0,1,-4");
  v1::CreateJobRequest as_view = with_enums;
  as_view.set_request_id("camera");
  as_view.mutable_solve()->mutable_view()->set_fov_degrees(39);
  as_view.mutable_solve()->mutable_view()->mutable_eye()->set_y(1);
  as_view.mutable_solve()->mutable_view()->mutable_eye()->set_z(-4);
  as_view.mutable_solve()->mutable_view()->mutable_eye()->set_x(0);
  as_view.mutable_solve()->set_shooting_start(v1::SHOOTING_WEIGHTED);
  as_view.mutable_solve()->mutable_formfactor()->set_method("montecarlo");
  ASSERT_OK_AND_ASSIGN(v1::Job camera_job, client_->CreateJob(as_text));
  ASSERT_OK_AND_ASSIGN(v1::Job camera_again, client_->CreateJob(as_view));
  EXPECT_EQ(camera_job.name(), camera_again.name());
  EXPECT_EQ(camera_job.solve().camera(), "eye=0,1,-4 fov=39");
  v1::CreateJobRequest other = with_strings;
  other.mutable_solve()->set_method("jacobi");
  EXPECT_EQ(client_->CreateJob(other).status().code(), absl::StatusCode::kAlreadyExists);
  ASSERT_TRUE(client_->Watch(first.name(), 0, true, nullptr).ok());
  ASSERT_OK_AND_ASSIGN(v1::Job done, client_->GetJob(first.name()));
  EXPECT_EQ(done.method(), "progressive");
  EXPECT_EQ(done.solve_method(), v1::SOLVE_METHOD_PROGRESSIVE);
}

}  // namespace
}  // namespace radiosity
