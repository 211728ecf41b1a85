// An ingest held against the truth of a synthetic raw recording (softid-lab synth --raw writes
// truth.json with the scanner pose, the floor and the camera poses, and with --true-masks the
// object's true pixels): the numbers the ingest's accuracy is judged by.
#pragma once

#include <filesystem>
#include <string>

#include "core/common/status.h"
#include "core/ingest/ingest.h"
#include "core/recording/recording.h"

namespace softid::lab {

struct IngestAccuracy {
  // Worst intersection over union of the object's pixels with the true mask, over every camera and
  // frame, and where it happened.
  double worst_iou = 1.0;
  std::string worst_iou_camera;
  int worst_iou_frame = -1;
  // The floor in camera 0's frame against the true floor seen from there.
  double floor_angle_deg = 0.0;
  double floor_offset_m = 0.0;
  // The posed mesh against the true pose at the release, over the mesh's vertices: the distance to
  // the truly posed surface, and the distance to the same vertex with the angle between the two
  // poses. A symmetric body (a torus turned about its axis, a pillow flipped) is the same body in
  // poses its symmetry relates: the vertices and the angle are held against the true pose composed
  // with the symmetry nearest the pose found.
  double surface_rms_m = 0.0;
  double vertex_rms_m = 0.0;
  double rotation_deg = 0.0;
};

// Compares `report`, the ingest of the recording in `recording_dir`, with its truth.json (and
// truth_masks/ when present: without them worst_iou stays 1 and worst_iou_frame -1).
// InvalidArgument naming the file when truth.json is missing or has no "raw" block.
Result<IngestAccuracy> CompareIngestWithTruth(const std::filesystem::path& recording_dir,
                                              const recording::Recording& recording,
                                              const ingest::IngestReport& report);

}  // namespace softid::lab
