#include "solver/results/elements_csv.h"

#include <vector>

#include "solver/geometry/interpolation.h"
#include "solver/results/text_writer.h"

namespace radiosity {

namespace {

absl::Status WriteCsvSide(const Mesh& mesh, const Solution& solution,
                          const std::vector<std::string>& names, int side,
                          const std::string& path) {
  OutputFile file(path, side == 0 ? "elements CSV" : "back-side elements CSV");
  absl::Status st = file.Open();
  if (!st.ok()) return st;
  st = file.Write("surface,element,cx,cy,cz,area,r,g,b\n");
  if (!st.ok()) return st;
  const auto& elements = mesh.elements();
  st = WriteBlocks(
      &file, static_cast<int64_t>(elements.size()),
      [&](int64_t begin, int64_t end, std::string* out) {
        for (int64_t i = begin; i < end; ++i) {
          const Element& e = elements[i];
          if (!mesh.sides().exists(Slot(static_cast<int>(i), side))) continue;
          Rgb b = SideRadiosity(solution, static_cast<int>(i), side);
          out->append(e.surface >= 0 && e.surface < static_cast<int>(names.size())
                          ? names[e.surface]
                          : std::string("?"));
          out->push_back(',');
          AppendInt(out, e.index_in_surface);
          for (double x : {e.centroid.x, e.centroid.y, e.centroid.z, e.area, b.r, b.g, b.b}) {
            out->push_back(',');
            AppendG9(out, x);
          }
          out->push_back('\n');
        }
      });
  if (!st.ok()) return st;
  return file.Close();
}

}  // namespace

absl::Status WriteElementsCsv(const Scene& scene, const Mesh& mesh, const Solution& solution,
                              const std::string& path, const std::string& back_path) {
  std::vector<std::string> names;
  names.reserve(scene.surfaces.size());
  for (const Surface& s : scene.surfaces) names.push_back(CsvField(s.name));
  absl::Status st = WriteCsvSide(mesh, solution, names, kFront, path);
  if (!st.ok()) return st;
  if (!mesh.sides().any_back() || back_path.empty()) return absl::OkStatus();
  return WriteCsvSide(mesh, solution, names, kBack, back_path);
}

}  // namespace radiosity
