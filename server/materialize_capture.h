// Lays a stored capture out as a capture folder (<dir>/<manifest path>) so the core reads it like
// any other: hard links to the immutable blobs when the data directory allows it (no copy of
// hundreds of frames per job), copies otherwise.
#pragma once

#include <filesystem>

#include "core/common/status.h"
#include "server/store/blob_store.h"
#include "server/store/capture.h"

namespace softid::server {

// @pre `dir` does not exist or is empty. IoError naming the file on failure; NotFound when a blob
// of the manifest is missing (a damaged data directory).
Status MaterializeCapture(const store::Capture& capture, const store::BlobStore& blobs,
                          const std::filesystem::path& dir);

}  // namespace softid::server
