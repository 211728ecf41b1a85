// A contact sheet of depth frames as one colour PNG, for people to look at a capture: frames in a
// grid, depth colour-mapped over the range of the shown frames, no-data pixels black.
#pragma once

#include <filesystem>
#include <vector>

#include "core/capture/depth_image.h"
#include "core/common/status.h"

namespace softid::capture {

struct DepthPreviewOptions {
  int max_frames = 12;    // frames shown, evenly spaced over the sequence, >= 1
  int columns = 4;        // >= 1
  int min_tile_px = 160;  // small frames are upscaled (nearest) to at least this width, >= 1
  Status Validate() const;
};

Status WriteDepthPreview(const std::filesystem::path& path, const std::vector<DepthImage>& frames,
                         const DepthPreviewOptions& options = {});

}  // namespace softid::capture
