// Files and paths: whole-file reads and writes whose errors name the path and the system's reason,
// and the path arithmetic the loaders, the service and the client share.
#ifndef RADIOSITY_SOLVER_UTIL_FILE_IO_H_
#define RADIOSITY_SOLVER_UTIL_FILE_IO_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace radiosity {

// `prefix` followed by strerror(err), with the code the error deserves: NOT_FOUND for a missing
// file, PERMISSION_DENIED for a refused one, INVALID_ARGUMENT otherwise.
absl::Status ErrnoStatus(int err, absl::string_view prefix);

// The whole file at `path`. Errors (codes as ErrnoStatus): "PATH: cannot open WHAT: reason",
// "PATH: cannot read WHAT: reason" (a directory, a read error); WHAT may be empty.
absl::StatusOr<std::string> ReadWholeFile(const std::string& path, absl::string_view what = "");

// A failed write with errno `err` (0: unknown): "PREFIXreason", RESOURCE_EXHAUSTED when the disk
// or the quota is full, else INTERNAL.
absl::Status WriteErrnoStatus(int err, absl::string_view prefix);

// Writes `data` to `path` (replacing it). Errors: "PATH: cannot open for writing: reason" or
// "PATH: cannot write: reason", RESOURCE_EXHAUSTED for a full disk or quota, else INTERNAL.
absl::Status WriteWholeFile(const std::string& path, absl::string_view data);

// Writes through a temporary file beside `path` and a rename, so readers never see half a file.
// Errors as WriteWholeFile's.
absl::Status WriteFileAtomically(const std::string& path, absl::string_view data);

// "dir/name", or `name` alone when it is absolute or `dir` is empty.
std::string JoinPath(const std::string& dir, const std::string& name);
// The directory part of a path ("" when there is none, "/" for a file at the root).
std::string DirName(const std::string& path);
// The last component of a path.
std::string BaseName(const std::string& path);
// File name without directory and last extension: "scenes/box.obj" -> "box".
std::string Stem(const std::string& path);
// The last extension, lowercased, with its dot: "box.OBJ" -> ".obj" ("" when there is none).
std::string Extension(const std::string& path);
// A file (not a directory) exists at `path`.
bool FileExists(const std::string& path);

// Whether `name` is a relative '/'-separated path with no empty, "." or ".." component, no
// backslash, NUL or control character, at most 255 bytes: safe to join below a directory.
bool IsSafeRelativeName(absl::string_view name);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_UTIL_FILE_IO_H_
