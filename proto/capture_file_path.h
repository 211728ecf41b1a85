// The rule every CaptureFile.path of the API obeys (proto/softid/v1/softid.proto): a relative,
// '/'-separated path that cannot leave the folder it is written into. The server refuses a
// manifest that breaks it; the client refuses a download that does (it trusts no server to keep
// it). Header-only: the client-only build links no library of the server's.
#pragma once

#include <string_view>

namespace softid::api {

// True for "a/b.png"; false for "", "/a", "a//b", "./a", "a/../b", "a\\b" or a NUL anywhere.
inline bool IsSafeRelativePath(std::string_view path) {
  if (path.empty() || path.front() == '/' || path.find('\\') != std::string_view::npos ||
      path.find('\0') != std::string_view::npos) {
    return false;
  }
  size_t start = 0;
  while (start <= path.size()) {
    size_t end = path.find('/', start);
    if (end == std::string_view::npos) end = path.size();
    const std::string_view segment = path.substr(start, end - start);
    if (segment.empty() || segment == "." || segment == "..") return false;
    start = end + 1;
  }
  return true;
}

}  // namespace softid::api
