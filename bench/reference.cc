// Reference solutions on disk (bench_util.h): a gzip stream of a text header and float32 RGB.
#include <zlib.h>

#include <cstring>
#include <memory>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "bench/bench_util.h"

namespace radiosity::bench {

namespace {

constexpr char kMagic[] = "radiosity-reference 1";

void Fnv(uint64_t* h, const void* data, size_t n) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (size_t i = 0; i < n; ++i) {
    *h ^= p[i];
    *h *= 0x100000001b3ULL;
  }
}

struct GzCloser {
  void operator()(gzFile_s* f) const {
    if (f != nullptr) gzclose(f);
  }
};
using GzFile = std::unique_ptr<gzFile_s, GzCloser>;

}  // namespace

uint64_t MeshHash(const Mesh& mesh) {
  uint64_t h = 0xcbf29ce484222325ULL;
  const int64_t n = static_cast<int64_t>(mesh.elements().size());
  Fnv(&h, &n, sizeof(n));
  for (const Element& e : mesh.elements()) {
    const int32_t face = e.face;
    const float uv[4] = {e.u0, e.v0, e.u1, e.v1};
    Fnv(&h, &face, sizeof(face));
    Fnv(&h, uv, sizeof(uv));
  }
  return h;
}

absl::Status WriteReference(const std::string& path, const Reference& ref) {
  GzFile f(gzopen(path.c_str(), "wb9"));
  if (f == nullptr) return absl::InternalError(absl::StrCat(path, ": cannot write"));
  std::string header = absl::StrCat(kMagic, "\n");
  for (const auto& [key, value] : ref.meta) {
    std::string v = value;
    for (char& c : v) {
      if (c == '\n') c = ' ';
    }
    absl::StrAppend(&header, key, "=", v, "\n");
  }
  header += "end\n";
  bool ok = gzwrite(f.get(), header.data(), static_cast<unsigned>(header.size())) ==
            static_cast<int>(header.size());
  std::vector<float> data(ref.radiosity.size() * 3);
  // Fronts first, then backs (all zero for one-sided scenes: they compress to nothing).
  const size_t elements = ref.radiosity.size() / 2;
  for (int side = 0; side < 2; ++side) {
    for (size_t e = 0; e < elements; ++e) {
      const Rgb& c = ref.radiosity[Slot(static_cast<int>(e), side)];
      float* out = &data[3 * (side * elements + e)];
      out[0] = static_cast<float>(c.r);
      out[1] = static_cast<float>(c.g);
      out[2] = static_cast<float>(c.b);
    }
  }
  const size_t bytes = data.size() * sizeof(float);
  size_t done = 0;
  while (ok && done < bytes) {
    const unsigned n = static_cast<unsigned>(std::min<size_t>(bytes - done, 1u << 30));
    ok = gzwrite(f.get(), reinterpret_cast<const char*>(data.data()) + done, n) ==
         static_cast<int>(n);
    done += n;
  }
  if (gzclose(f.release()) != Z_OK || !ok) {
    return absl::InternalError(absl::StrCat(path, ": write failed"));
  }
  return absl::OkStatus();
}

absl::StatusOr<Reference> ReadReference(const std::string& path) {
  GzFile f(gzopen(path.c_str(), "rb"));
  if (f == nullptr) return absl::NotFoundError(absl::StrCat(path, ": cannot open"));
  Reference ref;
  char line[8192];
  if (gzgets(f.get(), line, sizeof(line)) == nullptr ||
      std::strncmp(line, kMagic, std::strlen(kMagic)) != 0) {
    return absl::DataLossError(absl::StrCat(path, ": not a radiosity reference"));
  }
  for (;;) {
    if (gzgets(f.get(), line, sizeof(line)) == nullptr) {
      return absl::DataLossError(absl::StrCat(path, ": header has no end"));
    }
    std::string s(line);
    while (!s.empty() && (s.back() == '\n' || s.back() == '\r')) s.pop_back();
    if (s == "end") break;
    const size_t eq = s.find('=');
    if (eq == std::string::npos) continue;
    ref.meta[s.substr(0, eq)] = s.substr(eq + 1);
  }
  int64_t elements = 0;
  if (!absl::SimpleAtoi(ref.meta["elements"], &elements) || elements <= 0) {
    return absl::DataLossError(absl::StrCat(path, ": bad element count"));
  }
  std::vector<float> data(static_cast<size_t>(elements) * 6);
  const size_t bytes = data.size() * sizeof(float);
  size_t done = 0;
  while (done < bytes) {
    const unsigned n = static_cast<unsigned>(std::min<size_t>(bytes - done, 1u << 30));
    const int got = gzread(f.get(), reinterpret_cast<char*>(data.data()) + done, n);
    if (got <= 0) return absl::DataLossError(absl::StrCat(path, ": truncated"));
    done += static_cast<size_t>(got);
  }
  ref.radiosity.resize(static_cast<size_t>(elements) * 2);
  for (int side = 0; side < 2; ++side) {
    for (int64_t e = 0; e < elements; ++e) {
      const float* in = &data[3 * (side * elements + e)];
      ref.radiosity[Slot(static_cast<int>(e), side)] = Rgb(in[0], in[1], in[2]);
    }
  }
  return ref;
}

absl::Status CheckReferenceMesh(const Reference& ref, const Mesh& mesh) {
  const std::string hash = absl::StrCat(MeshHash(mesh));
  auto it = ref.meta.find("mesh_hash");
  if (static_cast<int64_t>(ref.radiosity.size()) !=
          2 * static_cast<int64_t>(mesh.elements().size()) ||
      it == ref.meta.end() || it->second != hash) {
    return absl::FailedPreconditionError(absl::StrCat(
        "the reference was made on another mesh (", ref.radiosity.size() / 2, " elements, hash ",
        it == ref.meta.end() ? "?" : it->second, "; this mesh: ", mesh.elements().size(),
        " elements, hash ", hash, "): regenerate it with bench/run --make-references"));
  }
  return absl::OkStatus();
}

}  // namespace radiosity::bench
