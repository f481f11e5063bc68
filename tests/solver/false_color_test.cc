// False colour (solver/results/false_color.h): the scale's ends and middle are viridis's published
// colours; a uniform image maps to one colour at its place on the scale, unlit pixels are black;
// the legend runs from MIN (bottom) to MAX (top) with labels; the PNG reads back as written.
#include "solver/results/false_color.h"

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <string>

#include "solver/geometry/vec.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using Color = std::array<uint8_t, 3>;

Color At(const Image8& image, int x, int y) {
  const size_t i = 3 * (static_cast<size_t>(y) * image.width + x);
  return {image.rgb[i], image.rgb[i + 1], image.rgb[i + 2]};
}

TEST(FalseColorTest, TheScaleIsViridis) {
  // matplotlib's viridis: #440154 at 0, #26828e at 0.5, #fde725 at 1.
  EXPECT_EQ(FalseColorOf(0), (Color{0x44, 0x01, 0x54}));
  EXPECT_EQ(FalseColorOf(0.5), (Color{0x26, 0x82, 0x8e}));
  EXPECT_EQ(FalseColorOf(1), (Color{0xfd, 0xe7, 0x25}));
  EXPECT_EQ(FalseColorOf(-3), FalseColorOf(0));
  EXPECT_EQ(FalseColorOf(7), FalseColorOf(1));
  // Luminance of the scale rises monotonically (a perceptual scale's defining property).
  double last = -1;
  for (int k = 0; k <= 64; ++k) {
    const Color c = FalseColorOf(k / 64.0);
    const double y = Rgb(c[0], c[1], c[2]).Luminance();
    EXPECT_GT(y, last) << k;
    last = y;
  }
}

TEST(FalseColorTest, UniformRadiosityIsOneColourAndTheLegendSpansTheRange) {
  const int w = 64, h = 512;
  Image radiance;
  radiance.width = w;
  radiance.height = h;
  // Radiance of a grey surface of radiosity 3: L = B / pi.
  const double l = 3 / 3.14159265358979323846;
  radiance.rgb.assign(3 * w * h, static_cast<float>(l));
  for (int c = 0; c < 3; ++c) radiance.rgb[c] = 0;  // Pixel (0, 0) sees nothing.
  const FalseColorRange range{2, 4};
  const Image8 image = FalseColorImage(radiance, range);
  ASSERT_EQ(image.width, w + FalseColorLegendWidth(h));
  ASSERT_EQ(image.height, h);
  EXPECT_EQ(At(image, 0, 0), (Color{0, 0, 0}));
  const Color mid = FalseColorOf(0.5);
  for (int y = 0; y < h; y += 7) {
    for (int x = (y == 0 ? 1 : 0); x < w; x += 5) {
      const Color c = At(image, x, y);
      for (int k = 0; k < 3; ++k) ASSERT_NEAR(c[k], mid[k], 1) << x << "," << y;
    }
  }
  // The bar: the legend's column of the scale's colours, max at the top, min at the bottom.
  const int s = h / 256;
  const int bar_x = w + 8 * s + 2, top = 10 * s, bottom = h - 1 - 10 * s;
  EXPECT_EQ(At(image, bar_x, top), FalseColorOf(1));
  EXPECT_EQ(At(image, bar_x, bottom), FalseColorOf(0));
  EXPECT_EQ(At(image, bar_x, (top + bottom + 1) / 2), FalseColorOf(0.5));
  // Labels: white text beside the bar.
  int white = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = w + 30 * s; x < image.width; ++x) white += At(image, x, y) == Color{255, 255, 255};
  }
  EXPECT_GT(white, 5 * 20 * s * s) << "five labels of a few characters";
}

TEST(FalseColorTest, RangesAreParsedOrRefusedByName) {
  ASSERT_OK_AND_ASSIGN(FalseColorRange r, ParseFalseColorRange("0.5:1e3", "--false-color"));
  EXPECT_EQ(r.min, 0.5);
  EXPECT_EQ(r.max, 1000);
  for (const std::string bad : {"5", "1:1", "3:2", "a:b", "0:inf", "1:2:3", ""}) {
    absl::StatusOr<FalseColorRange> refused = ParseFalseColorRange(bad, "--false-color");
    EXPECT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument) << bad;
    EXPECT_NE(refused.status().message().find("--false-color"), std::string::npos) << bad;
  }
}

// `auto`: the range is the image's own, from its lowest lit value to the 99th percentile, so a
// small lamp in view (here 0.5 % of the pixels, 100 times brighter) does not set the top.
TEST(FalseColorTest, AutoTakesTheRangeInViewWithoutTheLamp) {
  const int w = 100, h = 256;
  Image radiance;
  radiance.width = w;
  radiance.height = h;
  radiance.rgb.assign(3 * w * h, 0.0f);
  const double pi = 3.14159265358979323846;
  // A ramp of radiosity from 1 to 5 across the columns, a black row (nothing seen) and a lamp of
  // radiosity 500 on the first 128 pixels.
  for (int y = 1; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double b = 1 + 4.0 * x / (w - 1);
      for (int c = 0; c < 3; ++c) radiance.rgb[3 * (y * w + x) + c] = static_cast<float>(b / pi);
    }
  }
  for (int p = w; p < w + 128; ++p) {
    for (int c = 0; c < 3; ++c) radiance.rgb[3 * p + c] = static_cast<float>(500 / pi);
  }
  ASSERT_OK_AND_ASSIGN(FalseColorRange parsed, ParseFalseColorRange("auto", "--false-color"));
  EXPECT_TRUE(parsed.automatic);
  const FalseColorRange r = AutoFalseColorRange(radiance);
  EXPECT_NEAR(r.min, 1, 1e-5);
  // The 99th percentile of the lit pixels: the lamp's 0.5 % lies above it, the ramp's top below.
  EXPECT_GT(r.max, 4.8);
  EXPECT_LT(r.max, 5 + 1e-5);
  // Drawn with auto, the ramp spans the scale: its ends get the scale's ends.
  const Image8 image = FalseColorImage(radiance, parsed);
  const Color low = At(image, 0, h / 2), high = At(image, w - 1, h / 2);
  const Color c0 = FalseColorOf(0), c1 = FalseColorOf((5 - r.min) / (r.max - r.min));
  for (int k = 0; k < 3; ++k) {
    EXPECT_NEAR(low[k], c0[k], 1);
    EXPECT_NEAR(high[k], c1[k], 1);
  }
  // No lit pixel: a valid range all the same.
  Image dark = radiance;
  std::fill(dark.rgb.begin(), dark.rgb.end(), 0.0f);
  const FalseColorRange d = AutoFalseColorRange(dark);
  EXPECT_LT(d.min, d.max);
}

// The unit is drawn above the bar, left of the top label: white pixels in the legend's top
// margin, between the image and the labels' column.
TEST(FalseColorTest, TheLegendCarriesTheUnit) {
  const int w = 16, h = 512, s = h / 256;
  Image radiance;
  radiance.width = w;
  radiance.height = h;
  radiance.rgb.assign(3 * w * h, 1.0f);
  const Image8 image = FalseColorImage(radiance, FalseColorRange{0, 10});
  int white = 0;
  for (int y = 0; y < 10 * s; ++y) {
    for (int x = w; x < w + 20 * s; ++x) white += At(image, x, y) == Color{255, 255, 255};
  }
  EXPECT_GT(white, 4 * 8 * s * s) << "\"W/m2\": four glyphs";
}

TEST(FalseColorTest, ThePngReadsBackAsWritten) {
  Image8 image;
  image.width = 5;
  image.height = 3;
  for (int i = 0; i < 15; ++i) {
    const Color c = FalseColorOf(i / 14.0);
    image.rgb.insert(image.rgb.end(), c.begin(), c.end());
  }
  testing::TempDir dir;
  const std::string path = dir.File("scale.png");
  ASSERT_OK(WritePng8(image, path));
  auto in = OIIO::ImageInput::open(path);
  ASSERT_TRUE(in);
  ASSERT_EQ(in->spec().width, 5);
  ASSERT_EQ(in->spec().height, 3);
  std::vector<uint8_t> read(15 * 3);
  ASSERT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, read.data()));
  EXPECT_EQ(read, image.rgb);
  EXPECT_FALSE(WritePng8(Image8{}, path).ok());
}

}  // namespace
}  // namespace radiosity
