// The station's web page (client/station/web: index.html, style.css, protobuf.js and the ES modules
// app.js imports, as web.cmake lists them), compiled into the binary at build time by web.cmake, so
// the station serves it without files.
#pragma once

#include <span>
#include <string_view>

namespace stevi::station {

struct WebAsset {
  std::string_view path;  // as served: "/index.html", "/app.js", ...
  std::string_view body;  // the file's bytes, static storage
  std::string_view
      content_type;  // "text/html; charset=utf-8", "text/javascript; charset=utf-8", ...
};

// Every embedded file, in a fixed order. Defined in the generated web_assets_data.cc.
std::span<const WebAsset> WebAssets();

// The asset served at `path` (a URL path without its query: "/" and "/index.html" are the page),
// or nullptr when there is none.
const WebAsset* FindWebAsset(std::string_view path);

}  // namespace stevi::station
