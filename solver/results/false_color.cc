#include "solver/results/false_color.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "solver/geometry/vec.h"

namespace radiosity {

namespace {

// Viridis at nine evenly spaced points (matplotlib's hex values), interpolated linearly between.
constexpr std::array<std::array<uint8_t, 3>, 9> kViridis = {{{0x44, 0x01, 0x54},
                                                             {0x48, 0x28, 0x78},
                                                             {0x3e, 0x4a, 0x89},
                                                             {0x31, 0x68, 0x8e},
                                                             {0x26, 0x82, 0x8e},
                                                             {0x1f, 0x9e, 0x89},
                                                             {0x35, 0xb7, 0x79},
                                                             {0x6e, 0xce, 0x58},
                                                             {0xfd, 0xe7, 0x25}}};

// A 5 x 7 pixel font for the labels: each row's 5 bits, the leftmost column the highest bit.
struct Glyph {
  char c;
  std::array<uint8_t, 7> rows;
};
constexpr Glyph kGlyphs[] = {
    {'0', {0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E}},
    {'1', {0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E}},
    {'2', {0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F}},
    {'3', {0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E}},
    {'4', {0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02}},
    {'5', {0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E}},
    {'6', {0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E}},
    {'7', {0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08}},
    {'8', {0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E}},
    {'9', {0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C}},
    {'.', {0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C}},
    {'-', {0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00}},
    {'+', {0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00}},
    {'e', {0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E}},
    {'W', {0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A}},
    {'/', {0x01, 0x01, 0x02, 0x04, 0x08, 0x10, 0x10}},
    {'m', {0x00, 0x00, 0x1A, 0x15, 0x15, 0x15, 0x15}},
};

// The legend's unit: radiosity luminance in W per square scene unit ("W/m" and a raised "2").
constexpr char kUnit[] = "W/m";

// Labels hold at most this many characters ("-1.23e+05").
constexpr int kLabelChars = 9;

int Scale(int height) { return std::max(1, height / 256); }

void Put(Image8* image, int x, int y, const std::array<uint8_t, 3>& c) {
  if (x < 0 || y < 0 || x >= image->width || y >= image->height) return;
  const size_t i = 3 * (static_cast<size_t>(y) * image->width + x);
  image->rgb[i] = c[0];
  image->rgb[i + 1] = c[1];
  image->rgb[i + 2] = c[2];
}

void DrawText(Image8* image, int x, int y, int s, const std::string& text) {
  for (char ch : text) {
    for (const Glyph& g : kGlyphs) {
      if (g.c != ch) continue;
      for (int row = 0; row < 7; ++row) {
        for (int col = 0; col < 5; ++col) {
          if (!(g.rows[row] >> (4 - col) & 1)) continue;
          for (int dy = 0; dy < s; ++dy) {
            for (int dx = 0; dx < s; ++dx)
              Put(image, x + col * s + dx, y + row * s + dy, {255, 255, 255});
          }
        }
      }
    }
    x += 6 * s;
  }
}

std::string Label(double v) {
  std::string text = absl::StrFormat("%.3g", v);
  return text.size() <= kLabelChars ? text : absl::StrFormat("%.1e", v);
}

}  // namespace

std::string FalseColorRange::ToString() const {
  return automatic ? "auto" : absl::StrCat(min, ":", max);
}

absl::StatusOr<FalseColorRange> ParseFalseColorRange(const std::string& text,
                                                     const std::string& flag) {
  FalseColorRange range;
  if (text == "auto") {
    range.automatic = true;
    return range;
  }
  std::vector<std::string> parts = absl::StrSplit(text, ':');
  if (parts.size() != 2 || !absl::SimpleAtod(parts[0], &range.min) ||
      !absl::SimpleAtod(parts[1], &range.max) || !std::isfinite(range.min) ||
      !std::isfinite(range.max)) {
    return absl::InvalidArgumentError(
        absl::StrCat(flag, " '", text, "': expected MIN:MAX, two numbers (e.g. 0:50), or auto"));
  }
  if (!(range.min < range.max)) {
    return absl::InvalidArgumentError(absl::StrCat(flag, " '", text, "': MIN must be below MAX"));
  }
  return range;
}

std::array<uint8_t, 3> FalseColorOf(double t) {
  t = std::clamp(std::isnan(t) ? 0.0 : t, 0.0, 1.0) * (kViridis.size() - 1);
  const size_t i = std::min(static_cast<size_t>(t), kViridis.size() - 2);
  const double f = t - static_cast<double>(i);
  std::array<uint8_t, 3> c;
  for (int k = 0; k < 3; ++k) {
    c[k] = static_cast<uint8_t>(std::lround((1 - f) * kViridis[i][k] + f * kViridis[i + 1][k]));
  }
  return c;
}

int FalseColorLegendWidth(int height) {
  const int s = Scale(height);
  return s * (8 + 16 + 6 + 6 * kLabelChars + 4);
}

FalseColorRange AutoFalseColorRange(const Image& radiance) {
  std::vector<double> lit;
  const size_t pixels = static_cast<size_t>(radiance.width) * radiance.height;
  for (size_t p = 0; p < pixels && 3 * p + 2 < radiance.rgb.size(); ++p) {
    const Rgb l(radiance.rgb[3 * p], radiance.rgb[3 * p + 1], radiance.rgb[3 * p + 2]);
    const double b = kPi * l.Luminance();
    if (b > 0 && std::isfinite(b)) lit.push_back(b);
  }
  FalseColorRange range{0, 1};
  if (lit.empty()) return range;
  const size_t top = std::min(lit.size() - 1, static_cast<size_t>(0.99 * lit.size()));
  std::nth_element(lit.begin(), lit.begin() + top, lit.end());
  range.max = lit[top];
  range.min = *std::min_element(lit.begin(), lit.begin() + top + 1);
  if (!(range.max > range.min)) {
    // One value everywhere: a scale around it.
    const double v = range.max;
    range.min = v > 0 ? 0.5 * v : 0;
    range.max = v > 0 ? 1.5 * v : 1;
  }
  return range;
}

Image8 FalseColorImage(const Image& radiance, const FalseColorRange& requested) {
  const FalseColorRange range = requested.automatic ? AutoFalseColorRange(radiance) : requested;
  const int w = radiance.width, h = radiance.height, s = Scale(h);
  Image8 out;
  out.width = w + FalseColorLegendWidth(h);
  out.height = h;
  out.rgb.assign(3 * static_cast<size_t>(out.width) * h, 24);  // The legend's dark grey.
  const double span = range.max - range.min;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t i = 3 * (static_cast<size_t>(y) * w + x);
      const Rgb l(radiance.rgb[i], radiance.rgb[i + 1], radiance.rgb[i + 2]);
      const double b = kPi * l.Luminance();
      Put(&out, x, y, b > 0 ? FalseColorOf((b - range.min) / span) : std::array<uint8_t, 3>{});
    }
  }
  // The scale: min at the bottom, max at the top, between margins of 10 s; ticks and labels.
  const int bar_x = w + 8 * s, bar_w = 16 * s, top = 10 * s, bottom = h - 1 - 10 * s;
  if (bottom <= top) return out;
  for (int y = top; y <= bottom; ++y) {
    const auto c = FalseColorOf(static_cast<double>(bottom - y) / (bottom - top));
    for (int x = bar_x; x < bar_x + bar_w; ++x) Put(&out, x, y, c);
  }
  for (int k = 0; k <= 4; ++k) {
    const int y = bottom - (bottom - top) * k / 4;
    for (int x = bar_x + bar_w; x < bar_x + bar_w + 3 * s; ++x) {
      for (int dy = 0; dy < s; ++dy) Put(&out, x, y + dy, {255, 255, 255});
    }
    DrawText(&out, bar_x + bar_w + 5 * s, std::clamp(y - 3 * s, 0, h - 7 * s), s,
             Label(range.min + span * k / 4));
  }
  // The unit above the bar, clear of the top label (which starts 21 s right of the bar).
  const int unit_x = w + s, unit_y = std::max(0, top - 9 * s);
  DrawText(&out, unit_x, unit_y + 2 * s, s, kUnit);
  DrawText(&out, unit_x + 6 * s * (sizeof(kUnit) - 1), unit_y, s, "2");
  return out;
}

absl::Status WritePng8(const Image8& image, const std::string& path) {
  if (image.width <= 0 || image.height <= 0 ||
      image.rgb.size() != 3 * static_cast<size_t>(image.width) * image.height) {
    return absl::InvalidArgumentError("cannot write an empty image");
  }
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": cannot write image: ", OIIO::geterror()));
  }
  OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  if (!out->open(path, spec) || !out->write_image(OIIO::TypeDesc::UINT8, image.rgb.data()) ||
      !out->close()) {
    return absl::InternalError(absl::StrCat(path, ": cannot write image: ", out->geterror()));
  }
  return absl::OkStatus();
}

}  // namespace radiosity
