// Error texts travel to clients; where the server keeps its files does not. Core names files by
// their full path (useful on a command line); the service strips its own folders from every text
// it sends (upload staging, a job's work folder, the data directory as a catch-all) and logs the
// full text instead.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

namespace softid::server {

// `message` with every occurrence of `dir` (as given and canonical) removed: "<dir>/a/b" becomes
// "<replacement>a/b" and a bare "<dir>" becomes `replacement` without a trailing '/' (or "."
// when the replacement is empty).
std::string RedactPath(std::string message, const std::filesystem::path& dir,
                       std::string_view replacement = "");

}  // namespace softid::server
