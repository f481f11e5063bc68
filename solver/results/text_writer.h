// Writing large text files (CSV, PLY) fast and with errors that name the file: a buffered file,
// number formatting that reads back exactly, and formatting in parallel blocks written in order.
#ifndef RADIOSITY_SOLVER_RESULTS_TEXT_WRITER_H_
#define RADIOSITY_SOLVER_RESULTS_TEXT_WRITER_H_

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"

namespace radiosity {

// A file written through a 1 MiB stdio buffer; errors (INTERNAL: exit code 1 of the CLI) name the
// path, what was being written and the system's reason.
class OutputFile {
 public:
  OutputFile(std::string path, std::string what) : path_(std::move(path)), what_(std::move(what)) {}
  ~OutputFile();
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  absl::Status Open();
  absl::Status Write(absl::string_view text);
  absl::Status Close();

 private:
  absl::Status Error(int err) const;

  std::string path_, what_;
  std::FILE* file_ = nullptr;
};

// Appends %.9g of v (std::to_chars with a precision is specified as printf's %.*g).
void AppendG9(std::string* out, double v);
// Appends the shortest text that reads back as the same float.
void AppendFloat(std::string* out, float v);
void AppendInt(std::string* out, int64_t v);

// A CSV field: quoted (RFC 4180) only when it contains a separator, a quote or a line break.
std::string CsvField(const std::string& s);

// Items per block of parallel text formatting.
inline constexpr int64_t kTextBlock = 4096;

// Formats items [0, n) in blocks of kTextBlock, in parallel, and writes them in order.
// format(begin, end, &text) appends the text of items [begin, end). Batches bound the memory.
template <typename Format>
absl::Status WriteBlocks(OutputFile* file, int64_t n, const Format& format) {
  constexpr int64_t kBatch = 64;
  const int64_t blocks = (n + kTextBlock - 1) / kTextBlock;
  std::vector<std::string> text(static_cast<size_t>(std::min(blocks, kBatch)));
  for (int64_t b0 = 0; b0 < blocks; b0 += kBatch) {
    const int64_t b1 = std::min(blocks, b0 + kBatch);
    tbb::parallel_for(b0, b1, [&](int64_t b) {
      std::string& s = text[static_cast<size_t>(b - b0)];
      s.clear();
      format(b * kTextBlock, std::min(n, (b + 1) * kTextBlock), &s);
    });
    for (int64_t b = b0; b < b1; ++b) {
      absl::Status st = file->Write(text[static_cast<size_t>(b - b0)]);
      if (!st.ok()) return st;
    }
  }
  return absl::OkStatus();
}

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_TEXT_WRITER_H_
