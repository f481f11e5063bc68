#include "server/live_share.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>

#include "absl/strings/str_cat.h"
#include "solver/util/file_io.h"

namespace radiosity::service {
namespace {

namespace fs = std::filesystem;

constexpr char kMagic[] = "RLIVE1\n";
constexpr size_t kMagicSize = sizeof(kMagic) - 1;

void PutInt(std::string* out, int64_t v) {
  char bytes[8];
  for (int i = 0; i < 8; ++i) bytes[i] = static_cast<char>((static_cast<uint64_t>(v) >> (8 * i)));
  out->append(bytes, 8);
}

bool GetInt(const std::string& in, size_t* at, int64_t* v) {
  if (in.size() - *at < 8) return false;
  uint64_t u = 0;
  for (int i = 0; i < 8; ++i)
    u |= static_cast<uint64_t>(static_cast<uint8_t>(in[*at + i])) << (8 * i);
  *at += 8;
  *v = static_cast<int64_t>(u);
  return true;
}

void PutFloats(std::string* out, const std::vector<float>& floats) {
  static_assert(sizeof(float) == 4);
  out->append(reinterpret_cast<const char*>(floats.data()), floats.size() * 4);
}

std::string MeshFile(const std::string& job_dir, int64_t version) {
  return absl::StrCat(LiveDir(job_dir), "/mesh-", version);
}

}  // namespace

std::string LiveDir(const std::string& job_dir) { return job_dir + "/live"; }

void TouchLiveInterest(const std::string& job_dir) {
  std::error_code ec;
  fs::create_directories(LiveDir(job_dir), ec);
  const std::string path = LiveDir(job_dir) + "/watched";
  const int fd = open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) return;
  futimens(fd, nullptr);  // Now.
  close(fd);
}

bool LiveWatched(const std::string& job_dir) {
  struct stat st;
  if (stat((LiveDir(job_dir) + "/watched").c_str(), &st) != 0) return false;
  const auto touched = std::chrono::system_clock::from_time_t(st.st_mtim.tv_sec) +
                       std::chrono::nanoseconds(st.st_mtim.tv_nsec);
  return std::chrono::system_clock::now() - touched < kLiveInterest;
}

absl::Status WriteLiveSnapshot(const std::string& job_dir, const Snapshot& snapshot) {
  if (!snapshot.radiosity || !snapshot.mesh) return absl::OkStatus();
  std::error_code ec;
  fs::create_directories(LiveDir(job_dir), ec);
  const std::string mesh_file = MeshFile(job_dir, snapshot.mesh_version);
  if (!fs::exists(mesh_file, ec)) {
    if (absl::Status st = WriteFileAtomically(mesh_file, SerializeMesh(*snapshot.mesh)); !st.ok()) {
      return st;
    }
  }
  const std::vector<float>& radiosity = snapshot.radiosity->data();
  const std::vector<float> none;
  const std::vector<float>& std_error = snapshot.std_error ? snapshot.std_error->data() : none;
  const std::string progress = snapshot.progress.SerializeAsString();
  std::string out(kMagic, kMagicSize);
  out.reserve(out.size() + 64 + progress.size() + (radiosity.size() + std_error.size()) * 4);
  for (int64_t v :
       {snapshot.sequence, snapshot.mesh_version, snapshot.elements,
        static_cast<int64_t>(radiosity.size()), static_cast<int64_t>(std_error.size()),
        static_cast<int64_t>(snapshot.attempts), static_cast<int64_t>(progress.size())}) {
    PutInt(&out, v);
  }
  out += progress;
  PutFloats(&out, radiosity);
  PutFloats(&out, std_error);
  return WriteFileAtomically(LiveDir(job_dir) + "/snapshot", out);
}

absl::StatusOr<SnapshotPtr> ReadLiveSnapshot(const std::string& job_dir, int64_t after_sequence,
                                             MeshPtr* mesh) {
  const std::string path = LiveDir(job_dir) + "/snapshot";
  {
    // The sequence first: the whole file only when it is newer.
    std::ifstream head(path, std::ios::binary);
    if (!head) return SnapshotPtr();
    std::string start(kMagicSize + 8, '\0');
    head.read(start.data(), static_cast<std::streamsize>(start.size()));
    size_t at = kMagicSize;
    int64_t sequence = 0;
    if (head.gcount() == static_cast<std::streamsize>(start.size()) &&
        GetInt(start, &at, &sequence) && sequence <= after_sequence) {
      return SnapshotPtr();
    }
  }
  absl::StatusOr<std::string> bytes = ReadWholeFile(path);
  if (!bytes.ok()) return bytes.status();
  const std::string& in = *bytes;
  auto bad = [&] { return absl::DataLossError(absl::StrCat(path, ": not a live snapshot")); };
  if (in.size() < kMagicSize || in.compare(0, kMagicSize, kMagic, kMagicSize) != 0) return bad();
  size_t at = kMagicSize;
  int64_t sequence, mesh_version, elements, radiosity_count, std_error_count, attempts,
      progress_size;
  for (int64_t* v : {&sequence, &mesh_version, &elements, &radiosity_count, &std_error_count,
                     &attempts, &progress_size}) {
    if (!GetInt(in, &at, v)) return bad();
  }
  if (sequence <= after_sequence) return SnapshotPtr();
  if (progress_size < 0 || radiosity_count < 0 || std_error_count < 0 ||
      static_cast<uint64_t>(in.size() - at) !=
          static_cast<uint64_t>(progress_size) + 4 * (static_cast<uint64_t>(radiosity_count) +
                                                      static_cast<uint64_t>(std_error_count))) {
    return bad();
  }
  auto snapshot = std::make_shared<Snapshot>();
  snapshot->sequence = sequence;
  snapshot->state = v1::JOB_STATE_RUNNING;
  snapshot->elements = elements;
  snapshot->attempts = static_cast<int32_t>(attempts);
  if (!snapshot->progress.ParseFromArray(in.data() + at, static_cast<int>(progress_size))) {
    return bad();
  }
  at += static_cast<size_t>(progress_size);
  auto floats = [&](int64_t count) {
    std::vector<float> v(static_cast<size_t>(count));
    std::memcpy(v.data(), in.data() + at, v.size() * 4);
    at += v.size() * 4;
    return v;
  };
  snapshot->radiosity = std::make_shared<FloatBlock>(floats(radiosity_count));
  if (std_error_count > 0)
    snapshot->std_error = std::make_shared<FloatBlock>(floats(std_error_count));
  if (!*mesh || (*mesh)->version() != mesh_version) {
    absl::StatusOr<std::string> mesh_bytes = ReadWholeFile(MeshFile(job_dir, mesh_version));
    if (!mesh_bytes.ok()) return mesh_bytes.status();
    absl::StatusOr<MeshPtr> parsed = ParseMesh(*mesh_bytes);
    if (!parsed.ok()) return parsed.status();
    *mesh = *parsed;
  }
  if ((*mesh)->elements() * 6 != radiosity_count) return bad();
  snapshot->mesh = *mesh;
  snapshot->mesh_version = mesh_version;
  return SnapshotPtr(std::move(snapshot));
}

}  // namespace radiosity::service
