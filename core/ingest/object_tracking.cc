#include "core/ingest/object_tracking.h"

#include <fmt/format.h>

#include <cmath>

namespace softid::ingest {

Status ObjectTrackingOptions::Validate() const {
  if (!(max_speed_m_per_s > 0.0) || !std::isfinite(max_speed_m_per_s) || !(gate_radii > 0.0) ||
      !std::isfinite(gate_radii)) {
    return Status::InvalidArgument(
        fmt::format("max_speed_m_per_s = {}, gate_radii = {}: must be positive", max_speed_m_per_s,
                    gate_radii));
  }
  return Status::Ok();
}

ObjectTracker::ObjectTracker(double object_radius_m, const ObjectTrackingOptions& options)
    : object_radius_m_(object_radius_m), options_(options) {}

TrackedFrame ObjectTracker::Track(const Foreground& foreground, const Eigen::Isometry3d& X_WC,
                                  double time_s) {
  TrackedFrame out;
  if (foreground.regions.empty()) return out;
  // Before the object was found, the largest region stands for it, and the regions about it are
  // its parts too (a ring's far side, seen past a depth jump from its near side).
  const Eigen::Vector3d centre_W =
      last_centre_W_ ? *last_centre_W_ : X_WC * foreground.regions.front().centroid_C;
  const double travel_s = last_centre_W_ ? std::abs(time_s - last_time_s_) : 0.0;
  const double reach =
      options_.gate_radii * object_radius_m_ + options_.max_speed_m_per_s * travel_s;
  std::vector<const ForegroundRegion*> taken;
  for (const ForegroundRegion& region : foreground.regions) {
    if ((X_WC * region.centroid_C - centre_W).norm() <= reach) taken.push_back(&region);
  }
  out.rejected_regions = static_cast<int>(foreground.regions.size() - taken.size());
  if (taken.empty()) return out;
  double weight = 0.0;
  for (const ForegroundRegion* region : taken) {
    out.pixels.insert(out.pixels.end(), region->pixels.begin(), region->pixels.end());
    out.centre_W += static_cast<double>(region->pixels.size()) * (X_WC * region->centroid_C);
    weight += static_cast<double>(region->pixels.size());
  }
  out.centre_W /= weight;
  out.regions = static_cast<int>(taken.size());
  out.found = true;
  last_centre_W_ = out.centre_W;
  last_time_s_ = time_s;
  return out;
}

}  // namespace softid::ingest
