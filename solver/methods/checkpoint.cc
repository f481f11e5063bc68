#include "solver/methods/checkpoint.h"

#include <filesystem>

#include "absl/strings/match.h"
#include "absl/strings/str_format.h"
#include "solver/util/file_io.h"

namespace radiosity {

namespace {

// The first line of every checkpoint file; a new layout of any solver's state takes a new number.
constexpr absl::string_view kMagic = "radiosity checkpoint 3\n";

void AppendU64(std::string* out, uint64_t v) {
  for (int i = 0; i < 8; ++i) out->push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}

bool ReadU64(absl::string_view* in, uint64_t* v) {
  if (in->size() < 8) return false;
  *v = 0;
  for (int i = 0; i < 8; ++i) {
    *v |= static_cast<uint64_t>(static_cast<unsigned char>((*in)[i])) << (8 * i);
  }
  in->remove_prefix(8);
  return true;
}

}  // namespace

uint64_t Fnv1a(absl::string_view bytes, uint64_t hash) {
  for (unsigned char c : bytes) {
    hash ^= c;
    hash *= 0x100000001b3ULL;
  }
  return hash;
}

void StateWriter::PutBytes(absl::string_view name, const void* bytes, size_t size) {
  AppendU64(&data_, name.size());
  data_.append(name.data(), name.size());
  AppendU64(&data_, size);
  data_.append(static_cast<const char*>(bytes), size);
}

absl::StatusOr<absl::string_view> StateReader::Next(absl::string_view name) {
  uint64_t name_size = 0, size = 0;
  if (!ReadU64(&data_, &name_size) || data_.size() < name_size) {
    return absl::DataLossError(absl::StrCat("the state ends before '", name, "'"));
  }
  const absl::string_view have = data_.substr(0, name_size);
  data_.remove_prefix(name_size);
  if (have != name) {
    return absl::FailedPreconditionError(
        absl::StrCat("the state has '", have, "' where '", name, "' was expected"));
  }
  if (!ReadU64(&data_, &size) || data_.size() < size) {
    return absl::DataLossError(absl::StrCat("the state ends inside '", name, "'"));
  }
  const absl::string_view bytes = data_.substr(0, size);
  data_.remove_prefix(size);
  return bytes;
}

absl::Status StateReader::SizeError(absl::string_view name, size_t have, size_t want) {
  return absl::FailedPreconditionError(absl::StrFormat(
      "the state's '%s' has %d bytes where %d were expected (another mesh or other options)", name,
      have, want));
}

absl::Status StateReader::Finish() const {
  if (data_.empty()) return absl::OkStatus();
  return absl::FailedPreconditionError(
      absl::StrCat("the state has ", data_.size(), " bytes more than this solver reads"));
}

absl::Status WriteCheckpoint(const std::string& path, absl::string_view fingerprint,
                             absl::string_view state) {
  std::string data(kMagic);
  AppendU64(&data, fingerprint.size());
  data.append(fingerprint.data(), fingerprint.size());
  AppendU64(&data, state.size());
  data.append(state.data(), state.size());
  AppendU64(&data, Fnv1a(data));
  return WriteFileAtomically(path, data);
}

absl::StatusOr<std::string> ReadCheckpoint(const std::string& path, absl::string_view fingerprint) {
  // Only a regular file is read (a FIFO would block, a link to a device never end).
  std::error_code ec;
  const std::filesystem::file_status status = std::filesystem::symlink_status(path, ec);
  if (ec || status.type() == std::filesystem::file_type::not_found) {
    return absl::NotFoundError(absl::StrCat(path, ": no checkpoint"));
  }
  if (status.type() != std::filesystem::file_type::regular) {
    return absl::DataLossError(absl::StrCat(path, ": the checkpoint is not a regular file"));
  }
  absl::StatusOr<std::string> file = ReadWholeFile(path, "checkpoint");
  if (!file.ok()) return file.status();
  auto corrupt = [&](absl::string_view why) {
    return absl::DataLossError(absl::StrCat(path, ": the checkpoint is damaged (", why, ")"));
  };
  absl::string_view in = *file;
  if (in.size() < kMagic.size() + 8 || in.substr(0, kMagic.size()) != kMagic) {
    if (absl::StartsWith(in, "radiosity checkpoint ")) {
      return absl::FailedPreconditionError(
          absl::StrCat(path, ": the checkpoint was written by another version of the program"));
    }
    return corrupt("not a checkpoint of this format");
  }
  absl::string_view tail = in.substr(in.size() - 8);
  uint64_t checksum = 0;
  ReadU64(&tail, &checksum);
  in.remove_suffix(8);
  if (Fnv1a(in) != checksum) return corrupt("checksum");
  in.remove_prefix(kMagic.size());
  uint64_t size = 0;
  if (!ReadU64(&in, &size) || in.size() < size) return corrupt("truncated fingerprint");
  if (in.substr(0, size) != fingerprint) {
    return absl::FailedPreconditionError(
        absl::StrCat(path, ": the checkpoint belongs to another job, mesh or program version"));
  }
  in.remove_prefix(size);
  if (!ReadU64(&in, &size) || in.size() != size) return corrupt("truncated state");
  return std::string(in);
}

}  // namespace radiosity
