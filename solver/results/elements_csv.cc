#include "solver/results/elements_csv.h"

#include <cmath>
#include <vector>

#include "solver/geometry/interpolation.h"
#include "solver/results/text_writer.h"

namespace radiosity {

namespace {

// One side's rows: surface, element, and with `geometry` the centroid and area, then the slot's
// values.
absl::Status WriteCsvSide(const Mesh& mesh, const std::vector<Rgb>& values,
                          const std::vector<std::string>& names, int side, bool geometry,
                          const std::string& path, const std::string& what) {
  OutputFile file(path, what);
  absl::Status st = file.Open();
  if (!st.ok()) return st;
  st = file.Write(geometry ? "surface,element,cx,cy,cz,area,r,g,b\n" : "surface,element,r,g,b\n");
  if (!st.ok()) return st;
  const auto& elements = mesh.elements();
  st = WriteBlocks(&file, static_cast<int64_t>(elements.size()),
                   [&](int64_t begin, int64_t end, std::string* out) {
                     for (int64_t i = begin; i < end; ++i) {
                       const Element& e = elements[i];
                       const size_t slot = static_cast<size_t>(Slot(static_cast<int>(i), side));
                       if (!mesh.sides().exists(static_cast<int>(slot))) continue;
                       const Rgb b = slot < values.size() ? values[slot] : Rgb();
                       out->append(e.surface >= 0 && e.surface < static_cast<int>(names.size())
                                       ? names[e.surface]
                                       : std::string("?"));
                       out->push_back(',');
                       AppendInt(out, e.index_in_surface);
                       if (geometry) {
                         for (double x : {e.centroid.x, e.centroid.y, e.centroid.z, e.area}) {
                           out->push_back(',');
                           AppendG9(out, x);
                         }
                       }
                       for (double x : {b.r, b.g, b.b}) {
                         out->push_back(',');
                         if (std::isnan(x)) {
                           out->append("nan");
                         } else {
                           AppendG9(out, x);
                         }
                       }
                       out->push_back('\n');
                     }
                   });
  if (!st.ok()) return st;
  return file.Close();
}

std::vector<std::string> SurfaceNames(const Scene& scene) {
  std::vector<std::string> names;
  names.reserve(scene.surfaces.size());
  for (const Surface& s : scene.surfaces) names.push_back(CsvField(s.name));
  return names;
}

}  // namespace

absl::Status WriteElementsCsv(const Scene& scene, const Mesh& mesh, const Solution& solution,
                              const std::string& path, const std::string& back_path) {
  const std::vector<std::string> names = SurfaceNames(scene);
  absl::Status st =
      WriteCsvSide(mesh, solution.radiosity, names, kFront, true, path, "elements CSV");
  if (!st.ok()) return st;
  if (!mesh.sides().any_back() || back_path.empty()) return absl::OkStatus();
  return WriteCsvSide(mesh, solution.radiosity, names, kBack, true, back_path,
                      "back-side elements CSV");
}

std::vector<Rgb> StdErrors(const Mesh& mesh, const Solution& solution) {
  if (solution.std_error.size() == solution.radiosity.size()) return solution.std_error;
  const double nan = std::nan("");
  std::vector<Rgb> out(solution.radiosity.size(), Rgb(nan, nan, nan));
  if (solution.hits.size() != solution.radiosity.size()) return out;
  for (size_t s = 0; s < out.size(); ++s) {
    const Rgb received = solution.radiosity[s] - mesh.sides()[static_cast<int>(s)].exitance;
    out[s] = received / std::sqrt(std::max(1.0, solution.hits[s]));
  }
  return out;
}

absl::Status WriteElementsErrorCsv(const Scene& scene, const Mesh& mesh,
                                   const std::vector<Rgb>& std_error, const std::string& path,
                                   const std::string& back_path) {
  const std::vector<std::string> names = SurfaceNames(scene);
  absl::Status st = WriteCsvSide(mesh, std_error, names, kFront, false, path, "elements error CSV");
  if (!st.ok()) return st;
  if (!mesh.sides().any_back() || back_path.empty()) return absl::OkStatus();
  return WriteCsvSide(mesh, std_error, names, kBack, false, back_path,
                      "back-side elements error CSV");
}

}  // namespace radiosity
