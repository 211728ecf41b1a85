#include "server/materialize_capture.h"

#include <system_error>

namespace softid::server {

namespace fs = std::filesystem;

Status MaterializeCapture(const store::Capture& capture, const store::BlobStore& blobs,
                          const fs::path& dir) {
  for (const store::ManifestEntry& entry : capture.manifest) {
    // Paths were checked by ValidateManifest when the capture was stored: relative, no "..".
    SOFTID_ASSIGN_OR_RETURN(const fs::path blob, blobs.PathOf(entry.sha256));
    const fs::path target = dir / entry.path;
    std::error_code error;
    fs::create_directories(target.parent_path(), error);
    if (error) {
      return Status::IoError("cannot create " + target.parent_path().string() + ": " +
                             error.message());
    }
    fs::create_hard_link(blob, target, error);
    if (error) {
      error.clear();
      fs::copy_file(blob, target, fs::copy_options::overwrite_existing, error);
      if (error) {
        return Status::IoError("cannot copy " + blob.string() + " to " + target.string() + ": " +
                               error.message());
      }
    }
  }
  return Status::Ok();
}

}  // namespace softid::server
