// A picture of what the ingest saw, for a person to check it at a glance: camera 0's raw frames
// in a grid (depth in grey, near bright), the pixels taken as the object in red, the floor's
// pixels in green, and on the first frame the registered mesh's outline in yellow.
#pragma once

#include <filesystem>

#include "core/capture/pixel_rays.h"
#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"
#include "core/ingest/ingest.h"
#include "core/recording/recording.h"

namespace softid::ingest {

struct ContactSheetOptions {
  int max_frames = 12;    // frames shown, evenly spaced over the recording, >= 1
  int columns = 4;        // >= 1
  int min_tile_px = 240;  // small frames are enlarged (nearest pixel) to at least this width
  Status Validate() const;
};

// Writes the PNG for camera 0 of `recording` after `report` (its object masks, floor and
// registration), `mesh_S` being the recording's mesh in metres and `rays` camera 0's lens.
Status WriteContactSheet(const std::filesystem::path& path, const recording::Recording& recording,
                         const IngestReport& report, const geometry::TriangleMesh& mesh_S,
                         const capture::PixelRays& rays, const ContactSheetOptions& options = {});

}  // namespace softid::ingest
