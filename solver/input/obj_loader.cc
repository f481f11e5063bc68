#include "solver/input/obj_loader.h"

#include <fcntl.h>
#include <locale.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <climits>
#include <clocale>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <map>
#include <set>
#include <tuple>
#include <unordered_map>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/string_view.h"
#include "solver/input/model_loader.h"
#include "solver/util/file_io.h"

namespace radiosity {
namespace {

// ---------------------------------------------------------------------------------------------
// Line scanning. Both formats are line-oriented: a keyword, then arguments separated by blanks.

inline bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

// A cursor over one line [p, end); `end` points at the '\n' or the end of the text, so the
// character at `end` is never a digit and strtod cannot run past the line.
struct LineCursor {
  const char* p;
  const char* end;

  void SkipBlanks() {
    while (p < end && IsBlank(*p)) ++p;
  }
  // True at the end of the line or at a trailing comment (only used where '#' cannot be data).
  bool AtEndOrComment() {
    SkipBlanks();
    return p >= end || *p == '#';
  }
  absl::string_view Token() {
    SkipBlanks();
    const char* start = p;
    while (p < end && !IsBlank(*p)) ++p;
    return absl::string_view(start, static_cast<size_t>(p - start));
  }
  // The rest of the line without surrounding blanks (names may contain blanks or '#').
  absl::string_view Rest() {
    SkipBlanks();
    const char* e = end;
    while (e > p && IsBlank(e[-1])) --e;
    return absl::string_view(p, static_cast<size_t>(e - p));
  }
};

// Calls `fn(line_number, cursor)` for every line that is not blank or a comment. The text must be
// NUL-terminated at text.size() (std::string guarantees it). Stops at the first error.
template <typename Fn>
absl::Status ForEachLine(const std::string& text, Fn fn) {
  const char* p = text.data();
  const char* const end = p + text.size();
  // A UTF-8 byte-order mark is allowed at the start.
  if (text.size() >= 3 && std::memcmp(p, "\xEF\xBB\xBF", 3) == 0) p += 3;
  int line = 0;
  while (p < end) {
    ++line;
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', static_cast<size_t>(end - p)));
    if (eol == nullptr) eol = end;
    LineCursor cursor{p, eol};
    if (!cursor.AtEndOrComment()) {
      if (absl::Status s = fn(line, cursor); !s.ok()) return s;
    }
    p = eol + 1;
  }
  return absl::OkStatus();
}

// Parses a floating-point token with strtod in the "C" locale (a decimal point whatever the
// process locale); fails unless the whole token is a number. NaN and infinity parse successfully
// (callers decide).
bool ParseDouble(absl::string_view token, double* value) {
  static const locale_t c_locale = newlocale(LC_ALL_MASK, "C", locale_t{});
  if (token.empty()) return false;
  // The token ends at a blank, '\n' or the terminating NUL, none of which strtod consumes after a
  // number, so parsing in place is safe.
  char* stop = nullptr;
  *value = strtod_l(token.data(), &stop, c_locale);
  return stop == token.data() + token.size();
}

// Parses an OBJ index: an optional '-' and digits. Saturates at INT_MAX in magnitude so that
// absurd indices are reported as out of range rather than wrapped.
bool ParseIndex(absl::string_view token, long long* value) {
  if (token.empty()) return false;
  size_t i = 0;
  bool negative = false;
  if (token[0] == '-' || token[0] == '+') {
    negative = token[0] == '-';
    i = 1;
  }
  if (i == token.size()) return false;
  long long v = 0;
  for (; i < token.size(); ++i) {
    char c = token[i];
    if (c < '0' || c > '9') return false;
    v = v * 10 + (c - '0');
    if (v > INT_MAX) v = static_cast<long long>(INT_MAX) + 1;
  }
  *value = negative ? -v : v;
  return true;
}

// What a nameless `newmtl` / `usemtl` (as Blender writes them) is called.
constexpr char kUnnamedMaterial[] = "unnamed";

std::string Channels(const Rgb& c) { return absl::StrFormat("(%g, %g, %g)", c.r, c.g, c.b); }

// Rewrites `text` from UTF-16 to UTF-8 when it starts with a UTF-16 byte-order mark (some
// Windows exporters write it); otherwise leaves it. Unpaired surrogates become U+FFFD.
void DecodeUtf16(std::string* text) {
  if (text->size() < 2) return;
  const auto b0 = static_cast<unsigned char>((*text)[0]),
             b1 = static_cast<unsigned char>((*text)[1]);
  const bool big = b0 == 0xFE && b1 == 0xFF, little = b0 == 0xFF && b1 == 0xFE;
  if (!big && !little) return;
  auto unit = [&](size_t i) -> uint32_t {
    const auto hi = static_cast<unsigned char>((*text)[i + (little ? 1 : 0)]);
    const auto lo = static_cast<unsigned char>((*text)[i + (little ? 0 : 1)]);
    return (uint32_t{hi} << 8) | lo;
  };
  std::string out;
  out.reserve(text->size() / 2);
  for (size_t i = 2; i + 1 < text->size(); i += 2) {
    uint32_t c = unit(i);
    if (c >= 0xD800 && c <= 0xDBFF && i + 3 < text->size()) {
      const uint32_t d = unit(i + 2);
      if (d >= 0xDC00 && d <= 0xDFFF) {
        c = 0x10000 + ((c - 0xD800) << 10) + (d - 0xDC00);
        i += 2;
      } else {
        c = 0xFFFD;
      }
    } else if (c >= 0xD800 && c <= 0xDFFF) {
      c = 0xFFFD;
    }
    if (c < 0x80) {
      out += static_cast<char>(c);
    } else if (c < 0x800) {
      out += static_cast<char>(0xC0 | (c >> 6));
      out += static_cast<char>(0x80 | (c & 0x3F));
    } else if (c < 0x10000) {
      out += static_cast<char>(0xE0 | (c >> 12));
      out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
      out += static_cast<char>(0x80 | (c & 0x3F));
    } else {
      out += static_cast<char>(0xF0 | (c >> 18));
      out += static_cast<char>(0x80 | ((c >> 12) & 0x3F));
      out += static_cast<char>(0x80 | ((c >> 6) & 0x3F));
      out += static_cast<char>(0x80 | (c & 0x3F));
    }
  }
  *text = std::move(out);
}

int Utf8SequenceLength(const std::string& s, size_t i);  // Below.

// Length of the longest prefix of `s` that is valid UTF-8 (s.size() when all of it is).
size_t ValidUtf8Prefix(const std::string& s) {
  size_t i = 0;
  while (i < s.size()) {
    if (static_cast<unsigned char>(s[i]) < 0x80) {
      ++i;
      continue;
    }
    const int n = Utf8SequenceLength(s, i);
    if (n == 0) return i;
    i += static_cast<size_t>(n);
  }
  return i;
}

// Makes `text` (read from `name`) UTF-8 as exporters write it: UTF-16 with a byte-order mark is
// decoded; text that is not UTF-8 but has no NUL byte (the Latin-1 names and comments of older
// exporters) is read as Latin-1 (ISO 8859-1) with a warning. Binary files stay errors (CheckText).
absl::Status DecodeText(std::string* text, const std::string& name,
                        std::vector<std::string>* warnings) {
  DecodeUtf16(text);
  absl::Status status = CheckText(*text, name);
  // CheckText looks at the first 64 KiB; a Latin-1 byte may come later (a material name at line
  // 4841 of an exporter's file), and text that is not UTF-8 must never reach a message.
  if (status.ok() && ValidUtf8Prefix(*text) == text->size()) return status;
  const size_t limit = std::min<size_t>(text->size(), 64 * 1024);
  if (std::memchr(text->data(), '\0', limit) != nullptr) return status;
  std::string out;
  out.reserve(text->size() + text->size() / 8);
  for (const char ch : *text) {
    const auto c = static_cast<unsigned char>(ch);
    if (c < 0x80) {
      out += ch;
    } else {
      out += static_cast<char>(0xC0 | (c >> 6));
      out += static_cast<char>(0x80 | (c & 0x3F));
    }
  }
  size_t offset = 0;
  while (offset < text->size()) {
    const int n = Utf8SequenceLength(*text, offset);
    if (n == 0) break;
    offset += static_cast<size_t>(n);
  }
  if (warnings) {
    warnings->push_back(absl::StrFormat(
        "%s: not UTF-8 (byte 0x%02X at offset %d); read as Latin-1", name,
        offset < text->size() ? static_cast<unsigned char>((*text)[offset]) : 0, offset));
  }
  *text = std::move(out);
  return absl::OkStatus();
}

// A material library name as exporters write it, as a relative path: backslashes become slashes
// and leading "./" parts go ("./box.mtl" and ".\\mat\\box.mtl" name "box.mtl", "mat/box.mtl").
std::string NormaliseLibraryName(absl::string_view name) {
  std::string out(name);
  std::replace(out.begin(), out.end(), '\\', '/');
  while (out.size() > 2 && out[0] == '.' && out[1] == '/') {
    out.erase(0, 2);
    while (!out.empty() && out[0] == '/' && out.size() > 1) out.erase(0, 1);
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// MTL.

struct LibraryMaterial {
  Material material;
  std::string file;    // The MTL path, for messages.
  absl::Status error;  // First problem with its values; reported only if a face uses it.
  int scene_index = -1;
  // As read; `finish` in ParseMtl combines them into reflectance d x Kd and transmittance
  // (1 - d) x Tf.
  Rgb kd;
  Rgb tf = Rgb::Gray(1);
  double dissolve = 1;
  double ni = 1.5;  // Ni, the glass's index of refraction.
};

struct MaterialLibrary {
  std::vector<LibraryMaterial> materials;
  std::unordered_map<std::string, int> by_name;
  std::set<std::string> loaded_files;

  // The defined names for a message, at most 20 of them.
  std::string DefinedNames() const {
    constexpr size_t kMaxNames = 20;
    std::vector<std::string> names;
    for (size_t i = 0; i < materials.size() && i < kMaxNames; ++i) {
      names.push_back(materials[i].material.name);
    }
    std::string text = absl::StrJoin(names, ", ");
    if (materials.size() > kMaxNames) {
      absl::StrAppend(&text, " and ", materials.size() - kMaxNames, " more");
    }
    return text;
  }
};

// Reads `Kd`-style values: one value (gray) or three. Fails naming the file and line.
absl::Status ParseColor(LineCursor& cursor, absl::string_view key, const std::string& where,
                        Rgb* color) {
  double v[3];
  int n = 0;
  while (!cursor.AtEndOrComment()) {
    absl::string_view token = cursor.Token();
    if (n == 3 || !ParseDouble(token, &v[n])) {
      if (n == 0 && (token == "spectral" || token == "xyz")) {
        return absl::InvalidArgumentError(absl::StrCat(
            where, "'", key, " ", token, "' is not supported; give linear RGB values"));
      }
      return absl::InvalidArgumentError(
          absl::StrCat(where, "'", key, "' expects 1 or 3 numbers; '", token, "' is not one"));
    }
    ++n;
  }
  if (n == 1) {
    *color = Rgb::Gray(v[0]);
  } else if (n == 3) {
    *color = Rgb(v[0], v[1], v[2]);
  } else {
    return absl::InvalidArgumentError(
        absl::StrCat(where, "'", key, "' expects 1 or 3 numbers, got ", n));
  }
  return absl::OkStatus();
}

// Checks what can be checked of one value as soon as it is read (same wording as ValidateScene).
absl::Status CheckColor(absl::string_view key, const Rgb& c, const std::string& where) {
  if (!c.IsFinite()) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, "NaN or infinite value in ", key, " ", Channels(c)));
  }
  for (int i = 0; i < 3; ++i) {
    if (key == "Kd" && (c[i] < 0 || c[i] >= 1)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "reflectance (Kd) ", Channels(c), " is outside [0, 1)"));
    }
    if (key == "Tf" && (c[i] < 0 || c[i] > 1)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "transmittance (Tf) ", Channels(c), " is outside [0, 1]"));
    }
    if (key == "Ke" && c[i] < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "negative emission (Ke) ", Channels(c)));
    }
  }
  return absl::OkStatus();
}

bool IsIgnoredMtlKey(absl::string_view key) {
  static const char* const kIgnored[] = {"Ka",     "sharpness", "bump", "disp", "decal", "refl",
                                         "Pr",     "Pm",        "Ps",   "Pc",   "Pcr",   "aniso",
                                         "anisor", "norm",      "Km",   "Tm",   "Ts"};
  if (key.substr(0, 4) == "map_") return true;
  for (const char* k : kIgnored) {
    if (key == k) return true;
  }
  return false;
}

// Reads the single number of `d`, `Tr`, `Ns`, `Ni` or `illum`.
absl::Status ParseNumber(LineCursor& cursor, absl::string_view key, const std::string& where,
                         double* value) {
  const absl::string_view token = cursor.Token();
  if (!ParseDouble(token, value) || !std::isfinite(*value)) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, "'", key, "' expects a number; '", token, "' is not one"));
  }
  // Some exporters write `d -halo 0.5`; any further token is an error as for colours.
  if (!cursor.AtEndOrComment()) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, "'", key, "' expects one number; '", cursor.Token(), "' follows it"));
  }
  return absl::OkStatus();
}

// Parses one MTL file into `library`. Problems with values are stored with the material and
// reported when a face uses it; syntax errors fail at once.
absl::Status ParseMtl(const std::string& text, const std::string& file, MaterialLibrary* library,
                      const ObjOptions& options, std::vector<std::string>* warnings) {
  int current = -1;
  bool current_is_duplicate = false;
  LibraryMaterial scratch;  // Receives the values of a duplicate definition (ignored).
  std::map<std::string, std::pair<int, int>> unknown;  // key -> (first line, count)

  // docs/guide/specular.md, the MTL mapping: illum 4, 6 or 7 makes the
  // transparent part (1 - d) x Tf glass of index Ni; illum 3 or 5 makes d x Ks a mirror; illum 2
  // with Ns >= 1 makes d x Ks a glossy lobe of exponent Ns; otherwise the transparent part
  // transmits diffusely and Ks is not used.
  auto finish = [&](LibraryMaterial* m) {
    if (!m->error.ok()) return;
    Material& mat = m->material;
    const std::string what = absl::StrCat(file, ":", mat.line, ": material '", mat.name, "': ");
    mat.reflectance = m->kd * m->dissolve;
    const bool glass = mat.illum == 4 || mat.illum == 6 || mat.illum == 7;
    if (glass) {
      mat.glass = m->tf * (1 - m->dissolve);
      mat.ior = m->ni;
      if (!(m->ni >= 1 && m->ni <= kMaxIor)) {
        mat.ior = 1.5;
        if (warnings && !mat.glass.IsZero()) {
          warnings->push_back(absl::StrCat(what, "Ni ", m->ni,
                                           " is not an index of refraction in [1, ", kMaxIor,
                                           "]: the glass takes 1.5"));
        }
      }
    } else {
      mat.transmittance = m->tf * (1 - m->dissolve);
    }
    Rgb sum = mat.reflectance + mat.transmittance + mat.glass;
    if (sum.Max() > 1) {
      m->error = absl::InvalidArgumentError(
          absl::StrCat(what, "reflectance + transmittance ", Channels(sum), " is above 1"));
      return;
    }
    const bool mirror = mat.illum == 3 || mat.illum == 5;
    const bool glossy = mat.illum == 2 && mat.shininess >= 1;
    if (!(mirror || glossy) || mat.specular.IsZero()) return;
    if (glossy && mat.shininess > kMaxGlossyExponent) {
      m->error = absl::InvalidArgumentError(
          absl::StrCat(what, "Ns ", mat.shininess, " is above ", kMaxGlossyExponent));
      return;
    }
    // The specular part keeps the diffuse one as written and takes at most what is left of
    // kMaxReflectance (exporters write Kd 0.8 with Ks 0.5).
    const Rgb wanted = mat.specular * m->dissolve;
    Rgb part;
    for (int c = 0; c < 3; ++c) {
      part[c] = std::clamp(std::min(wanted[c], kMaxReflectance - sum[c]), 0.0, 1.0);
    }
    if (!(part == wanted)) {
      if (options.strict) {
        m->error = absl::InvalidArgumentError(
            absl::StrCat(what, "Kd + Ks ", Channels(sum + wanted), " is above ", kMaxReflectance));
        return;
      }
      if (warnings) {
        warnings->push_back(absl::StrCat(what, "Ks ", Channels(wanted), " reduced to ",
                                         Channels(part), " so that Kd + Ks stays at most ",
                                         kMaxReflectance));
      }
    }
    if (mirror) {
      mat.mirror = part;
    } else {
      mat.glossy = part;
      mat.glossy_exponent = mat.shininess;
    }
  };
  auto target = [&]() -> LibraryMaterial* {
    return current_is_duplicate ? &scratch : &library->materials[current];
  };

  absl::Status status = ForEachLine(text, [&](int line, LineCursor& cursor) -> absl::Status {
    std::string where = absl::StrCat(file, ":", line, ": ");
    absl::string_view key = cursor.Token();
    if (key == "newmtl") {
      if (current >= 0) finish(target());
      std::string name(cursor.Rest());
      if (name.empty()) {
        if (options.strict) {
          return absl::InvalidArgumentError(absl::StrCat(where, "newmtl needs a material name"));
        }
        // Blender writes `newmtl ` and `usemtl ` for a material without a name.
        name = kUnnamedMaterial;
        if (warnings) {
          warnings->push_back(
              absl::StrCat(where, "newmtl without a name: called '", kUnnamedMaterial, "'"));
        }
      }
      auto it = library->by_name.find(name);
      if (it != library->by_name.end()) {
        const LibraryMaterial& first = library->materials[it->second];
        if (warnings) {
          warnings->push_back(absl::StrCat(where, "material '", name,
                                           "' is defined again (first at ", first.file, ":",
                                           first.material.line, "); keeping the first definition"));
        }
        current_is_duplicate = true;
        scratch = LibraryMaterial();
        scratch.material.name = name;
        scratch.material.line = line;
        current = it->second;
        return absl::OkStatus();
      }
      current_is_duplicate = false;
      LibraryMaterial m;
      m.material.name = name;
      m.material.line = line;
      m.file = file;
      current = static_cast<int>(library->materials.size());
      library->by_name.emplace(name, current);
      library->materials.push_back(std::move(m));
      return absl::OkStatus();
    }
    if (key == "d" || key == "Tr" || key == "Ns" || key == "Ni" || key == "illum") {
      if (current < 0) {
        return absl::InvalidArgumentError(absl::StrCat(where, "'", key, "' before any newmtl"));
      }
      LibraryMaterial* m = target();
      double value;
      if (absl::Status s = ParseNumber(cursor, key, where, &value); !s.ok()) return s;
      const std::string what = absl::StrCat(where, "material '", m->material.name, "': ");
      if (key == "Ns") {
        m->material.shininess = value;
      } else if (key == "Ni") {
        m->ni = value;
      } else if (key == "illum") {
        if (value >= 0 && value <= 1000) {
          m->material.illum = static_cast<int>(value);
        } else if (m->error.ok()) {
          m->error = absl::InvalidArgumentError(
              absl::StrCat(what, "'illum ", value, "' is not an illumination model (0-10)"));
        }
      } else if (!(value >= 0 && value <= 1)) {
        if (m->error.ok()) {
          m->error = absl::InvalidArgumentError(
              absl::StrCat(what, "'", key, " ", value, "' is outside [0, 1]"));
        }
      } else {
        m->dissolve = key == "d" ? value : 1 - value;
      }
      return absl::OkStatus();
    }
    if (key == "Kd" || key == "Ke" || key == "Tf" || key == "Ks" || key == "two_sided") {
      if (current < 0) {
        return absl::InvalidArgumentError(absl::StrCat(where, "'", key, "' before any newmtl"));
      }
      LibraryMaterial* m = target();
      if (key == "two_sided") {
        absl::string_view value = cursor.Token();
        if (value == "1" || value == "on" || value == "true") {
          m->material.two_sided = true;
        } else if (value == "0" || value == "off" || value == "false") {
          m->material.two_sided = false;
        } else {
          return absl::InvalidArgumentError(
              absl::StrCat(where, "two_sided expects 1, 0, on or off, got '", value, "'"));
        }
        return absl::OkStatus();
      }
      Rgb color;
      if (absl::Status s = ParseColor(cursor, key, where, &color); !s.ok()) return s;
      if (key == "Kd" && !options.strict && color.IsFinite() && color.Max() >= 1 &&
          !(color.Min() < 0)) {
        const Rgb clamped(std::min(color.r, kMaxReflectance), std::min(color.g, kMaxReflectance),
                          std::min(color.b, kMaxReflectance));
        if (warnings && !current_is_duplicate) {
          warnings->push_back(absl::StrCat(where, "material '", m->material.name, "': Kd ",
                                           Channels(color), " clamped to ", Channels(clamped),
                                           " (a reflectance of 1 never lets the light go)"));
        }
        color = clamped;
      }
      if (key == "Kd") m->kd = color;
      if (key == "Ke") m->material.emission = color;
      if (key == "Tf") m->tf = color;
      if (key == "Ks") m->material.specular = color;
      if (m->error.ok()) {
        m->error =
            CheckColor(key, color, absl::StrCat(where, "material '", m->material.name, "': "));
      }
      return absl::OkStatus();
    }
    if (IsIgnoredMtlKey(key)) return absl::OkStatus();
    auto [it, inserted] = unknown.try_emplace(std::string(key), line, 0);
    ++it->second.second;
    return absl::OkStatus();
  });
  if (!status.ok()) return status;
  if (current >= 0) finish(target());
  if (warnings) {
    for (const auto& [key, where] : unknown) {
      warnings->push_back(
          absl::StrCat(file, ":", where.first, ": unknown MTL keyword '", key, "' ignored",
                       where.second > 1 ? absl::StrCat(" (", where.second, " lines)") : ""));
    }
  }
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------------------------
// OBJ.

struct Group {
  std::string name;
  int line = 0;  // Line of the `o`/`g` statement, or of its first face for the default group.
};

// A face as parsed, before surfaces are formed.
struct RawFace {
  int group;
  int material;  // Index into Scene::materials.
  int line;
  std::vector<int> vertices;
};

class ObjParser {
 public:
  ObjParser(const std::string& name, const std::string& mtl_dir, const ObjOptions& options,
            std::vector<std::string>* warnings)
      : name_(name), mtl_dir_(mtl_dir), options_(options), warnings_(warnings) {}

  absl::StatusOr<Scene> Parse(const std::string& text) {
    scene_.source = name_;
    absl::Status status = ForEachLine(text, [this](int line, LineCursor& cursor) {
      if (line % 65536 == 0) {
        if (absl::Status st = StopStatus(options_.stop, "reading the OBJ file"); !st.ok()) {
          return st;
        }
      }
      return Line(line, cursor);
    });
    if (!status.ok()) return status;
    BuildSurfaces();
    if (warnings_) {
      for (size_t i = 0; i < default_causes_.size(); ++i) {
        const LineRanges& r = defaulted_[i];
        warnings_->push_back(absl::StrCat(name_, ":", r.ToString(), ": ", default_causes_[i], ": ",
                                          r.count, r.count == 1 ? " face takes" : " faces take",
                                          " the default material '", kDefaultMaterialName,
                                          "' (grey, Kd ", kDefaultReflectance, ")"));
      }
      for (const auto& [key, where] : unknown_) {
        warnings_->push_back(
            absl::StrCat(Where(where.first), "unknown OBJ keyword '", key, "' ignored",
                         where.second > 1 ? absl::StrCat(" (", where.second, " lines)") : ""));
      }
    }
    return std::move(scene_);
  }

 private:
  std::string Where(int line) const { return absl::StrCat(name_, ":", line, ": "); }
  absl::Status Error(int line, absl::string_view message) const {
    return absl::InvalidArgumentError(absl::StrCat(Where(line), message));
  }

  absl::Status Line(int line, LineCursor& cursor) {
    absl::string_view key = cursor.Token();
    if (key == "v") return Vertex(line, cursor);
    if (key == "f") return FaceLine(line, cursor);
    if (key == "g" || key == "o") {
      std::string group_name(cursor.Rest());
      if (group_name.empty()) group_name = DefaultGroupName();
      SetGroup(group_name, line);
      return absl::OkStatus();
    }
    if (key == "usemtl") {
      material_name_ = std::string(cursor.Rest());
      if (material_name_.empty()) {
        if (options_.strict) return Error(line, "usemtl needs a material name");
        material_name_ = kUnnamedMaterial;  // As ParseMtl names `newmtl ` without a name.
      }
      usemtl_line_ = line;
      material_ = -1;  // Resolved at the first face that uses it.
      default_cause_ = -1;
      return absl::OkStatus();
    }
    if (key == "mtllib") return MtlLib(line, cursor);
    if (key == "vt" || key == "vn" || key == "vp" || key == "s" || key == "l" || key == "p") {
      return absl::OkStatus();
    }
    auto [it, inserted] = unknown_.try_emplace(std::string(key), line, 0);
    ++it->second.second;
    return absl::OkStatus();
  }

  absl::Status Vertex(int line, LineCursor& cursor) {
    double c[3];
    for (int i = 0; i < 3; ++i) {
      if (cursor.AtEndOrComment()) {
        return Error(line, absl::StrCat("vertex has ", i, " coordinates; it needs 3"));
      }
      absl::string_view token = cursor.Token();
      if (!ParseDouble(token, &c[i])) {
        return Error(line, absl::StrCat("vertex coordinate '", token, "' is not a number"));
      }
      if (!std::isfinite(c[i])) {
        return Error(line, absl::StrCat("vertex has a NaN or infinite coordinate ('", token, "')"));
      }
    }
    // An optional weight w (only meaningful for rational curves: ignored) or, in some exporters'
    // files, a vertex colour r g b follow. They must be numbers.
    double extra[4];
    int extras = 0;
    while (!cursor.AtEndOrComment()) {
      absl::string_view token = cursor.Token();
      double value;
      if (!ParseDouble(token, &value)) {
        return Error(line, absl::StrCat("vertex value '", token, "' is not a number"));
      }
      if (extras < 4) extra[extras] = value;
      ++extras;
    }
    if (options_.vertex_colors) {
      vertex_color_.resize(scene_.vertices.size(), kNoColor);
      if (extras == 3 && std::isfinite(extra[0] + extra[1] + extra[2])) {
        vertex_color_.push_back(Rgb(std::clamp(extra[0], 0.0, 1.0), std::clamp(extra[1], 0.0, 1.0),
                                    std::clamp(extra[2], 0.0, 1.0)));
      } else {
        vertex_color_.push_back(kNoColor);
      }
    }
    scene_.vertices.push_back({c[0], c[1], c[2]});
    return absl::OkStatus();
  }

  absl::Status FaceLine(int line, LineCursor& cursor) {
    const long long nv = static_cast<long long>(scene_.vertices.size());
    RawFace face;
    face.line = line;
    face.vertices.reserve(4);
    while (!cursor.AtEndOrComment()) {
      absl::string_view token = cursor.Token();
      // i, i/t, i//n or i/t/n: only the position index matters here.
      size_t slash = token.find('/');
      absl::string_view index_text = token.substr(0, slash);
      long long index;
      if (!ParseIndex(index_text, &index)) {
        return Error(line, absl::StrCat("bad face vertex '", token, "'"));
      }
      if (slash != absl::string_view::npos) {
        absl::string_view rest = token.substr(slash + 1);
        size_t slash2 = rest.find('/');
        absl::string_view t = rest.substr(0, slash2);
        absl::string_view n =
            slash2 == absl::string_view::npos ? absl::string_view() : rest.substr(slash2 + 1);
        long long ignored;
        if ((!t.empty() && !ParseIndex(t, &ignored)) ||
            (slash2 != absl::string_view::npos && !ParseIndex(n, &ignored))) {
          return Error(line, absl::StrCat("bad face vertex '", token, "'"));
        }
      }
      if (index == 0) {
        return Error(line, "vertex index 0 is invalid (OBJ indices start at 1)");
      }
      long long resolved = index > 0 ? index - 1 : nv + index;
      if (resolved < 0 || resolved >= nv) {
        return Error(line, absl::StrCat("vertex index ", index, " is out of range (", nv,
                                        " vertices defined so far)"));
      }
      face.vertices.push_back(static_cast<int>(resolved));
    }
    if (face.vertices.size() < 3) {
      return Error(line, absl::StrCat("face has ", face.vertices.size(),
                                      " vertices; a face needs at least 3"));
    }
    if (material_ < 0) {
      if (absl::Status s = ResolveMaterial(line); !s.ok()) return s;
    }
    if (default_cause_ >= 0) defaulted_[default_cause_].Add(line);
    if (group_ < 0) SetGroup(DefaultGroupName(), line);
    face.group = group_;
    face.material = material_;
    faces_.push_back(std::move(face));
    return absl::OkStatus();
  }

  // Finds the current usemtl material in the libraries and adds it to the scene if new. Without
  // one (no usemtl, or a name no library defines), the default material unless options.strict.
  absl::Status ResolveMaterial(int face_line) {
    if (usemtl_line_ == 0) {
      if (options_.strict) return Error(face_line, "no material (usemtl) for face");
      UseDefaultMaterial("no material (usemtl)");
      return absl::OkStatus();
    }
    auto it = library_.by_name.find(material_name_);
    if (it == library_.by_name.end()) {
      std::string defined =
          library_.materials.empty() ? "none; is an mtllib line missing?" : library_.DefinedNames();
      std::string message =
          absl::StrCat("unknown material '", material_name_, "' (defined: ", defined, ")");
      if (options_.strict) return Error(usemtl_line_, message);
      UseDefaultMaterial(absl::StrCat(message, " named at line ", usemtl_line_));
      return absl::OkStatus();
    }
    LibraryMaterial& m = library_.materials[it->second];
    if (!m.error.ok()) return m.error;
    if (m.scene_index < 0) {
      m.scene_index = static_cast<int>(scene_.materials.size());
      scene_.materials.push_back(m.material);
    }
    material_ = m.scene_index;
    return absl::OkStatus();
  }

  absl::Status MtlLib(int line, LineCursor& cursor) {
    const absl::string_view rest = cursor.Rest();
    if (rest.empty()) return Error(line, "mtllib needs a file name");
    const std::vector<std::string> files = MaterialLibraryNames(rest, mtl_dir_);
    if (options_.confine_to_directory) {
      for (const std::string& file : files) {
        if (!IsSafeRelativeName(file)) {
          return absl::InvalidArgumentError(absl::StrCat(
              Where(line), "mtllib '", file,
              "': only material libraries inside the scene's directory are read (a relative "
              "path without '..')"));
        }
      }
    }
    for (const std::string& file : files) {
      std::string path = JoinPath(mtl_dir_, file);
      if (!library_.loaded_files.insert(path).second) continue;
      absl::StatusOr<std::string> text = ReadWholeFile(path, "material library");
      if (!text.ok()) {
        std::string message =
            absl::StrCat(Where(line), "mtllib '", file, "': ", text.status().message());
        if (absl::IsNotFound(text.status()) && !options_.strict) {
          // Its materials become unknown names, which take the default with their own warning.
          if (warnings_) warnings_->push_back(absl::StrCat(message, "; skipped"));
          continue;
        }
        return absl::IsNotFound(text.status()) ? absl::NotFoundError(message)
                                               : absl::InvalidArgumentError(message);
      }
      if (absl::Status s = DecodeText(&*text, path, warnings_); !s.ok()) {
        return absl::InvalidArgumentError(
            absl::StrCat(Where(line), "mtllib '", file, "': ", s.message()));
      }
      if (absl::Status s = ParseMtl(*text, path, &library_, options_, warnings_); !s.ok()) {
        return s;
      }
    }
    return absl::OkStatus();
  }

  std::string DefaultGroupName() const {
    std::string stem = Stem(name_);
    return stem.empty() ? "default" : stem;
  }

  // Line numbers as compact ranges for a message: "4-9, 12 and 3 more ranges".
  struct LineRanges {
    std::vector<std::pair<int, int>> ranges;
    int64_t count = 0;
    void Add(int line) {
      ++count;
      if (!ranges.empty() && ranges.back().second + 1 >= line) {
        ranges.back().second = std::max(ranges.back().second, line);
      } else {
        ranges.push_back({line, line});
      }
    }
    std::string ToString() const {
      constexpr size_t kShown = 6;
      std::vector<std::string> parts;
      for (size_t i = 0; i < ranges.size() && i < kShown; ++i) {
        const auto [a, b] = ranges[i];
        parts.push_back(a == b ? absl::StrCat(a) : absl::StrCat(a, "-", b));
      }
      std::string text = absl::StrJoin(parts, ", ");
      if (ranges.size() > kShown) {
        absl::StrAppend(&text, " and ", ranges.size() - kShown, " more ranges");
      }
      return text;
    }
  };

  // The current faces take the default material (added to the scene at its first use) because
  // of `cause`; FaceLine counts them under it.
  void UseDefaultMaterial(const std::string& cause) {
    if (default_material_ < 0) {
      default_material_ = static_cast<int>(scene_.materials.size());
      Material m;
      m.name = kDefaultMaterialName;
      m.reflectance = Rgb::Gray(kDefaultReflectance);
      scene_.materials.push_back(m);
    }
    material_ = default_material_;
    auto [it, inserted] = default_cause_index_.try_emplace(cause, default_causes_.size());
    if (inserted) {
      default_causes_.push_back(cause);
      defaulted_.emplace_back();
    }
    default_cause_ = static_cast<int>(it->second);
  }

  void SetGroup(const std::string& group_name, int line) {
    auto [it, inserted] = group_index_.try_emplace(group_name, static_cast<int>(groups_.size()));
    if (inserted) groups_.push_back({group_name, line});
    group_ = it->second;
  }

  // A face's mean vertex colour (ObjOptions::vertex_colors), or kNoColor when some vertex has
  // none.
  Rgb FaceColor(const RawFace& f) const {
    Rgb sum;
    for (int v : f.vertices) {
      const Rgb& c = vertex_color_[static_cast<size_t>(v)];
      if (c.r < 0) return kNoColor;
      sum += c;
    }
    return sum / static_cast<double>(f.vertices.size());
  }

  // One surface per (group, material); named after the group alone when the group has a single
  // material, else "group/material". Surfaces are ordered by first appearance. With
  // ObjOptions::vertex_colors, faces with colours are split further by colour ("...#k").
  void BuildSurfaces() {
    std::vector<std::set<int>> materials_of_group(groups_.size());
    for (const RawFace& f : faces_) materials_of_group[f.group].insert(f.material);
    const bool colored = options_.vertex_colors && !vertex_color_.empty();
    if (colored) vertex_color_.resize(scene_.vertices.size(), kNoColor);
    std::vector<Rgb> face_color;
    if (colored) {
      face_color.reserve(faces_.size());
      for (const RawFace& f : faces_) face_color.push_back(FaceColor(f));
    }
    // Faces without a colour count as one more group, as they make one more surface.
    const double step = ColorGroupingStep(face_color);
    if (colored && step != kTextureColorStep) {
      if (warnings_) {
        warnings_->push_back(absl::StrFormat(
            "%s: vertex colours rounded to steps of 1/%d to keep %d colours or fewer", name_,
            static_cast<int>(std::lround(1 / step)), kMaxColorGroups));
      }
    }
    std::map<std::tuple<int, int, std::array<int64_t, 3>>, int> surface_of;
    std::map<std::pair<int, int>, int> colours_of;  // (group, material) -> colour surfaces so far
    scene_.faces.reserve(faces_.size());
    for (size_t i = 0; i < faces_.size(); ++i) {
      RawFace& f = faces_[i];
      const std::array<int64_t, 3> key = colored && face_color[i].r >= 0
                                             ? ColorKey(face_color[i], step)
                                             : std::array<int64_t, 3>{-1, -1, -1};
      auto [it, inserted] = surface_of.try_emplace({f.group, f.material, key},
                                                   static_cast<int>(scene_.surfaces.size()));
      if (inserted) {
        const Group& g = groups_[f.group];
        Surface s;
        s.material = f.material;
        if (materials_of_group[f.group].size() > 1) {
          s.name = absl::StrCat(g.name, "/", scene_.materials[f.material].name);
          s.line = f.line;
        } else {
          s.name = g.name;
          s.line = g.line;
        }
        if (key[0] >= 0) {
          absl::StrAppend(&s.name, "#", ++colours_of[{f.group, f.material}]);
          Material m = scene_.materials[f.material];
          m.name = absl::StrCat(m.name, "@", s.name);
          // The colour takes Kd's place: what the material transmits (1 - d, filtered by Tf)
          // stays, and the colour is scaled by what is left (d x colour for a white Tf).
          for (int c = 0; c < 3; ++c) {
            m.reflectance[c] = std::min(
                static_cast<double>(key[c]) * step * (1 - m.transmittance[c]), kMaxReflectance);
          }
          scene_.materials.push_back(std::move(m));
          s.material = static_cast<int>(scene_.materials.size()) - 1;
        }
        scene_.surfaces.push_back(std::move(s));
      }
      Face face;
      face.surface = it->second;
      face.vertices = std::move(f.vertices);
      face.line = f.line;
      scene_.faces.push_back(std::move(face));
    }
    faces_.clear();
  }

  const std::string name_;
  const std::string mtl_dir_;
  const ObjOptions options_;
  std::vector<std::string>* const warnings_;

  Scene scene_;
  MaterialLibrary library_;
  std::vector<Group> groups_;
  std::unordered_map<std::string, int> group_index_;
  std::vector<RawFace> faces_;
  // ObjOptions::vertex_colors: each vertex's colour, kNoColor where it has none.
  static constexpr Rgb kNoColor{-1, -1, -1};
  std::vector<Rgb> vertex_color_;
  std::map<std::string, std::pair<int, int>> unknown_;  // keyword -> (first line, count)

  // Faces given the default material, per cause (in order of first appearance).
  int default_material_ = -1;
  int default_cause_ = -1;  // Of the current faces, or -1.
  std::vector<std::string> default_causes_;
  std::unordered_map<std::string, size_t> default_cause_index_;
  std::vector<LineRanges> defaulted_;

  int group_ = -1;
  std::string material_name_;
  int usemtl_line_ = 0;  // 0 while no usemtl has been seen.
  int material_ = -1;    // Scene material of the current usemtl, -1 until resolved.
};

// Length of the valid UTF-8 sequence starting at s[i] (s.size() > i), or 0 if invalid.
int Utf8SequenceLength(const std::string& s, size_t i) {
  auto byte = [&](size_t k) -> int { return k < s.size() ? static_cast<unsigned char>(s[k]) : -1; };
  int c = byte(i);
  if (c < 0x80) return 1;
  int n;
  int lo = 0x80, hi = 0xBF;  // Allowed range of the second byte.
  if (c >= 0xC2 && c <= 0xDF) {
    n = 2;
  } else if (c >= 0xE0 && c <= 0xEF) {
    n = 3;
    if (c == 0xE0) lo = 0xA0;  // No overlong forms.
    if (c == 0xED) hi = 0x9F;  // No surrogates.
  } else if (c >= 0xF0 && c <= 0xF4) {
    n = 4;
    if (c == 0xF0) lo = 0x90;
    if (c == 0xF4) hi = 0x8F;  // At most U+10FFFF.
  } else {
    return 0;
  }
  int b1 = byte(i + 1);
  if (b1 < lo || b1 > hi) return 0;
  for (int k = 2; k < n; ++k) {
    int b = byte(i + k);
    if (b < 0x80 || b > 0xBF) return 0;
  }
  return n;
}

}  // namespace

absl::Status CheckText(const std::string& bytes, const std::string& name) {
  const size_t limit = std::min<size_t>(bytes.size(), 64 * 1024);
  const void* nul = std::memchr(bytes.data(), '\0', limit);
  if (nul != nullptr) {
    size_t offset = static_cast<size_t>(static_cast<const char*>(nul) - bytes.data());
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": looks binary (NUL byte at offset ", offset, ")"));
  }
  // Sequences starting inside the window are checked whole, even if they end just past it.
  for (size_t i = 0; i < limit;) {
    if (static_cast<unsigned char>(bytes[i]) < 0x80) {
      ++i;
      continue;
    }
    int n = Utf8SequenceLength(bytes, i);
    if (n == 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ": looks binary (invalid UTF-8 at offset ", i, ")"));
    }
    i += static_cast<size_t>(n);
  }
  return absl::OkStatus();
}

std::vector<std::string> MaterialLibraryNames(absl::string_view rest, const std::string& dir) {
  std::vector<std::string> files;
  const std::string whole = NormaliseLibraryName(rest);
  if (FileExists(JoinPath(dir, whole))) {
    files.push_back(whole);
  } else {
    LineCursor names{rest.data(), rest.data() + rest.size()};
    while (!names.AtEndOrComment()) files.push_back(NormaliseLibraryName(names.Token()));
  }
  return files;
}

std::vector<std::string> ScanMaterialLibraries(const std::string& raw, const std::string& dir) {
  std::string decoded = raw.size() >= 2 && (raw[0] == '\xFE' || raw[0] == '\xFF') ? raw : "";
  if (!decoded.empty()) DecodeUtf16(&decoded);
  const std::string& text = decoded.empty() ? raw : decoded;
  std::vector<std::string> out;
  ForEachLine(text, [&](int, LineCursor& cursor) {
    if (cursor.Token() != "mtllib") return absl::OkStatus();
    for (std::string& name : MaterialLibraryNames(cursor.Rest(), dir))
      out.push_back(std::move(name));
    return absl::OkStatus();
  }).IgnoreError();
  return out;
}

absl::StatusOr<Scene> ParseObj(const std::string& text, const std::string& name,
                               const std::string& mtl_dir, std::vector<std::string>* warnings,
                               const ObjOptions& options) {
  ObjParser parser(name, mtl_dir, options, warnings);
  absl::StatusOr<Scene> scene = parser.Parse(text);
  if (!scene.ok()) return scene.status();
  if (absl::Status s = ValidateScene(*scene); !s.ok()) return s;
  if (absl::Status s = DropDegenerateFaces(&*scene, warnings); !s.ok()) return s;
  return scene;
}

absl::StatusOr<Scene> LoadObj(const std::string& path, std::vector<std::string>* warnings,
                              const ObjOptions& options) {
  absl::StatusOr<std::string> text = ReadWholeFile(path, "scene");
  if (!text.ok()) return text.status();
  if (absl::Status s = DecodeText(&*text, path, warnings); !s.ok()) return s;
  return ParseObj(*text, path, DirName(path), warnings, options);
}

}  // namespace radiosity
