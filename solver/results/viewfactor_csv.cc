#include "solver/results/viewfactor_csv.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/results/text_writer.h"

namespace radiosity {

absl::Status WriteViewFactorCsv(const ViewFactorMatrix& matrix, const std::string& path) {
  OutputFile file(path, "view factors CSV");
  if (absl::Status st = file.Open(); !st.ok()) return st;
  if (absl::Status st = file.Write("from,to,F\n"); !st.ok()) return st;
  const int n = matrix.size();
  std::string text;
  for (int i = 0; i < n; ++i) {
    text.clear();
    for (int j = 0; j < n; ++j) {
      const double f = matrix.at(i, j);
      if (!(f > 0)) continue;
      absl::StrAppend(&text, CsvField(matrix.surfaces[i]), ",", CsvField(matrix.surfaces[j]), ",",
                      absl::StrFormat("%.12g", f), "\n");
    }
    if (absl::Status st = file.Write(text); !st.ok()) return st;
  }
  return file.Close();
}

}  // namespace radiosity
