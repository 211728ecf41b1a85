// Writing a capture folder frame by frame, so that a long recording is never held in memory
// (WriteCapture in capture.h writes one from images in memory, through this writer).
//
// capture.json is written last, through a temporary file renamed into place, and a
// folder whose write did not finish never looks complete. The writer stages its files in a hidden
// folder inside the capture folder and moves them into place only when it finishes: an ingest
// that fails halfway leaves an earlier capture in the same folder as it was (the staging folder is
// removed when the writer is destroyed unfinished, and so is a capture folder it made).
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "core/capture/capture.h"
#include "core/capture/depth_image.h"
#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::capture {

class CaptureWriter {
 public:
  // A writer of `num_frames` (>= 1) frames per camera of `capture`'s cameras into `directory`,
  // named <camera name>/%06d.png. InvalidArgument for camera names that cannot be folder names
  // (not empty, no '/', '\\', "." or ".."), a mesh file not ending in ".obj" or num_frames < 1;
  // IoError when the folders cannot be made.
  static Result<CaptureWriter> Create(const std::filesystem::path& directory,
                                      const Capture& capture, int num_frames);
  CaptureWriter(CaptureWriter&& other) noexcept;
  CaptureWriter& operator=(CaptureWriter&&) = delete;
  CaptureWriter(const CaptureWriter&) = delete;
  // Unless Finish succeeded: removes the staging folder, and the capture folder when Create made it
  // and it is empty.
  ~CaptureWriter();

  // Writes frame `frame` of camera `camera` with the camera's depth_scale. InvalidArgument for an
  // index out of range, an image of another size than the camera's, or depths a PNG cannot store
  // (WriteDepthPng); IoError when it cannot be written. Different frames may be written from
  // different threads at once.
  Status WriteFrame(int camera, int frame, const DepthImage& image);

  // Writes the mesh, moves every frame into place and writes capture.json last. `capture` gives
  // the fields known only now (poses, floor, frame times, mass); its cameras must be Create's
  // (same names, sizes and depth scales). FailedPrecondition when a frame was not written;
  // InvalidArgument for a capture a reader would reject (CaptureFromJson's rules) or an empty
  // mesh, before anything is moved; IoError when a file cannot be written or moved.
  Status Finish(const Capture& capture, const geometry::TriangleMesh& mesh);

  int NumFrames() const { return num_frames_; }

 private:
  CaptureWriter() = default;
  std::filesystem::path directory_;
  std::filesystem::path staging_;
  Capture named_;  // Create's capture with the directory, mesh file and frame names set
  int num_frames_ = 0;
  // [camera][frame]; bytes, not std::vector<bool>'s shared bits, so that threads writing different
  // frames touch different memory.
  std::vector<std::vector<uint8_t>> written_;
  bool made_directory_ = false;  // Create made `directory_`
  bool finished_ = false;
};

}  // namespace softid::capture
