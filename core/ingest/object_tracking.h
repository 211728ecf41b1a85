// Which foreground regions are the object, frame after frame: in the first frame the largest
// region and the regions within reach of it (its size); afterwards every region whose centre lies
// within reach of where the object was (its size plus the distance it can travel since), so
// noise, a person walking in the far background or a second moving thing elsewhere do not count.
#pragma once

#include <Eigen/Geometry>
#include <optional>
#include <vector>

#include "core/common/status.h"
#include "core/ingest/foreground.h"

namespace softid::ingest {

struct ObjectTrackingOptions {
  // Fastest the object moves [m/s]: bounds how far it can get between two frames.
  double max_speed_m_per_s = 10.0;
  // A region belongs to the object when its centre lies within gate_radii object radii (plus the
  // travel) of the object's last centre.
  double gate_radii = 1.5;

  Status Validate() const;
};

// The object's pixels in one frame of one camera.
struct TrackedFrame {
  bool found = false;
  std::vector<int> pixels;            // row-major pixel indices of the object's regions
  Eigen::Vector3d centre_W{0, 0, 0};  // mean of the object's points, world frame [m]
  int regions = 0;                    // regions taken as the object
  int rejected_regions = 0;           // foreground regions left out (too far from the object)
};

class ObjectTracker {
 public:
  // @param object_radius_m half the mesh's bounding-box diagonal [m], > 0.
  ObjectTracker(double object_radius_m, const ObjectTrackingOptions& options = {});

  // The object in `foreground` of a frame at `time_s` (ascending between calls), seen by a camera
  // at X_WC. Before the object was first found, the largest region and those about it are.
  TrackedFrame Track(const Foreground& foreground, const Eigen::Isometry3d& X_WC, double time_s);

 private:
  double object_radius_m_;
  ObjectTrackingOptions options_;
  std::optional<Eigen::Vector3d> last_centre_W_;
  double last_time_s_ = 0.0;
};

}  // namespace softid::ingest
