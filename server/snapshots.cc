#include "server/snapshots.h"

#include <algorithm>
#include <array>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "proto/api/back_ranges.h"
#include "server/metrics.h"

namespace radiosity::service {
namespace {

constexpr size_t kMaxNameBytes = 4096;
constexpr char kMeshMagic[] = "RMG1";

// Length of the well-formed UTF-8 sequence at s[i] (Unicode 15, table 3-7), or 0.
size_t Utf8Length(const std::string& s, size_t i) {
  auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char c = byte(i);
  if (c < 0x80) return 1;
  size_t len;
  unsigned char lo = 0x80, hi = 0xBF;  // Range of the second byte.
  if (c >= 0xC2 && c <= 0xDF) {
    len = 2;
  } else if (c >= 0xE0 && c <= 0xEF) {
    len = 3;
    if (c == 0xE0) lo = 0xA0;
    if (c == 0xED) hi = 0x9F;
  } else if (c >= 0xF0 && c <= 0xF4) {
    len = 4;
    if (c == 0xF0) lo = 0x90;
    if (c == 0xF4) hi = 0x8F;
  } else {
    return 0;
  }
  if (i + len > s.size() || byte(i + 1) < lo || byte(i + 1) > hi) return 0;
  for (size_t k = 2; k < len; ++k) {
    if ((byte(i + k) & 0xC0) != 0x80) return 0;
  }
  return len;
}

// `name` cut to kMaxNameBytes at a character boundary, with bytes that are not UTF-8 replaced by
// '?' (proto3 strings must be valid UTF-8; scene names come from arbitrary files).
std::string WireName(const std::string& name) {
  std::string out;
  out.reserve(std::min(name.size(), kMaxNameBytes));
  size_t i = 0;
  while (i < name.size()) {
    const size_t len = Utf8Length(name, i);
    if (out.size() + std::max<size_t>(len, 1) > kMaxNameBytes) break;
    if (len > 0) {
      out.append(name, i, len);
      i += len;
    } else {
      out.push_back('?');
      ++i;
    }
  }
  return out;
}

}  // namespace

FloatBlock::FloatBlock(std::vector<float> data) : data_(std::move(data)) {
  SnapshotBytesLive() += static_cast<int64_t>(data_.size() * sizeof(float));
}

FloatBlock::~FloatBlock() {
  SnapshotBytesLive() -= static_cast<int64_t>(data_.size() * sizeof(float));
}

namespace {

std::shared_ptr<const FloatBlock> Pack(const std::vector<Rgb>& values) {
  std::vector<float> data(values.size() * 3);
  for (size_t i = 0; i < values.size(); ++i) {
    const Rgb& b = values[i];
    data[3 * i] = static_cast<float>(b.r);
    data[3 * i + 1] = static_cast<float>(b.g);
    data[3 * i + 2] = static_cast<float>(b.b);
  }
  return std::make_shared<const FloatBlock>(std::move(data));
}

}  // namespace

std::shared_ptr<const FloatBlock> PackRadiosity(const Solution& solution) {
  return Pack(solution.radiosity);
}

std::shared_ptr<const FloatBlock> PackStdError(const Solution& solution) {
  if (solution.std_error.size() != solution.radiosity.size()) return nullptr;
  return Pack(solution.std_error);
}

MeshAnnouncement::MeshAnnouncement(std::vector<v1::MeshGeometry> chunks,
                                   std::shared_ptr<const std::vector<int64_t>> back_ranges)
    : chunks_(std::move(chunks)), back_ranges_(std::move(back_ranges)) {
  if (!chunks_.empty()) {
    version_ = chunks_[0].version();
    elements_ = chunks_[0].elements();
  }
  for (const v1::MeshGeometry& c : chunks_) bytes_ += static_cast<int64_t>(c.SpaceUsedLong());
  MeshBytesLive() += bytes_;
}

MeshAnnouncement::~MeshAnnouncement() { MeshBytesLive() -= bytes_; }

std::string SerializeBackRanges(const std::vector<int64_t>& ranges) {
  std::string bytes(ranges.size() * sizeof(int64_t), '\0');
  if (!ranges.empty()) std::memcpy(bytes.data(), ranges.data(), bytes.size());
  return bytes;
}

std::shared_ptr<const std::vector<int64_t>> ParseBackRanges(const std::string& bytes,
                                                            int64_t elements) {
  if (bytes.size() % (2 * sizeof(int64_t)) != 0) return nullptr;
  std::vector<int64_t> ranges(bytes.size() / sizeof(int64_t));
  if (!ranges.empty()) std::memcpy(ranges.data(), bytes.data(), bytes.size());
  if (BackRangeElements(ranges, elements) < 0) return nullptr;
  return std::make_shared<const std::vector<int64_t>>(std::move(ranges));
}

void AddExistingSides(Snapshot* snapshot) {
  if (!snapshot->back_ranges && snapshot->mesh)
    snapshot->back_ranges = snapshot->mesh->back_ranges();
  if (!snapshot->radiosity || !snapshot->back_ranges) return;
  const std::vector<int64_t>& ranges = *snapshot->back_ranges;
  const int64_t n = static_cast<int64_t>(snapshot->radiosity->data().size()) / 6;
  const int64_t backs = BackRangeElements(ranges, n);
  if (static_cast<int64_t>(snapshot->radiosity->data().size()) != 6 * n || backs < 0) {
    snapshot->back_ranges = nullptr;
    return;
  }
  if (backs == n) {
    snapshot->existing_radiosity = snapshot->radiosity;
    snapshot->existing_std_error = snapshot->std_error;
    return;
  }
  auto compact = [&](const FloatBlock& full) {
    const std::vector<float>& in = full.data();
    std::vector<float> out;
    out.reserve(static_cast<size_t>(3 * (n + backs)));
    size_t r = 0;
    for (int64_t e = 0; e < n; ++e) {
      while (r + 1 < ranges.size() && ranges[r + 1] <= e) r += 2;
      const bool back = r + 1 < ranges.size() && ranges[r] <= e;
      const float* v = in.data() + 6 * e;
      out.insert(out.end(), v, v + (back ? 6 : 3));
    }
    return std::make_shared<const FloatBlock>(std::move(out));
  };
  snapshot->existing_radiosity = compact(*snapshot->radiosity);
  if (snapshot->std_error) snapshot->existing_std_error = compact(*snapshot->std_error);
}

MeshPtr PackMesh(const Scene& scene, const Mesh& mesh, int64_t version) {
  const auto& elements = mesh.elements();
  const auto& faces = mesh.faces();
  const int64_t n = static_cast<int64_t>(elements.size());
  const Vec3 origin = mesh.origin();

  // Surface names, spread over the messages by bytes.
  std::vector<std::string> names;
  names.reserve(scene.surfaces.size());
  for (const Surface& s : scene.surfaces) names.push_back(WireName(s.name));
  std::vector<size_t> name_start{0};  // First name of each message that holds names.
  size_t bytes = 0;
  for (size_t i = 0; i < names.size(); ++i) {
    const size_t b = names[i].size() + 8;
    if (bytes > 0 && bytes + b > static_cast<size_t>(kMaxNameBytesPerMessage)) {
      name_start.push_back(i);
      bytes = 0;
    }
    bytes += b;
  }
  name_start.push_back(names.size());
  const int64_t name_chunks = static_cast<int64_t>(name_start.size()) - 1;
  // Elements, spread over the messages by count and by the faces agglomerated ones hold.
  std::vector<int64_t> element_start{0};
  int64_t members = 0;
  for (int64_t e = 0; e < n; ++e) {
    const int64_t m = elements[e].num_members;
    const int64_t k = e - element_start.back();
    if (k > 0 && (k >= kMaxMeshElementsPerMessage || members + m > kMaxMeshMemberFacesPerMessage ||
                  100 * (k + 1) + 52 * (members + m) > kMaxMeshBytesPerMessage)) {
      element_start.push_back(e);
      members = 0;
    }
    members += m;
  }
  if (n > 0) element_start.push_back(n);
  const int64_t element_chunks = static_cast<int64_t>(element_start.size()) - 1;
  const int64_t count = std::max<int64_t>({1, name_chunks, element_chunks});

  std::vector<v1::MeshGeometry> chunks(static_cast<size_t>(count));
  for (int64_t c = 0; c < count; ++c) {
    v1::MeshGeometry& g = chunks[static_cast<size_t>(c)];
    g.set_version(version);
    g.set_elements(n);
    g.set_faces(static_cast<int64_t>(faces.size()));
    g.set_chunk_index(static_cast<int32_t>(c));
    g.set_chunk_count(static_cast<int32_t>(count));
    g.mutable_origin()->set_x(origin.x);
    g.mutable_origin()->set_y(origin.y);
    g.mutable_origin()->set_z(origin.z);
    g.set_surfaces(static_cast<int32_t>(names.size()));
    if (c < name_chunks) {
      g.set_surface_names_offset(static_cast<int32_t>(name_start[c]));
      for (size_t i = name_start[c]; i < name_start[c + 1]; ++i) g.add_surface_names(names[i]);
    } else {
      g.set_surface_names_offset(static_cast<int32_t>(names.size()));
    }
    const int64_t begin = c < element_chunks ? element_start[c] : n;
    const int64_t end = c < element_chunks ? element_start[c + 1] : n;
    g.set_first_element(begin);
    const int k = static_cast<int>(end - begin);
    int64_t chunk_members = 0;
    for (int64_t e = begin; e < end; ++e) chunk_members += elements[e].num_members;
    const bool member_corners = chunk_members <= kMaxMeshMemberFacesPerMessage;
    if (member_corners) g.mutable_member_corners()->Reserve(static_cast<int>(12 * chunk_members));
    g.mutable_surface()->Reserve(k);
    g.mutable_face()->Reserve(k);
    g.mutable_uv()->Reserve(4 * k);
    g.mutable_corners()->Reserve(12 * k);
    g.mutable_normal()->Reserve(3 * k);
    g.mutable_centroid()->Reserve(3 * k);
    g.mutable_area()->Reserve(k);
    auto add3 = [](google::protobuf::RepeatedField<float>* out, const Vec3& p) {
      out->Add(static_cast<float>(p.x));
      out->Add(static_cast<float>(p.y));
      out->Add(static_cast<float>(p.z));
    };
    for (int64_t e = begin; e < end; ++e) {
      const Element& el = elements[e];
      const MeshFace& f = faces[el.face];
      g.add_surface(el.surface);
      g.add_face(el.face);
      for (float x : {el.u0, el.v0, el.u1, el.v1}) g.add_uv(x);
      // Mesh faces are in recentred coordinates (Mesh::origin): the offsets we want.
      add3(g.mutable_corners(), f.Eval(el.u0, el.v0));
      add3(g.mutable_corners(), f.Eval(el.u1, el.v0));
      add3(g.mutable_corners(), f.Eval(el.u1, el.v1));
      add3(g.mutable_corners(), f.Eval(el.u0, el.v1));
      // Front normal: the halves' normals weighted by the element's area on each (on each face
      // of an agglomerated element).
      std::array<ElementPiece, 2> pieces;
      Vec3 normal;
      for (int m = 0; m < mesh.FaceCount(static_cast<int>(e)); ++m) {
        const MeshFace& mf = faces[mesh.FaceOf(static_cast<int>(e), m)];
        const int np = mesh.Pieces(static_cast<int>(e), &pieces, m);
        for (int p = 0; p < np; ++p) {
          normal = normal + (pieces[p].ParamArea() * mf.jacobian[pieces[p].half]) *
                                mf.normal[pieces[p].half];
        }
      }
      add3(g.mutable_normal(), Length(normal) > 0 ? Normalize(normal) : f.normal[0]);
      add3(g.mutable_centroid(), el.centroid - origin);
      g.add_area(static_cast<float>(el.area));
      g.add_member_count(el.num_members);
      for (int m = 0; m < el.num_members; ++m) {
        const int face = mesh.FaceOf(static_cast<int>(e), m);
        g.add_member_faces(face);
        if (!member_corners) continue;
        const MeshFace& mf = faces[face];
        for (auto [u, v] : {std::pair{0.0, 0.0}, {1.0, 0.0}, {1.0, 1.0}, {0.0, 1.0}}) {
          add3(g.mutable_member_corners(), mf.Eval(u, v));
        }
      }
    }
  }
  // The elements with a back side, as ranges (elements come surface by surface, so there are
  // few), unless there are too many for a snapshot's first message.
  auto back_ranges = std::make_shared<std::vector<int64_t>>();
  for (int64_t e = 0; e < n; ++e) {
    if (!mesh.sides().exists(Slot(static_cast<int>(e), kBack))) continue;
    if (!back_ranges->empty() && back_ranges->back() == e) {
      back_ranges->back() = e + 1;
    } else {
      back_ranges->push_back(e);
      back_ranges->push_back(e + 1);
    }
    if (static_cast<int64_t>(back_ranges->size()) > 2 * kMaxBackRanges) {
      back_ranges = nullptr;
      break;
    }
  }
  return std::make_shared<const MeshAnnouncement>(std::move(chunks), std::move(back_ranges));
}

std::string SerializeMesh(const MeshAnnouncement& mesh) {
  std::string out(kMeshMagic, 4);
  for (const v1::MeshGeometry& c : mesh.chunks()) {
    const std::string bytes = c.SerializeAsString();
    const uint32_t size = static_cast<uint32_t>(bytes.size());
    const char prefix[4] = {static_cast<char>(size & 0xff), static_cast<char>((size >> 8) & 0xff),
                            static_cast<char>((size >> 16) & 0xff),
                            static_cast<char>((size >> 24) & 0xff)};
    out.append(prefix, 4);
    out += bytes;
  }
  return out;
}

absl::StatusOr<MeshPtr> ParseMesh(const std::string& bytes) {
  if (bytes.size() < 4 || bytes.compare(0, 4, kMeshMagic, 4) != 0) {
    return absl::DataLossError("mesh geometry file: bad header");
  }
  std::vector<v1::MeshGeometry> chunks;
  size_t at = 4;
  while (at < bytes.size()) {
    if (bytes.size() - at < 4) return absl::DataLossError("mesh geometry file: truncated");
    uint32_t size = 0;
    for (int k = 0; k < 4; ++k)
      size |= uint32_t{static_cast<unsigned char>(bytes[at + k])} << (8 * k);
    at += 4;
    if (bytes.size() - at < size) return absl::DataLossError("mesh geometry file: truncated");
    v1::MeshGeometry chunk;
    if (!chunk.ParseFromArray(bytes.data() + at, static_cast<int>(size))) {
      return absl::DataLossError("mesh geometry file: a message does not parse");
    }
    at += size;
    chunks.push_back(std::move(chunk));
  }
  if (chunks.empty() || static_cast<int64_t>(chunks.size()) != chunks[0].chunk_count()) {
    return absl::DataLossError(absl::StrCat("mesh geometry file: ", chunks.size(),
                                            " messages, expected ",
                                            chunks.empty() ? 1 : chunks[0].chunk_count()));
  }
  return std::make_shared<const MeshAnnouncement>(std::move(chunks));
}

void JobChannel::Publish(SnapshotPtr snapshot) {
  std::lock_guard<std::mutex> lock(mu_);
  if (closed_) return;
  latest_ = std::move(snapshot);
  for (SnapshotSink* sink : sinks_) sink->OnSnapshot(latest_);
}

void JobChannel::Close(const absl::Status& status) {
  std::lock_guard<std::mutex> lock(mu_);
  if (closed_) return;
  closed_ = true;
  close_status_ = status;
  for (SnapshotSink* sink : sinks_) sink->OnClose(status);
}

void JobChannel::Subscribe(SnapshotSink* sink) {
  std::lock_guard<std::mutex> lock(mu_);
  sinks_.push_back(sink);
  if (closed_) {
    sink->OnClose(close_status_);
  } else if (latest_) {
    sink->OnSnapshot(latest_);
  }
}

void JobChannel::Unsubscribe(SnapshotSink* sink) {
  std::lock_guard<std::mutex> lock(mu_);
  sinks_.erase(std::remove(sinks_.begin(), sinks_.end(), sink), sinks_.end());
}

bool JobChannel::WantsExistingSides() const {
  std::lock_guard<std::mutex> lock(mu_);
  for (const SnapshotSink* sink : sinks_) {
    if (sink->WantsExistingSides()) return true;
  }
  return false;
}

bool JobChannel::HasSinks() const {
  std::lock_guard<std::mutex> lock(mu_);
  return !sinks_.empty();
}

SnapshotPtr JobChannel::latest() const {
  std::lock_guard<std::mutex> lock(mu_);
  return latest_;
}

}  // namespace radiosity::service
