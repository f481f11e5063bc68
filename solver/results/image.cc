#include "solver/results/image.h"

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cstdint>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/geometry/vec.h"
#include "solver/results/tone_map.h"

namespace radiosity {

namespace {

absl::Status WriteOiio(const std::string& path, const OIIO::ImageSpec& spec, OIIO::TypeDesc type,
                       const void* data) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": cannot write image: ", OIIO::geterror()));
  }
  if (!out->open(path, spec)) {
    return absl::InternalError(absl::StrCat(path, ": cannot write image: ", out->geterror()));
  }
  if (!out->write_image(type, data)) {
    std::string message = out->geterror();
    out->close();
    return absl::InternalError(absl::StrCat(path, ": cannot write image: ", message));
  }
  if (!out->close()) {
    return absl::InternalError(absl::StrCat(path, ": cannot write image: ", out->geterror()));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status WriteImage(const Image& image, const std::string& exr_path,
                        const std::string& png_path) {
  const size_t pixels = static_cast<size_t>(std::max(0, image.width)) * std::max(0, image.height);
  if (image.width <= 0 || image.height <= 0 || image.rgb.size() != 3 * pixels) {
    return absl::InvalidArgumentError(absl::StrFormat("cannot write a %dx%d image with %d values",
                                                      image.width, image.height, image.rgb.size()));
  }
  if (!exr_path.empty()) {
    OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::HALF);
    spec.attribute("oiio:ColorSpace", "Linear");
    spec.attribute("compression", "zip");
    absl::Status st = WriteOiio(exr_path, spec, OIIO::TypeDesc::FLOAT, image.rgb.data());
    if (!st.ok()) return st;
  }
  if (!png_path.empty()) {
    std::vector<float> lum(pixels);
    for (size_t i = 0; i < pixels; ++i) {
      lum[i] = static_cast<float>(
          Rgb(image.rgb[3 * i], image.rgb[3 * i + 1], image.rgb[3 * i + 2]).Luminance());
    }
    const double exposure = Exposure(&lum);
    std::vector<uint8_t> bytes(3 * pixels);
    for (size_t i = 0; i < 3 * pixels; ++i) bytes[i] = ToSrgb8(exposure * image.rgb[i]);
    OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
    spec.attribute("oiio:ColorSpace", "sRGB");
    absl::Status st = WriteOiio(png_path, spec, OIIO::TypeDesc::UINT8, bytes.data());
    if (!st.ok()) return st;
  }
  return absl::OkStatus();
}

}  // namespace radiosity
