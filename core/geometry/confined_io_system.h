// An assimp file system that opens only files inside one folder. Some mesh formats refer to
// other files (glTF buffers and images, OBJ material libraries); a mesh that arrived over the
// network must not make the importer read anything outside its own upload, nor reveal whether a
// file exists elsewhere. Paths are resolved with symlinks followed before the check.
#pragma once

#include <assimp/DefaultIOSystem.h>

#include <filesystem>

namespace softid::geometry {

class ConfinedIOSystem : public Assimp::DefaultIOSystem {
 public:
  // Files are allowed when they resolve to `root` (empty: the working folder) or below it; a root
  // that does not exist allows nothing.
  explicit ConfinedIOSystem(const std::filesystem::path& root);

  bool Exists(const char* file) const override;
  // Read-only: any mode other than "r"/"rb"/"rt" is refused like a file outside the root.
  Assimp::IOStream* Open(const char* file, const char* mode = "rb") override;

  // Whether the importer asked for a file outside the root (or for writing) since construction.
  bool refused_any() const { return refused_any_; }

 private:
  bool Allowed(const char* file) const;

  std::filesystem::path root_;  // canonical; empty when the root does not exist (nothing allowed)
  mutable bool refused_any_ = false;
};

}  // namespace softid::geometry
