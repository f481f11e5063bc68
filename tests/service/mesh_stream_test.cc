// Mesh announcements on the snapshot stream (issue 7): a job with adaptive refinement streamed
// from its start against a real server on 127.0.0.1 announces every mesh before the values that
// use it, the final mesh is the one of elements.csv, a resumed watcher gets the geometry first,
// and `radiosity watch --preview-dir` keeps writing pictures across refinements (with `render`
// of the refined result matching the server's own image). Also the solver side: a refined mesh
// rebuilt from nothing but its element rectangles is the refined mesh.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>
#include <thread>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "client/client.h"
#include "client/preview.h"
#include "proto/api/exit_codes.h"
#include "server/metrics.h"
#include "server/server.h"
#include "solver/input/scene_files.h"
#include "solver/methods/adaptive.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

// After protobuf's headers: the other order fails to compile (bswap_32 in protobuf's port.h).
#include <OpenImageIO/imageio.h>

namespace radiosity {
namespace {

using service::testing::WaitFor;
using testing::RunCli;
using testing::SourcePath;
using testing::TempDir;

// ---------------------------------------------------------------------------------------------
// Solver: MeshFromElementRects

TEST(MeshFromElementRectsTest, RebuildsTwoRefinementPassesFromTheRectanglesAlone) {
  absl::StatusOr<Scene> scene = LoadSceneFile(SourcePath("scenes/cornell_box.obj"), nullptr);
  ASSERT_TRUE(scene.ok()) << scene.status();
  MeshOptions options;
  options.max_elements = 64;
  absl::StatusOr<Mesh> base = Mesh::Build(*scene, options);
  ASSERT_TRUE(base.ok()) << base.status();
  // Two passes, as adaptive refinement makes them (each split also balances the quadtrees).
  std::vector<int> first, second;
  for (int e = 0; e < static_cast<int>(base->elements().size()); e += 3) first.push_back(e);
  Mesh once = RefineMesh(*scene, *base, first);
  for (int e = 1; e < static_cast<int>(once.elements().size()); e += 4) second.push_back(e);
  Mesh twice = RefineMesh(*scene, once, second);
  ASSERT_GT(twice.elements().size(), once.elements().size());

  // The rectangles in reverse order: the rebuild numbers its elements its own way and `local`
  // maps between the two.
  const int n = static_cast<int>(twice.elements().size());
  std::vector<ElementRect> rects;
  for (int i = n - 1; i >= 0; --i) {
    const Element& e = twice.elements()[i];
    rects.push_back({e.face, e.u0, e.v0, e.u1, e.v1});
  }
  std::vector<int> local;
  absl::StatusOr<Mesh> rebuilt = MeshFromElementRects(*scene, *base, rects, &local);
  ASSERT_TRUE(rebuilt.ok()) << rebuilt.status();
  ASSERT_EQ(rebuilt->elements().size(), twice.elements().size());
  std::vector<char> seen(local.size(), 0);
  for (size_t i = 0; i < rects.size(); ++i) {
    ASSERT_GE(local[i], 0);
    ASSERT_LT(local[i], static_cast<int>(seen.size()));
    EXPECT_FALSE(seen[local[i]]) << i;
    seen[local[i]] = 1;
    const Element& want = twice.elements()[n - 1 - i];
    const Element& got = rebuilt->elements()[local[i]];
    EXPECT_EQ(got.face, want.face);
    EXPECT_EQ(got.surface, want.surface);
    EXPECT_EQ(got.u0, want.u0);
    EXPECT_EQ(got.v1, want.v1);
    EXPECT_DOUBLE_EQ(got.area, want.area);
    EXPECT_LT(Length(got.centroid - want.centroid), 1e-9 * twice.scale());
    // Ray hits find the same element as in the refined mesh.
    const double u = 0.25 * want.u0 + 0.75 * want.u1, v = 0.6 * want.v0 + 0.4 * want.v1;
    EXPECT_EQ(rebuilt->FindElement(want.face, u, v), local[i]);
  }

  // Not a refinement of the base mesh: a rectangle no halving reaches, or one missing.
  std::vector<ElementRect> bad = rects;
  bad[0].u1 = bad[0].u0 + 0.3f * (bad[0].u1 - bad[0].u0);
  EXPECT_EQ(MeshFromElementRects(*scene, *base, bad, &local).status().code(),
            absl::StatusCode::kInvalidArgument);
  bad = rects;
  bad.pop_back();
  EXPECT_EQ(MeshFromElementRects(*scene, *base, bad, &local).status().code(),
            absl::StatusCode::kInvalidArgument);
  bad = rects;
  bad[1] = bad[0];
  EXPECT_EQ(MeshFromElementRects(*scene, *base, bad, &local).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// ---------------------------------------------------------------------------------------------
// Service

// What a raw WatchJob stream carried, checked message by message as it arrives.
struct StreamLog {
  std::vector<int64_t> announced;     // Versions of the complete announcements, in order.
  std::vector<int64_t> value_meshes;  // mesh_version of each snapshot with radiosity.
  int64_t snapshots_with_values = 0;
  int messages = 0;
  int mesh_messages = 0;
  bool first_message_is_mesh = false;
  bool final_seen = false;
  std::vector<std::string> errors;  // Violations of the protocol.
  client::MeshGeometry mesh;        // The last complete announcement.
  std::vector<float> final_radiosity;
};

StreamLog ReadStream(client::Client& c, const std::string& job, int64_t after, bool include_mesh,
                     bool progress_only = false) {
  StreamLog log;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  v1::WatchJobRequest request;
  request.set_name(job);
  request.set_after_sequence(after);
  request.set_include_mesh(include_mesh);
  request.set_progress_only(progress_only);
  auto reader = c.stub().WatchJob(&context, request);
  client::MeshGeometry building;
  bool complete_mesh = false;
  int64_t values_total = 0;
  std::vector<float> values;
  v1::WatchJobResponse m;
  auto error = [&](const std::string& what) {
    log.errors.push_back(absl::StrCat("message ", log.messages, ": ", what));
  };
  while (reader->Read(&m)) {
    if (m.ByteSizeLong() >= (size_t{1} << 20)) error("1 MiB or more");
    if (log.messages++ == 0) log.first_message_is_mesh = m.has_mesh();
    if (m.has_mesh()) {
      ++log.mesh_messages;
      const v1::MeshGeometry& g = m.mesh();
      if (m.chunk_count() != 0 || m.radiosity_size() != 0) error("mesh message with values");
      if (g.version() != m.mesh_version()) error("mesh message of two versions");
      if (g.chunk_index() == 0) {
        building = client::MeshGeometry();
        building.version = g.version();
        building.faces = g.faces();
        building.origin[0] = g.origin().x();
        building.origin[1] = g.origin().y();
        building.origin[2] = g.origin().z();
      }
      if (g.first_element() != building.elements()) error("elements out of order");
      if (g.surface_names_size() > 0 &&
          g.surface_names_offset() != static_cast<int64_t>(building.surface_names.size())) {
        error("surface names out of order");
      }
      const int k = g.surface_size();
      if (g.uv_size() != 4 * k || g.corners_size() != 12 * k || g.normal_size() != 3 * k ||
          g.centroid_size() != 3 * k || g.area_size() != k || g.face_size() != k ||
          g.member_count_size() != k) {
        error("arrays of different lengths");
      }
      int64_t members = 0;
      for (int32_t count : g.member_count()) members += count;
      if (members != g.member_faces_size()) error("member faces not as counted");
      if (g.member_corners_size() != 0 && g.member_corners_size() != 12 * members) {
        error("member corners not 12 per member face");
      }
      building.surface_names.insert(building.surface_names.end(), g.surface_names().begin(),
                                    g.surface_names().end());
      building.surface.insert(building.surface.end(), g.surface().begin(), g.surface().end());
      building.face.insert(building.face.end(), g.face().begin(), g.face().end());
      building.uv.insert(building.uv.end(), g.uv().begin(), g.uv().end());
      building.corners.insert(building.corners.end(), g.corners().begin(), g.corners().end());
      building.normal.insert(building.normal.end(), g.normal().begin(), g.normal().end());
      building.centroid.insert(building.centroid.end(), g.centroid().begin(), g.centroid().end());
      building.area.insert(building.area.end(), g.area().begin(), g.area().end());
      building.member_count.insert(building.member_count.end(), g.member_count().begin(),
                                   g.member_count().end());
      building.member_faces.insert(building.member_faces.end(), g.member_faces().begin(),
                                   g.member_faces().end());
      building.member_corners.insert(building.member_corners.end(), g.member_corners().begin(),
                                     g.member_corners().end());
      if (g.chunk_index() + 1 == g.chunk_count()) {
        if (building.elements() != g.elements()) error("announcement short of elements");
        if (!log.announced.empty() && g.version() <= log.announced.back()) {
          error("mesh version did not grow");
        }
        log.announced.push_back(g.version());
        log.mesh = building;
        complete_mesh = true;
      }
      continue;
    }
    if (m.chunk_index() == 0) {
      values_total = m.radiosity_total();
      values.assign(static_cast<size_t>(values_total), 0.f);
      if (values_total > 0) {
        ++log.snapshots_with_values;
        log.value_meshes.push_back(m.mesh_version());
        if (include_mesh) {
          if (!complete_mesh) error("values before any mesh announcement");
          if (m.mesh_version() != log.mesh.version) error("values of another mesh version");
          if (values_total != 6 * log.mesh.elements()) {
            error(absl::StrCat(values_total, " values for ", log.mesh.elements(), " elements"));
          }
          if (m.elements() != log.mesh.elements()) error("element count is not the mesh's");
        }
      }
    }
    std::copy(m.radiosity().begin(), m.radiosity().end(), values.begin() + m.radiosity_offset());
    if (m.final() && m.chunk_index() + 1 == m.chunk_count()) {
      log.final_seen = true;
      log.final_radiosity = values;
    }
  }
  grpc::Status status = reader->Finish();
  if (!status.ok()) log.errors.push_back(absl::StrCat("stream: ", status.error_message()));
  return log;
}

// Linear RGB of an image file (EXR or PNG).
std::vector<float> ReadPixels(const std::string& path, int* width, int* height) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) return {};
  const OIIO::ImageSpec& spec = in->spec();
  *width = spec.width;
  *height = spec.height;
  std::vector<float> pixels(static_cast<size_t>(spec.width) * spec.height * 3);
  if (!in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, pixels.data())) pixels.clear();
  in->close();
  return pixels;
}

// One worker (TestServerOptions): a job queued behind a blocker is watched from its very first
// snapshot.
class ServiceMeshStreamTest : public service::testing::ServiceTest {
 protected:
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(ServiceTest::SetUp());
    address_ = address();
    ASSERT_OK_AND_ASSIGN(scene_, client_->UploadSceneFile(SourcePath("scenes/cornell_box.obj")));
  }

  // Starts a solve that keeps the only worker busy until cancelled: its name, once it runs.
  absl::StatusOr<std::string> StartBlocker() {
    v1::CreateJobRequest r = service::testing::LongSolve(scene_.name(), 100, 4);
    r.mutable_solve()->set_skip_mesh_ply(true);
    r.mutable_solve()->set_threads(1);  // Leaves a core to the clients (CLI processes) meanwhile.
    absl::StatusOr<std::string> job = CreateJobNamed(r);
    if (job.ok() && !WaitFor([&] { return State(*job) == v1::JOB_STATE_RUNNING; }, 30)) {
      return absl::DeadlineExceededError(*job + " did not start running within 30 s");
    }
    return job;
  }

  // The coarse Cornell box (64 elements first) refined up to 1600 elements in 3 passes at most.
  static v1::SolveSpec RefineSpec() {
    v1::SolveSpec s;
    s.mutable_mesh()->set_max_elements(1600);
    s.mutable_refine()->set_tolerance(0.2);
    s.mutable_refine()->set_max_passes(3);
    s.set_rays_per_element(200);
    s.set_snapshot_interval(0.01);
    s.set_width(32);
    s.set_height(32);
    s.set_skip_mesh_ply(true);
    return s;
  }

  absl::StatusOr<std::string> CreateRefineJob() {
    v1::CreateJobRequest r;
    r.set_scene(scene_.name());
    *r.mutable_solve() = RefineSpec();
    return CreateJobNamed(r);
  }

  std::string address_;
  v1::SceneInfo scene_;
};

// `radiosity render` of finished job `job` (through the server at `address`), with the job's
// camera and its size x size image, is the server's own image.exr: the client rebuilt the
// server's mesh from the scene and the announcement.
void ExpectRenderIsTheServersImage(client::Client& c, const std::string& address,
                                   const std::string& job, int size) {
  TempDir got, picture;
  ASSERT_TRUE(c.DownloadResults(job, got.path(), "image.exr").ok());
  auto rendered = RunCli({"--server", address, "render", job, "--out", picture.File("again.exr")});
  ASSERT_EQ(rendered.exit_code, kExitOk) << rendered.output;
  int w1 = 0, h1 = 0, w2 = 0, h2 = 0;
  std::vector<float> server_image = ReadPixels(got.File("image.exr"), &w1, &h1);
  std::vector<float> client_image = ReadPixels(picture.File("again.exr"), &w2, &h2);
  ASSERT_EQ(w1, size);
  ASSERT_EQ(h1, size);
  ASSERT_EQ(w2, w1);
  ASSERT_EQ(h2, h1);
  ASSERT_EQ(client_image.size(), server_image.size());
  double max_value = 0;
  for (float v : server_image) max_value = std::max<double>(max_value, v);
  ASSERT_GT(max_value, 0);
  for (size_t i = 0; i < server_image.size(); ++i) {
    // Half floats, and radiosity sent as float: agreement to a few parts in a thousand.
    EXPECT_NEAR(client_image[i], server_image[i], 4e-3 * server_image[i] + 1e-6 * max_value)
        << "pixel " << i / 3;
  }
}

// A finished solve of an uploaded OBJ: its job's name and its last snapshot.
struct Solved {
  std::string job;
  client::Snapshot last;
};

// Uploads `obj` as NAME.obj (with `mtl` beside it as NAME.mtl, which the OBJ names) and solves it
// on at most `max_elements` elements with `max_rays` rays and a `size` x `size` image, no PLY.
absl::StatusOr<Solved> SolveObj(client::Client& c, const TempDir& dir, const std::string& name,
                                const std::string& obj, const std::string& mtl,
                                int64_t max_elements, int64_t max_rays, int size) {
  dir.Write(name + ".mtl", mtl);
  absl::StatusOr<v1::SceneInfo> scene = c.UploadSceneFile(dir.Write(name + ".obj", obj));
  if (!scene.ok()) return scene.status();
  v1::CreateJobRequest r;
  r.set_scene(scene->name());
  r.mutable_solve()->mutable_mesh()->set_max_elements(max_elements);
  r.mutable_solve()->set_max_rays(max_rays);
  r.mutable_solve()->set_width(size);
  r.mutable_solve()->set_height(size);
  r.mutable_solve()->set_skip_mesh_ply(true);
  absl::StatusOr<v1::Job> job = c.CreateJob(r);
  if (!job.ok()) return job.status();
  absl::StatusOr<client::Snapshot> last = c.Watch(job->name(), 0, true, nullptr);
  if (!last.ok()) return last.status();
  return Solved{job->name(), *std::move(last)};
}

// JobProgress.phase: a progress-only watcher sees meshing (no elements yet, all power unshot),
// solving and writing, in that order, meshing and writing each from 0 to 1; a watcher of values
// gets values in every snapshot, writing's included (the newest again), and no meshing.
TEST_F(ServiceMeshStreamTest, WatchersSeeMeshingSolvingAndWritingInOrder) {
  ASSERT_OK_AND_ASSIGN(const std::string blocker, StartBlocker());
  v1::CreateJobRequest r;
  r.set_scene(scene_.name());
  r.mutable_solve()->mutable_mesh()->set_max_elements(20000);
  r.mutable_solve()->set_max_rays(200000);
  r.mutable_solve()->set_width(16);
  r.mutable_solve()->set_height(16);
  ASSERT_OK_AND_ASSIGN(const std::string job, CreateJobNamed(r));
  std::vector<client::Snapshot> progress, full;
  absl::Status progress_status, full_status;
  // A watcher of the job on a connection of its own, recording what it sees.
  auto watch = [&, server = server_.get()](bool progress_only, std::vector<client::Snapshot>* seen,
                                           absl::Status* status) {
    return std::thread([=, &job] {
      std::unique_ptr<client::Client> c = service::testing::ConnectTo(*server);
      *status = c->Watch(job, 0, progress_only, [&](const client::Snapshot& s) {
                   seen->push_back(s);
                   return true;
                 }).status();
    });
  };
  std::thread progress_watcher = watch(/*progress_only=*/true, &progress, &progress_status);
  std::thread full_watcher = watch(/*progress_only=*/false, &full, &full_status);
  ASSERT_TRUE(WaitFor([&] { return server_->metrics().watchers.load() >= 2; }, 30));
  ASSERT_TRUE(client_->CancelJob(blocker).ok());  // The job starts now.
  progress_watcher.join();
  full_watcher.join();
  ASSERT_OK(progress_status);
  ASSERT_OK(full_status);

  ASSERT_GE(progress.size(), 3u);
  EXPECT_EQ(progress.front().progress.phase(), v1::JOB_PHASE_MESHING);
  EXPECT_EQ(progress.front().elements, 0);
  EXPECT_EQ(progress.front().progress.unshot_fraction(), 1);
  std::vector<v1::JobPhase> phases;
  double fraction = 0;
  bool gap = false;  // A reader slower than the job skips snapshots, and says so.
  for (const client::Snapshot& s : progress) {
    gap = gap || s.resync;
    if (s.final) break;
    if (phases.empty() || phases.back() != s.progress.phase()) {
      phases.push_back(s.progress.phase());
      fraction = 0;
    }
    EXPECT_GE(s.progress.phase_fraction(), fraction) << s.sequence;
    fraction = s.progress.phase_fraction();
    if (s.progress.phase() == v1::JOB_PHASE_WRITING) {
      EXPECT_GT(s.elements, 0);
    }
  }
  if (!gap) {
    EXPECT_THAT(phases, ::testing::ElementsAre(v1::JOB_PHASE_MESHING, v1::JOB_PHASE_SOLVING,
                                               v1::JOB_PHASE_WRITING));
    EXPECT_EQ(fraction, 1);
  }
  ASSERT_FALSE(full.empty());
  bool writing_seen = false;
  for (const client::Snapshot& s : full) {
    EXPECT_NE(s.progress.phase(), v1::JOB_PHASE_MESHING) << s.sequence;
    EXPECT_EQ(static_cast<int64_t>(s.radiosity.size()), 6 * s.elements) << s.sequence;
    EXPECT_GT(s.elements, 0) << s.sequence;
    writing_seen = writing_seen || (!s.final && s.progress.phase() == v1::JOB_PHASE_WRITING);
  }
  // Writing repeats the last values: the same as the final snapshot's.
  if (writing_seen) {
    for (const client::Snapshot& s : full) {
      if (!s.final && s.progress.phase() == v1::JOB_PHASE_WRITING) {
        EXPECT_EQ(s.radiosity, full.back().radiosity);
      }
    }
  }
}

TEST_F(ServiceMeshStreamTest, EveryMeshIsAnnouncedBeforeTheValuesThatUseIt) {
  ASSERT_OK_AND_ASSIGN(const std::string blocker, StartBlocker());
  ASSERT_OK_AND_ASSIGN(const std::string job, CreateRefineJob());
  StreamLog log;
  std::thread watcher([&, server = server_.get()] {
    std::unique_ptr<client::Client> c = service::testing::ConnectTo(*server);
    log = ReadStream(*c, job, 0, /*include_mesh=*/true);
  });
  ASSERT_TRUE(WaitFor([&] { return server_->metrics().watchers.load() >= 1; }, 30));
  ASSERT_TRUE(client_->CancelJob(blocker).ok());  // The refinement job starts now.
  watcher.join();

  EXPECT_TRUE(log.errors.empty()) << absl::StrJoin(log.errors, "\n");
  ASSERT_TRUE(log.final_seen);
  EXPECT_TRUE(log.first_message_is_mesh);
  // The watcher's first snapshot is the job's first (first mesh) and its last is the final one
  // (refined mesh), whatever was skipped in between.
  ASSERT_GE(log.announced.size(), 2u);
  std::set<int64_t> used(log.value_meshes.begin(), log.value_meshes.end());
  EXPECT_GE(used.size(), 2u);
  absl::StatusOr<v1::Job> ended = client_->GetJob(job);
  ASSERT_TRUE(ended.ok()) << ended.status();
  ASSERT_EQ(ended->state(), v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(ended->mesh().mesh_version(), log.announced.back());
  EXPECT_EQ(ended->mesh().elements(), log.mesh.elements());
  EXPECT_EQ(log.mesh.faces, ended->mesh().faces());
  EXPECT_GT(log.mesh.elements(), 64);  // Refined beyond the first mesh.
  // The job has ended and its watcher left: no geometry is held any more (it is on disk).
  EXPECT_TRUE(WaitFor([] { return service::MeshBytesLive().load() == 0; }, 10))
      << service::MeshBytesLive().load();

  // The final mesh is the mesh of elements.csv: same elements, surfaces, centroids and areas.
  TempDir out;
  ASSERT_TRUE(client_->DownloadResults(job, out.path(), "elements.csv").ok());
  testing::Csv csv = testing::ReadCsv(out.File("elements.csv"));
  const client::MeshGeometry& g = log.mesh;
  ASSERT_EQ(static_cast<int64_t>(csv.rows.size()), g.elements());
  const int cs = csv.Column("surface"), cx = csv.Column("cx"), ca = csv.Column("area");
  ASSERT_GE(cs, 0);
  ASSERT_GE(cx, 0);
  ASSERT_GE(ca, 0);
  double total_area = 0, corner_area = 0;
  for (int64_t i = 0; i < g.elements(); ++i) {
    const auto& row = csv.rows[i];
    ASSERT_LT(g.surface[i], static_cast<int>(g.surface_names.size()));
    EXPECT_EQ(row[cs], g.surface_names[g.surface[i]]) << i;
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(std::stod(row[cx + k]), g.origin[k] + g.centroid[3 * i + k], 0.02) << i;
    }
    EXPECT_NEAR(std::stod(row[ca]), g.area[i], 1e-4 * g.area[i]) << i;
    total_area += g.area[i];
    // The corners span the element (centroid within their box), facing along the normal.
    Vec3 c[4];
    for (int k = 0; k < 4; ++k) {
      c[k] = {g.corners[12 * i + 3 * k], g.corners[12 * i + 3 * k + 1],
              g.corners[12 * i + 3 * k + 2]};
    }
    const Vec3 n{g.normal[3 * i], g.normal[3 * i + 1], g.normal[3 * i + 2]};
    const Vec3 cross = Cross(c[2] - c[0], c[3] - c[1]);
    corner_area += 0.5 * Length(cross);
    EXPECT_NEAR(Length(n), 1, 1e-5) << i;
    EXPECT_GT(Dot(cross, n), 0) << i;
    const Vec3 centroid{g.centroid[3 * i], g.centroid[3 * i + 1], g.centroid[3 * i + 2]};
    for (int k = 0; k < 3; ++k) {
      const double lo = std::min({c[0][k], c[1][k], c[2][k], c[3][k]});
      const double hi = std::max({c[0][k], c[1][k], c[2][k], c[3][k]});
      EXPECT_GE(centroid[k], lo - 1e-3) << i;
      EXPECT_LE(centroid[k], hi + 1e-3) << i;
    }
  }
  // Conservation: the elements tile the scene (its total area, as the upload measured it).
  EXPECT_NEAR(total_area, scene_.area(), 1e-4 * scene_.area());
  EXPECT_NEAR(corner_area, scene_.area(), 5e-3 * scene_.area());
}

TEST_F(ServiceMeshStreamTest, ResumedWatchersGetTheMeshBeforeTheValues) {
  ASSERT_OK_AND_ASSIGN(const std::string blocker, StartBlocker());
  ASSERT_OK_AND_ASSIGN(const std::string job, CreateRefineJob());
  // A watcher that leaves after its first snapshot, and one that resumes after it, live (or, if
  // the job is quick, from what the server keeps of the ended job: either must announce first).
  client::Snapshot first;
  absl::Status first_status;
  std::thread watcher([&, server = server_.get()] {
    std::unique_ptr<client::Client> c = service::testing::ConnectTo(*server);
    first_status = c->Watch(
                        job, 0, false,
                        [&](const client::Snapshot& s) {
                          first = s;
                          return false;
                        },
                        nullptr, /*include_mesh=*/true)
                       .status();
  });
  ASSERT_TRUE(WaitFor([&] { return server_->metrics().watchers.load() >= 1; }, 30));
  ASSERT_TRUE(client_->CancelJob(blocker).ok());
  watcher.join();
  EXPECT_EQ(first_status.code(), absl::StatusCode::kCancelled);  // It stopped itself.
  ASSERT_GT(first.sequence, 0);
  ASSERT_TRUE(first.mesh) << "the first snapshot came without its mesh";
  EXPECT_EQ(first.mesh_version, first.mesh->version);
  EXPECT_EQ(static_cast<int64_t>(first.radiosity.size()), 6 * first.mesh->elements());

  int with_values = 0;
  absl::StatusOr<client::Snapshot> last = client_->Watch(
      job, first.sequence, false,
      [&](const client::Snapshot& s) {
        if (s.radiosity.empty()) return true;
        ++with_values;
        // Snapshot::mesh is set only from an announcement on this stream of the same version.
        EXPECT_TRUE(s.mesh) << s.sequence;
        if (s.mesh) {
          EXPECT_EQ(static_cast<int64_t>(s.radiosity.size()), 6 * s.mesh->elements());
        }
        return true;
      },
      nullptr, /*include_mesh=*/true);
  ASSERT_TRUE(last.ok()) << last.status();
  EXPECT_GE(with_values, 1);
  EXPECT_GT(last->sequence, first.sequence);
  ASSERT_TRUE(last->mesh);
  EXPECT_GT(last->mesh->version, first.mesh->version);  // Refined since the first snapshot.

  // The ended job, resumed just before its final snapshot: from disk, mesh first.
  StreamLog resumed = ReadStream(*client_, job, last->sequence - 1, /*include_mesh=*/true);
  EXPECT_TRUE(resumed.errors.empty()) << absl::StrJoin(resumed.errors, "\n");
  EXPECT_TRUE(resumed.first_message_is_mesh);
  ASSERT_EQ(resumed.announced.size(), 1u);
  EXPECT_EQ(resumed.announced[0], last->mesh->version);
  EXPECT_EQ(resumed.mesh.centroid, last->mesh->centroid);
  EXPECT_EQ(resumed.mesh.uv, last->mesh->uv);
  EXPECT_EQ(resumed.final_radiosity, last->radiosity);

  // Without include_mesh (clients that predate announcements) or with progress_only: no
  // geometry, the same values.
  StreamLog plain = ReadStream(*client_, job, last->sequence - 1, /*include_mesh=*/false);
  EXPECT_TRUE(plain.errors.empty()) << absl::StrJoin(plain.errors, "\n");
  EXPECT_TRUE(plain.announced.empty());
  EXPECT_FALSE(plain.first_message_is_mesh);
  EXPECT_EQ(plain.final_radiosity, last->radiosity);
  ASSERT_EQ(plain.value_meshes.size(), 1u);
  EXPECT_EQ(plain.value_meshes[0], last->mesh->version);
  StreamLog progress =
      ReadStream(*client_, job, last->sequence - 1, /*include_mesh=*/true, /*progress_only=*/true);
  EXPECT_TRUE(progress.errors.empty()) << absl::StrJoin(progress.errors, "\n");
  EXPECT_TRUE(progress.announced.empty());
  EXPECT_TRUE(progress.final_seen);

  // The previewer renders in the server's element order, whatever its own numbering: the same
  // geometry and values listed backwards give the same picture.
  absl::StatusOr<v1::Job> j = client_->GetJob(job);
  ASSERT_TRUE(j.ok()) << j.status();
  TempDir scene_dir, pictures;
  absl::StatusOr<std::unique_ptr<client::Previewer>> previewer =
      client::Previewer::Create(*client_, *j, scene_dir.path());
  ASSERT_TRUE(previewer.ok()) << previewer.status();
  client::Previewer& p = **previewer;
  // The first mesh, of a sixteenth of the budget, as the server's first snapshot had it.
  EXPECT_EQ(p.elements(), first.mesh->elements());
  EXPECT_LE(p.elements(), 1600 / 16);
  ASSERT_TRUE(p.UseMesh(*last->mesh).ok());
  EXPECT_EQ(p.elements(), last->mesh->elements());
  ASSERT_TRUE(p.Render(last->radiosity, "", 16, 16, pictures.File("a.exr"), "").ok());
  const client::MeshGeometry& g = *last->mesh;
  client::MeshGeometry backwards = g;
  std::vector<float> values(last->radiosity.size());
  const int64_t n = g.elements();
  auto reverse = [n](const auto& from, auto* to, int stride) {
    for (int64_t i = 0; i < n; ++i) {
      std::copy_n(from.begin() + stride * i, stride, to->begin() + stride * (n - 1 - i));
    }
  };
  reverse(g.surface, &backwards.surface, 1);
  reverse(g.face, &backwards.face, 1);
  reverse(g.uv, &backwards.uv, 4);
  reverse(g.corners, &backwards.corners, 12);
  reverse(g.normal, &backwards.normal, 3);
  reverse(g.centroid, &backwards.centroid, 3);
  reverse(g.area, &backwards.area, 1);
  reverse(last->radiosity, &values, 6);
  backwards.version = g.version + 1;
  ASSERT_TRUE(p.UseMesh(backwards).ok());
  ASSERT_TRUE(p.Render(values, "", 16, 16, pictures.File("b.exr"), "").ok());
  int w = 0, h = 0;
  std::vector<float> a = ReadPixels(pictures.File("a.exr"), &w, &h);
  ASSERT_EQ(a.size(), 16u * 16 * 3);
  EXPECT_EQ(ReadPixels(pictures.File("b.exr"), &w, &h), a);
  EXPECT_GT(*std::max_element(a.begin(), a.end()), 0);
  // An announcement that is not a refinement of the local first mesh is refused.
  client::MeshGeometry broken = g;
  broken.uv[2] = broken.uv[0] + 0.3f * (broken.uv[2] - broken.uv[0]);
  EXPECT_EQ(p.UseMesh(broken).code(), absl::StatusCode::kFailedPrecondition);
}

TEST_F(ServiceMeshStreamTest, WatchPreviewsKeepComingAcrossRefinementsAndRenderRebuildsTheMesh) {
  ASSERT_OK_AND_ASSIGN(const std::string blocker, StartBlocker());
  auto submitted = RunCli({"--server", address_, "solve", SourcePath("scenes/cornell_box.obj"),
                           "--detach", "--max-elements", "1600", "--refine", "0.2",
                           "--refine-passes", "3", "--rays-per-element", "200",
                           "--snapshot-interval", "0.01", "--width", "32", "--height", "32"});
  ASSERT_EQ(submitted.exit_code, kExitOk) << submitted.output;
  std::vector<std::string> lines = absl::StrSplit(submitted.output, '\n', absl::SkipEmpty());
  ASSERT_FALSE(lines.empty());
  const std::string job = lines.back();
  ASSERT_EQ(job.rfind("jobs/", 0), 0u) << submitted.output;

  TempDir previews;
  testing::CommandResult watched;
  std::thread watcher([&] {
    watched = RunCli({"--server", address_, "--json", "watch", job, "--preview-dir",
                      previews.path(), "--preview-width", "16", "--preview-height", "12"});
  });
  ASSERT_TRUE(WaitFor([&] { return server_->metrics().watchers.load() >= 1; }, 60));
  ASSERT_TRUE(client_->CancelJob(blocker).ok());
  watcher.join();
  ASSERT_EQ(watched.exit_code, kExitOk) << watched.output;
  EXPECT_EQ(watched.output.find("have no preview"), std::string::npos) << watched.output;

  // One PNG per snapshot, of every mesh version the watcher saw.
  std::set<std::string> versions;
  int snapshots = 0;
  for (absl::string_view view : absl::StrSplit(watched.output, '\n', absl::SkipEmpty())) {
    const std::string line(view);
    if (line.rfind("{\"event\":\"snapshot\"", 0) != 0) continue;
    ++snapshots;
    const size_t at = line.find("\"sequence\":");
    ASSERT_NE(at, std::string::npos) << line;
    const long long sequence = std::stoll(line.substr(at + 11));
    const size_t mv = line.find("\"mesh_version\":");
    ASSERT_NE(mv, std::string::npos) << line;
    versions.insert(line.substr(mv + 15, line.find_first_of(",}", mv) - mv - 15));
    const std::string png = previews.File(absl::StrFormat("snapshot-%06d.png", sequence));
    int w = 0, h = 0;
    EXPECT_FALSE(ReadPixels(png, &w, &h).empty()) << png;
    EXPECT_EQ(w, 16);
    EXPECT_EQ(h, 12);
  }
  EXPECT_GE(snapshots, 2);
  EXPECT_GE(versions.size(), 2u) << watched.output;

  // `render` of the refined result, with the job's camera and size, is the server's own image:
  // the client rebuilt the server's refined mesh from the announcement.
  ExpectRenderIsTheServersImage(*client_, address_, job, 32);
}

TEST_F(ServiceMeshStreamTest, LargeAnnouncementsAreChunkedBelow1MiB) {
  // 60 floor tiles under a light, each its own surface with a 3000-byte name (one of 5000 bytes,
  // which the announcement cuts to 4096, one with a character across that cut): the names need
  // several messages, and so do the 20000 elements.
  TempDir dir;
  std::string obj = "mtllib tiles.mtl\n", names[61];
  int v = 0;
  for (int i = 0; i <= 60; ++i) {
    names[i] = absl::StrCat(std::string(i == 7 ? 5000 : 3000, 'a' + i % 26), i);
    if (i == 3) names[i] = std::string(4095, 'e') + "\xc3\xa9";  // Ends in a 2-byte e-acute.
    const bool light = i == 60;
    const double x0 = light ? 0 : i, x1 = light ? 60 : i + 1, y = light ? 5 : 0;
    absl::StrAppend(&obj, "g ", names[i], "\nusemtl ", light ? "light" : "tile", "\n");
    absl::StrAppendFormat(&obj, "v %g %g 0\nv %g %g 1\nv %g %g 1\nv %g %g 0\n", x0, y, x0, y, x1, y,
                          x1, y);
    if (light) {
      absl::StrAppendFormat(&obj, "f %d %d %d %d\n", v + 4, v + 3, v + 2, v + 1);
    } else {
      absl::StrAppendFormat(&obj, "f %d %d %d %d\n", v + 1, v + 2, v + 3, v + 4);
    }
    v += 4;
  }
  ASSERT_OK_AND_ASSIGN(
      Solved solved, SolveObj(*client_, dir, "tiles", obj,
                              "newmtl tile\nKd 0.5 0.5 0.5\nnewmtl light\nKd 0 0 0\nKe 10 10 10\n",
                              20000, 20000, 4));
  const client::Snapshot* last = &solved.last;
  ASSERT_EQ(last->state, v1::JOB_STATE_SUCCEEDED);

  StreamLog log = ReadStream(*client_, solved.job, last->sequence - 1, /*include_mesh=*/true);
  EXPECT_TRUE(log.errors.empty()) << absl::StrJoin(log.errors, "\n");
  ASSERT_EQ(log.announced.size(), 1u);
  EXPECT_GE(log.mesh_messages, 3);
  EXPECT_GT(log.mesh.elements(), 3 * 8192 / 2);
  EXPECT_EQ(log.mesh.elements(), last->elements);
  ASSERT_EQ(log.mesh.surface_names.size(), 61u);
  for (int i = 0; i <= 60; ++i) {
    if (i == 3) continue;
    EXPECT_EQ(log.mesh.surface_names[i], names[i].substr(0, 4096)) << i;
  }
  // Cut at 4096 bytes, but not inside a character (protobuf strings must be UTF-8).
  EXPECT_EQ(log.mesh.surface_names[3], std::string(4095, 'e'));
  double area = 0;
  for (float a : log.mesh.area) area += a;
  EXPECT_NEAR(area, 120, 1e-3);  // 60 tiles of 1 and a light of 60.
}

TEST_F(ServiceMeshStreamTest, AgglomeratedElementsAnnounceTheirFacesAndRenderTheSame) {
  // A floor of 190 x 190 cells of two triangles each (72 200 faces, each far smaller than an
  // element of a 60-element mesh) under a square light: the floor's elements hold about a
  // thousand triangles each, more member faces than one message carries.
  TempDir dir;
  constexpr int kCells = 190;
  std::string obj = "mtllib floor.mtl\ng floor\nusemtl floor\n";
  for (int j = 0; j <= kCells; ++j) {
    for (int i = 0; i <= kCells; ++i) {
      absl::StrAppendFormat(&obj, "v %g 0 %g\n", static_cast<double>(i) / kCells,
                            static_cast<double>(j) / kCells);
    }
  }
  auto vertex = [](int i, int j) { return j * (kCells + 1) + i + 1; };
  for (int j = 0; j < kCells; ++j) {
    for (int i = 0; i < kCells; ++i) {
      // Counter-clockwise seen from above (+y).
      absl::StrAppendFormat(&obj, "f %d %d %d\nf %d %d %d\n", vertex(i, j), vertex(i, j + 1),
                            vertex(i + 1, j + 1), vertex(i, j), vertex(i + 1, j + 1),
                            vertex(i + 1, j));
    }
  }
  const int light = (kCells + 1) * (kCells + 1) + 1;
  absl::StrAppendFormat(&obj,
                        "g light\nusemtl light\nv 0.3 1 0.3\nv 0.7 1 0.3\nv 0.7 1 0.7\n"
                        "v 0.3 1 0.7\nf %d %d %d %d\n",
                        light, light + 1, light + 2, light + 3);
  ASSERT_OK_AND_ASSIGN(
      Solved solved, SolveObj(*client_, dir, "floor", obj,
                              "newmtl floor\nKd 0.5 0.5 0.5\nnewmtl light\nKd 0 0 0\nKe 10 10 10\n",
                              60, 200000, 24));
  ASSERT_EQ(solved.last.state, v1::JOB_STATE_SUCCEEDED);
  const std::string& job = solved.job;

  StreamLog log = ReadStream(*client_, job, solved.last.sequence - 1, /*include_mesh=*/true);
  EXPECT_TRUE(log.errors.empty()) << absl::StrJoin(log.errors, "\n");
  const client::MeshGeometry& g = log.mesh;
  ASSERT_EQ(g.faces, 2 * kCells * kCells + 1);
  ASSERT_EQ(static_cast<int64_t>(g.member_count.size()), g.elements());
  EXPECT_LE(g.elements(), 60);
  EXPECT_GE(log.mesh_messages, 2) << "member faces beyond one message's share";
  // Every traced face is in exactly one agglomerated element, or cut into leaves of its own.
  std::vector<int> as_member(static_cast<size_t>(g.faces), 0), as_leaf(as_member);
  size_t next = 0;
  double area = 0;
  for (int64_t e = 0; e < g.elements(); ++e) {
    area += g.area[e];
    if (g.member_count[e] == 0) {
      ++as_leaf[g.face[e]];
      continue;
    }
    EXPECT_EQ(g.member_faces[next], g.face[e]) << "an element's face is its first member";
    for (int m = 0; m < g.member_count[e]; ++m) ++as_member[g.member_faces[next++]];
  }
  EXPECT_EQ(next, g.member_faces.size());
  for (size_t f = 0; f < as_member.size(); ++f) {
    EXPECT_TRUE(as_member[f] == 1 ? as_leaf[f] == 0 : as_member[f] == 0 && as_leaf[f] > 0)
        << "face " << f << ": member of " << as_member[f] << ", leaves " << as_leaf[f];
  }
  EXPECT_NEAR(area, 1 + 0.16, 1e-3);

  // What a client draws: each leaf's corners, each agglomerated element's member faces' corners.
  // They outline the OBJ's triangles: every corner on the grid's lines (or the hypotenuse), on
  // the floor's plane, each element's outlines adding up to its area, all of them to the scene's.
  ASSERT_EQ(g.member_corners.size(), 12 * g.member_faces.size());
  auto quad_area = [](const float* c) {  // Two triangles: (0, 1, 2) and (0, 2, 3).
    auto tri = [&](int a, int b, int d) {
      const Vec3 p(c[3 * a], c[3 * a + 1], c[3 * a + 2]), q(c[3 * b], c[3 * b + 1], c[3 * b + 2]),
          r(c[3 * d], c[3 * d + 1], c[3 * d + 2]);
      return 0.5 * Length(Cross(q - p, r - p));
    };
    return tri(0, 1, 2) + tri(0, 2, 3);
  };
  double outlined = 0;
  next = 0;
  for (int64_t e = 0; e < g.elements(); ++e) {
    if (g.member_count[e] == 0) {
      outlined += quad_area(&g.corners[12 * e]);
      continue;
    }
    double element = 0;
    for (int m = 0; m < g.member_count[e]; ++m, ++next) {
      const float* c = &g.member_corners[12 * next];
      element += quad_area(c);
      for (int k = 0; k < 4; ++k) {
        const double x = c[3 * k] + g.origin[0], y = c[3 * k + 1] + g.origin[1],
                     z = c[3 * k + 2] + g.origin[2];
        EXPECT_TRUE(std::abs(y) < 1e-6 || std::abs(y - 1) < 1e-6) << "off the floor and light";
        // On a grid line in x or in z, or on a cell's diagonal (x - z a multiple of the cell).
        const double gx = x * kCells, gz = z * kCells;
        EXPECT_TRUE(std::abs(gx - std::round(gx)) < 1e-3 || std::abs(gz - std::round(gz)) < 1e-3 ||
                    std::abs(gx - gz - std::round(gx - gz)) < 1e-3)
            << "element " << e << " corner " << k << " at " << x << ", " << z;
      }
    }
    EXPECT_NEAR(element, g.area[e], 1e-5 * g.area[e] + 1e-9) << "element " << e;
    outlined += element;
  }
  EXPECT_NEAR(outlined, 1 + 0.16, 1e-4);

  // `render` rebuilds the agglomerated mesh from the scene and the announcement, and draws the
  // server's own image.
  ExpectRenderIsTheServersImage(*client_, address_, job, 24);
}

}  // namespace
}  // namespace radiosity
