// Bounded work against a real server on 127.0.0.1 (issue 15): scenes built to make work slow or
// huge are cancelled within a second whatever step they are in, and polygons past the documented
// limit are refused at upload naming the line.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"
#include "solver/geometry/scene.h"
#include "solver/util/file_io.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using service::testing::LongSolve;
using service::testing::WaitFor;
using testing::TempDir;

#ifdef __SANITIZE_ADDRESS__
constexpr double kCancelSeconds = 3;  // Instrumented code runs several times slower.
#else
constexpr double kCancelSeconds = 1;
#endif

// One face whose 4096 indices go round the same square 1024 times: 2047 coincident pieces that
// every ray near the square tests.
std::string RepeatedSquareObj() {
  std::string text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf";
  for (int k = 0; k < 1024; ++k) text += " 1 2 3 4";
  return text + "\n";
}

class ServiceBoundedWorkTest : public service::testing::ServiceTest {
 protected:
  // Uploads `obj` as NAME.obj, starts a solve that would run for a minute with the default
  // material made to emit, cancels it `delay` seconds after it starts running and returns how
  // long the cancel took to end the job (-1 if it did not within 30 s).
  double CancelLatency(const std::string& name, const std::string& obj, double delay) {
    TempDir dir;
    const std::string path = dir.File(name + ".obj");
    EXPECT_TRUE(WriteWholeFile(path, obj).ok());
    absl::StatusOr<v1::SceneInfo> scene = client_->UploadSceneFile(path);
    EXPECT_TRUE(scene.ok()) << scene.status();
    if (!scene.ok()) return -1;
    v1::CreateJobRequest request = LongSolve(scene->name(), 4096, 256);
    v1::EmitOverride* emit = request.mutable_solve()->add_emit();
    emit->set_name(kDefaultMaterialName);
    emit->set_r(1);
    emit->set_g(1);
    emit->set_b(1);
    absl::StatusOr<v1::Job> job = client_->CreateJob(request);
    EXPECT_TRUE(job.ok()) << job.status();
    if (!job.ok()) return -1;
    EXPECT_TRUE(WaitFor([&] { return State(job->name()) == v1::JOB_STATE_RUNNING; }, 60));
    std::this_thread::sleep_for(std::chrono::duration<double>(delay));
    const auto start = std::chrono::steady_clock::now();
    EXPECT_TRUE(client_->CancelJob(job->name()).ok());
    if (!WaitFor([&] { return State(job->name()) == v1::JOB_STATE_CANCELLED; }, 30)) return -1;
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
};

TEST_F(ServiceBoundedWorkTest, HostileScenesAreCancelledWithinASecond) {
  struct Case {
    std::string name;
    std::string obj;
    double delay;  // Seconds after RUNNING: in the solve, or (0) in reading and meshing.
  };
  const Case cases[] = {
      {"repeated_square", RepeatedSquareObj(), 1.0},
      {"polygon_4096", testing::RegularPolygonObj(static_cast<int>(kMaxFaceVertices)), 1.0},
      {"grid_while_meshing", service::testing::TriangleGridObj(300), 0.0},
      {"grid_while_solving", service::testing::TriangleGridObj(300), 4.0},
  };
  for (const Case& c : cases) {
    const double seconds = CancelLatency(c.name, c.obj, c.delay);
    EXPECT_GE(seconds, 0) << c.name << ": not cancelled within 30 s";
    EXPECT_LT(seconds, kCancelSeconds) << c.name;
  }
}

TEST_F(ServiceBoundedWorkTest, PolygonsPastTheLimitAreRefusedAtUploadNamingTheLine) {
  TempDir dir;
  const int n = static_cast<int>(kMaxFaceVertices) + 1;
  const std::string path = dir.File("polygon.obj");
  ASSERT_TRUE(WriteWholeFile(path, testing::RegularPolygonObj(n)).ok());
  absl::StatusOr<v1::SceneInfo> scene = client_->UploadSceneFile(path);
  ASSERT_FALSE(scene.ok());
  EXPECT_EQ(scene.status().code(), absl::StatusCode::kInvalidArgument) << scene.status();
  EXPECT_NE(scene.status().message().find(absl::StrCat("polygon.obj:", n + 1, ": ")),
            std::string::npos)
      << scene.status();
  EXPECT_NE(scene.status().message().find(absl::StrCat("at most ", kMaxFaceVertices)),
            std::string::npos)
      << scene.status();
}

}  // namespace
}  // namespace radiosity
