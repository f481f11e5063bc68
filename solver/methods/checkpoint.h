// Checkpoints: a solver's state after a complete step, written to a file, from which a solver of
// the same scene, mesh and options continues exactly as the first would have
// (docs/service/server.md). Every method's steps depend only on its state and the seed (each step's
// random streams are keyed by the step number), so the state is all there is to save.
//
// The state is a sequence of named sections of raw bytes (trivially copyable values and vectors of
// them), read back in the order written; a section whose name or size differs from what the
// reader expects is an error, which catches a state from another mesh or other options. The file
// adds a format line, a fingerprint of what the state belongs to, and a checksum (FNV-1a, 64
// bits), and is replaced atomically.
#ifndef RADIOSITY_SOLVER_METHODS_CHECKPOINT_H_
#define RADIOSITY_SOLVER_METHODS_CHECKPOINT_H_

#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/string_view.h"

namespace radiosity {

class StateWriter {
 public:
  template <typename T>
  void Put(absl::string_view name, const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    PutBytes(name, &value, sizeof(T));
  }
  template <typename T>
  void PutVector(absl::string_view name, const std::vector<T>& values) {
    static_assert(std::is_trivially_copyable_v<T>);
    PutBytes(name, values.data(), values.size() * sizeof(T));
  }
  // Room for `bytes` more (a large state is then copied once).
  void Reserve(size_t bytes) { data_.reserve(data_.size() + bytes); }
  const std::string& data() const { return data_; }

 private:
  void PutBytes(absl::string_view name, const void* bytes, size_t size);
  std::string data_;
};

class StateReader {
 public:
  explicit StateReader(absl::string_view data) : data_(data) {}

  template <typename T>
  absl::Status Get(absl::string_view name, T* value) {
    static_assert(std::is_trivially_copyable_v<T>);
    absl::StatusOr<absl::string_view> bytes = Next(name);
    if (!bytes.ok()) return bytes.status();
    if (bytes->size() != sizeof(T)) return SizeError(name, bytes->size(), sizeof(T));
    std::memcpy(value, bytes->data(), sizeof(T));
    return absl::OkStatus();
  }
  // Reads into `values`, which must already have the size the state was saved with (the reader's
  // own solver allocated it from the same mesh and options).
  template <typename T>
  absl::Status GetVector(absl::string_view name, std::vector<T>* values) {
    static_assert(std::is_trivially_copyable_v<T>);
    absl::StatusOr<absl::string_view> bytes = Next(name);
    if (!bytes.ok()) return bytes.status();
    const size_t want = values->size() * sizeof(T);
    if (bytes->size() != want) return SizeError(name, bytes->size(), want);
    if (want > 0) std::memcpy(values->data(), bytes->data(), want);
    return absl::OkStatus();
  }
  // Reads a vector of whatever length was saved.
  template <typename T>
  absl::Status GetAnyVector(absl::string_view name, std::vector<T>* values) {
    static_assert(std::is_trivially_copyable_v<T>);
    absl::StatusOr<absl::string_view> bytes = Next(name);
    if (!bytes.ok()) return bytes.status();
    if (bytes->size() % sizeof(T) != 0) return SizeError(name, bytes->size(), sizeof(T));
    values->resize(bytes->size() / sizeof(T));
    if (!values->empty()) std::memcpy(values->data(), bytes->data(), bytes->size());
    return absl::OkStatus();
  }
  // OK when every section was read.
  absl::Status Finish() const;

 private:
  absl::StatusOr<absl::string_view> Next(absl::string_view name);
  static absl::Status SizeError(absl::string_view name, size_t have, size_t want);
  absl::string_view data_;
};

// Writes `state` with `fingerprint` to `path`, atomically (a temporary file and a rename).
// Errors as WriteFileAtomically's (RESOURCE_EXHAUSTED for a full disk).
absl::Status WriteCheckpoint(const std::string& path, absl::string_view fingerprint,
                             absl::string_view state);

// The state in the checkpoint at `path`. NOT_FOUND when there is none; FAILED_PRECONDITION when it
// belongs to another fingerprint (another job, mesh, method or program version); DATA_LOSS when the
// file is truncated or its checksum fails.
absl::StatusOr<std::string> ReadCheckpoint(const std::string& path, absl::string_view fingerprint);

// FNV-1a, 64 bits, continuing from `hash`.
uint64_t Fnv1a(absl::string_view bytes, uint64_t hash = 0xcbf29ce484222325ULL);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_CHECKPOINT_H_
