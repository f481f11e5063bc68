// Helpers shared by the tests: paths, temporary directories, running the CLI, reading CSV.
#ifndef RADIOSITY_TESTS_TESTING_TEST_UTIL_H_
#define RADIOSITY_TESTS_TESTING_TEST_UTIL_H_

#include <map>
#include <string>
#include <vector>

#include "solver/geometry/scene.h"

namespace radiosity::testing {

// Absolute path of a file in the source tree, e.g. SourcePath("scenes/cornell_box.obj").
std::string SourcePath(const std::string& relative);

// A fresh empty directory under the system temp dir, removed when the object dies.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const std::string& path() const { return path_; }
  std::string File(const std::string& name) const { return path_ + "/" + name; }
  // Writes `text` to File(name) and returns that path.
  std::string Write(const std::string& name, const std::string& text) const;

 private:
  std::string path_;
};

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

// Runs the radiosity CLI with the given arguments (shell-quoted here) and captures its output.
CommandResult RunCli(const std::vector<std::string>& args);

// Reads a whole file; empty if missing.
std::string ReadFile(const std::string& path);

// A CSV file: its header and rows, split on commas (no quoting needed for our files).
struct Csv {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  int Column(const std::string& name) const;  // -1 if absent
};
Csv ReadCsv(const std::string& path);

// An axis-aligned closed box [0,sx]x[0,sy]x[0,sz] of six quads facing inward, one surface per
// side ("x0", "x1", "y0", "y1", "z0", "z1"), all with one material.
Scene MakeClosedBox(double sx, double sy, double sz, const Material& material);

// Adds the parallelogram corner, corner + u, corner + u + v, corner + v (front facing u x v) as a
// face of `surface`, created with `material` if the scene has no surface of that name yet.
void AddRect(Scene* s, const std::string& surface, int material, const Vec3& corner, const Vec3& u,
             const Vec3& v);

}  // namespace radiosity::testing

#endif  // RADIOSITY_TESTS_TESTING_TEST_UTIL_H_
