// GET / and GET /app/{file}: the browser app (web/app and the client module web/src/client.js),
// built into the library by cmake/EmbedFiles.cmake, so an installed softshell-server serves it
// from any folder and offline.
#include <string_view>

#include "extensions.h"
#include "web_assets.h"

namespace softshell::http::internal {

bool app_route(const httplib::Request& req, httplib::Response& res) {
  std::string_view path = req.path;
  if (path == "/" || path == "/index.html") {
    path = "index.html";
  } else if (path.substr(0, 5) == "/app/") {
    path.remove_prefix(5);
  } else {
    return false;
  }
  for (size_t i = 0; i < kWebAssetCount; ++i) {
    const WebAsset& a = kWebAssets[i];
    if (a.path != path) continue;
    // The files change with the server's version: revalidate, keyed by the build's hash of the file.
    const std::string etag = "\"" + std::string(a.hash) + "\"";
    res.set_header("ETag", etag);
    res.set_header("Cache-Control", "no-cache");
    res.set_header("X-Content-Type-Options", "nosniff");
    if (req.get_header_value("If-None-Match") == etag) {
      res.status = 304;
      return true;
    }
    res.set_content(std::string(a.body), std::string(a.media_type));
    return true;
  }
  return false;
}

}  // namespace softshell::http::internal
