#include "solver/util/file_io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"

namespace radiosity {

absl::Status ErrnoStatus(int err, absl::string_view prefix) {
  std::string text = absl::StrCat(prefix, std::strerror(err));
  switch (err) {
    case ENOENT:
    case ENOTDIR:
      return absl::NotFoundError(text);
    case EACCES:
    case EPERM:
      return absl::PermissionDeniedError(text);
    default:
      return absl::InvalidArgumentError(text);
  }
}

absl::StatusOr<std::string> ReadWholeFile(const std::string& path, absl::string_view what) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  const absl::string_view sep = what.empty() ? "" : " ";
  if (fd < 0) return ErrnoStatus(errno, absl::StrCat(path, ": cannot open", sep, what, ": "));
  struct stat st;
  const int stat_result = ::fstat(fd, &st);
  if (stat_result != 0 || S_ISDIR(st.st_mode)) {
    const int err = stat_result != 0 ? errno : EISDIR;
    ::close(fd);
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": cannot read", sep, what, ": ", std::strerror(err)));
  }
  std::string data;
  if (S_ISREG(st.st_mode) && st.st_size > 0) data.reserve(static_cast<size_t>(st.st_size));
  char buffer[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd, buffer, sizeof buffer);
    if (n < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      return absl::InvalidArgumentError(
          absl::StrCat(path, ": cannot read", sep, what, ": ", std::strerror(err)));
    }
    if (n == 0) break;
    data.append(buffer, static_cast<size_t>(n));
  }
  ::close(fd);
  return data;
}

namespace {

// Writes `data` to `path`; 0 or the errno of the failure (*opened: whether fopen succeeded).
int WriteTo(const std::string& path, absl::string_view data, bool* opened) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  *opened = f != nullptr;
  if (f == nullptr) return errno != 0 ? errno : EIO;
  errno = 0;
  const bool wrote = std::fwrite(data.data(), 1, data.size(), f) == data.size();
  int err = errno;
  const bool closed = std::fclose(f) == 0;
  if (!closed && err == 0) err = errno;
  return wrote && closed ? 0 : (err != 0 ? err : EIO);
}

}  // namespace

absl::Status WriteErrnoStatus(int err, absl::string_view prefix) {
  std::string message = absl::StrCat(prefix, err != 0 ? std::strerror(err) : "I/O error");
  if (err == ENOSPC || err == EDQUOT) return absl::ResourceExhaustedError(message);
  return absl::InternalError(message);
}

absl::Status WriteWholeFile(const std::string& path, absl::string_view data) {
  bool opened = false;
  if (int err = WriteTo(path, data, &opened); err != 0) {
    return WriteErrnoStatus(err,
                            path + (opened ? ": cannot write: " : ": cannot open for writing: "));
  }
  return absl::OkStatus();
}

absl::Status WriteFileAtomically(const std::string& path, absl::string_view data) {
  static std::atomic<uint64_t> counter{0};
  const std::string tmp = absl::StrCat(path, ".tmp-", ::getpid(), "-", counter++);
  std::error_code ec;
  bool opened = false;
  if (int err = WriteTo(tmp, data, &opened); err != 0) {
    std::filesystem::remove(tmp, ec);
    return WriteErrnoStatus(err, path + ": cannot write: ");
  }
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;  // ec keeps the rename's reason.
    std::filesystem::remove(tmp, ignored);
    return absl::InternalError(absl::StrCat(path, ": cannot rename: ", ec.message()));
  }
  return absl::OkStatus();
}

std::string JoinPath(const std::string& dir, const std::string& name) {
  if (dir.empty() || (!name.empty() && name[0] == '/')) return name;
  if (dir.back() == '/') return dir + name;
  return absl::StrCat(dir, "/", name);
}

std::string DirName(const std::string& path) {
  const size_t slash = path.rfind('/');
  if (slash == std::string::npos) return "";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

std::string BaseName(const std::string& path) {
  const size_t slash = path.rfind('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::string Stem(const std::string& path) {
  std::string base = BaseName(path);
  const size_t dot = base.rfind('.');
  if (dot != std::string::npos && dot > 0) base.resize(dot);
  return base;
}

std::string Extension(const std::string& path) {
  const size_t slash = path.rfind('/');
  const size_t dot = path.rfind('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  return absl::AsciiStrToLower(path.substr(dot));
}

bool FileExists(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 && !S_ISDIR(st.st_mode);
}

bool IsSafeRelativeName(absl::string_view name) {
  if (name.empty() || name.size() > 255 || name.front() == '/') return false;
  size_t start = 0;
  while (start <= name.size()) {
    size_t end = name.find('/', start);
    if (end == absl::string_view::npos) end = name.size();
    const absl::string_view part = name.substr(start, end - start);
    if (part.empty() || part == "." || part == "..") return false;
    start = end + 1;
  }
  for (char c : name) {
    if (c == '\\' || c == '\0' || static_cast<unsigned char>(c) < 0x20) return false;
  }
  return true;
}

}  // namespace radiosity
