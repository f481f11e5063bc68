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
    for (int64_t k = matrix.row_start[i]; k < matrix.row_start[i + 1]; ++k) {
      const double f = matrix.val[k];
      if (!(f > 0)) continue;
      absl::StrAppend(&text, CsvField(matrix.surfaces[i]), ",",
                      CsvField(matrix.surfaces[matrix.col[k]]), ",", absl::StrFormat("%.12g", f),
                      "\n");
    }
    if (absl::Status st = file.Write(text); !st.ok()) return st;
  }
  return file.Close();
}

absl::Status WriteViewFactorMatrixMarket(const ViewFactorMatrix& matrix, const std::string& path) {
  OutputFile file(path, "view factors Matrix Market file");
  if (absl::Status st = file.Open(); !st.ok()) return st;
  const int n = matrix.size();
  int64_t nonzeros = 0;
  for (double f : matrix.val) nonzeros += f > 0 ? 1 : 0;
  std::string text = "%%MatrixMarket matrix coordinate real general\n";
  absl::StrAppend(&text, "% radiosity view factors F_ij (row i: from, column j: to), method ",
                  matrix.method, ", enforced ", matrix.enforced, "\n");
  for (int i = 0; i < n; ++i) {
    std::string name;
    for (unsigned char c : matrix.surfaces[i]) {
      if (c <= ' ' || c == '%' || c == 0x7f) {
        absl::StrAppend(&name, absl::StrFormat("%%%02X", c));
      } else {
        name.push_back(static_cast<char>(c));
      }
    }
    absl::StrAppend(&text, "% surface ", i + 1, " ", name, " ",
                    absl::StrFormat("%.12g", matrix.area[i]), "\n");
  }
  absl::StrAppend(&text, n, " ", n, " ", nonzeros, "\n");
  if (absl::Status st = file.Write(text); !st.ok()) return st;
  for (int i = 0; i < n; ++i) {
    text.clear();
    for (int64_t k = matrix.row_start[i]; k < matrix.row_start[i + 1]; ++k) {
      const double f = matrix.val[k];
      if (!(f > 0)) continue;
      absl::StrAppend(&text, i + 1, " ", matrix.col[k] + 1, " ", absl::StrFormat("%.12g", f), "\n");
    }
    if (absl::Status st = file.Write(text); !st.ok()) return st;
  }
  return file.Close();
}

}  // namespace radiosity
