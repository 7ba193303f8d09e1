// Static files for the browser UI: maps a request target to a file under a root folder, never
// outside it (no "..", encoded or not; no symlink escapes), and names its MIME type.
#pragma once

#include <string>
#include <string_view>

#include "teachsim/base/status.h"

namespace teachsim::net {

// Decodes %XX escapes; InvalidInput on a malformed escape or an encoded NUL.
[[nodiscard]] Result<std::string> PercentDecode(std::string_view text);

// The file that `target` ("/js/app.js?v=3") names under `root` (an existing folder). "/" and
// folder targets map to index.html inside them. NotFound if the file does not exist or is not a
// regular file; InvalidInput for a target that tries to leave the root or is malformed.
[[nodiscard]] Result<std::string> ResolveStaticPath(const std::string& root, std::string_view target);

// "text/html; charset=utf-8", "text/javascript; charset=utf-8", ... ; application/octet-stream
// for extensions it does not know.
std::string_view MimeType(std::string_view path);

}  // namespace teachsim::net
