#include "core/geometry/confined_io_system.h"

#include <string_view>
#include <system_error>

namespace softid::geometry {

namespace fs = std::filesystem;

ConfinedIOSystem::ConfinedIOSystem(const fs::path& root) {
  std::error_code error;
  root_ = fs::canonical(root.empty() ? fs::path(".") : root, error);
  if (error) root_.clear();
}

bool ConfinedIOSystem::Allowed(const char* file) const {
  if (root_.empty() || file == nullptr || *file == '\0') return false;
  std::error_code error;
  const fs::path resolved = fs::weakly_canonical(fs::absolute(fs::path(file), error), error);
  if (error) return false;
  const fs::path relative = resolved.lexically_relative(root_);
  return !relative.empty() && *relative.begin() != "..";
}

bool ConfinedIOSystem::Exists(const char* file) const {
  if (!Allowed(file)) {
    refused_any_ = true;
    return false;
  }
  return DefaultIOSystem::Exists(file);
}

Assimp::IOStream* ConfinedIOSystem::Open(const char* file, const char* mode) {
  const std::string_view m = mode == nullptr ? "rb" : mode;
  const bool read_only = m == "r" || m == "rb" || m == "rt";
  if (!read_only || !Allowed(file)) {
    refused_any_ = true;
    return nullptr;
  }
  return DefaultIOSystem::Open(file, mode);
}

}  // namespace softid::geometry
