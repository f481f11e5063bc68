// The browser preview's page and scripts (server/web/), embedded in the binary at build time by
// server/web/embed.cmake, so that the server serves them without files beside it.
#ifndef RADIOSITY_SERVER_WEB_ASSETS_H_
#define RADIOSITY_SERVER_WEB_ASSETS_H_

#include <cstddef>
#include <string_view>

namespace radiosity::service {

struct WebAsset {
  const char* data;
  size_t size;
  const char* content_type;
};

// The asset served at `path` ("/index.html", "/preview.js", ...); null when there is none.
const WebAsset* FindWebAsset(std::string_view path);

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_WEB_ASSETS_H_
