// The size of a stored capture (mesh bounds, frames, cameras, image size), read when a job is
// created so that its resource needs are checked before it is queued (inverse::
// EstimateJobResources). Lays the capture out in a scratch folder (hard links to the blobs) and
// reads capture.json, the frame headers and the mesh (for a raw recording: recording.json, its
// frame headers and its mesh).
#pragma once

#include <filesystem>

#include "core/inverse/job_resources.h"
#include "server/service_status.h"
#include "server/store/blob_store.h"
#include "server/store/capture.h"

namespace softid::server {

// `scratch_root` is a folder of the data directory; the layout is removed before returning.
// `count_grid_nodes`: also count the nodes of the grids "auto" cells may simulate
// (CaptureExtent::candidate_grid_nodes; a signed-distance field per candidate, a fraction of a
// second each on a scanned mesh), which only a job that leaves its grid to "auto" needs.
ServiceResult<inverse::CaptureExtent> ReadCaptureExtent(const store::Capture& capture,
                                                        const store::BlobStore& blobs,
                                                        const std::filesystem::path& scratch_root,
                                                        bool count_grid_nodes);

}  // namespace softid::server
