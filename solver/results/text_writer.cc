#include "solver/results/text_writer.h"

#include <cerrno>
#include <charconv>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "solver/util/file_io.h"

namespace radiosity {

OutputFile::~OutputFile() {
  if (file_ != nullptr) std::fclose(file_);
}

absl::Status OutputFile::Open() {
  file_ = std::fopen(path_.c_str(), "wb");
  if (file_ == nullptr) return Error(errno);
  std::setvbuf(file_, nullptr, _IOFBF, 1 << 20);
  return absl::OkStatus();
}

absl::Status OutputFile::Write(absl::string_view text) {
  if (text.empty()) return absl::OkStatus();
  if (std::fwrite(text.data(), 1, text.size(), file_) != text.size()) return Error(errno);
  return absl::OkStatus();
}

absl::Status OutputFile::Close() {
  std::FILE* f = file_;
  file_ = nullptr;
  bool failed = std::ferror(f) != 0;
  int err = errno;
  if (std::fclose(f) != 0 && !failed) {
    failed = true;
    err = errno;
  }
  return failed ? Error(err) : absl::OkStatus();
}

absl::Status OutputFile::Error(int err) const {
  return WriteErrnoStatus(err, absl::StrCat(path_, ": cannot write ", what_, ": "));
}

void AppendG9(std::string* out, double v) {
  char buf[40];
  auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 9);
  out->append(buf, r.ptr);
}

void AppendFloat(std::string* out, float v) {
  char buf[40];
  auto r = std::to_chars(buf, buf + sizeof buf, v);
  out->append(buf, r.ptr);
}

void AppendInt(std::string* out, int64_t v) {
  char buf[24];
  auto r = std::to_chars(buf, buf + sizeof buf, v);
  out->append(buf, r.ptr);
}

std::string CsvField(const std::string& s) {
  if (s.find_first_of(",\"\r\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

}  // namespace radiosity
