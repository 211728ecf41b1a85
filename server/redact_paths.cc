#include "server/redact_paths.h"

#include <system_error>
#include <vector>

namespace softid::server {
namespace {

void ReplaceAll(std::string& text, const std::string& from, std::string_view to) {
  if (from.empty()) return;
  for (size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size())) {
    text.replace(at, from.size(), to);
  }
}

}  // namespace

std::string RedactPath(std::string message, const std::filesystem::path& dir,
                       std::string_view replacement) {
  std::vector<std::string> spellings = {dir.lexically_normal().string()};
  std::error_code error;
  const std::filesystem::path canonical = std::filesystem::weakly_canonical(dir, error);
  if (!error) spellings.push_back(canonical.string());
  std::string bare(replacement);
  while (!bare.empty() && bare.back() == '/') bare.pop_back();
  if (bare.empty()) bare.push_back('.');
  for (std::string spelling : spellings) {
    while (spelling.size() > 1 && spelling.back() == '/') spelling.pop_back();
    if (spelling.empty() || spelling == "/" || spelling == ".") continue;
    ReplaceAll(message, spelling + "/", replacement);
    ReplaceAll(message, spelling, bare);
  }
  return message;
}

}  // namespace softid::server
