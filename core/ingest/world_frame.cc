#include "core/ingest/world_frame.h"

namespace softid::ingest {

Eigen::Isometry3d WorldFromFloor(const FloorPlane& floor) {
  const Eigen::Vector3d z = floor.normal_C.normalized();
  Eigen::Vector3d x = Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitZ().dot(z) * z;
  if (x.norm() < 1e-6) x = z.unitOrthogonal();  // looking straight down: any x
  x.normalize();
  Eigen::Matrix3d R_CW;  // columns: world axes in the camera frame
  R_CW.col(0) = x;
  R_CW.col(1) = z.cross(x);
  R_CW.col(2) = z;
  // Foot of the camera centre on the floor: p = offset * n (n . p = offset).
  const Eigen::Vector3d origin_C = floor.offset_m * z;
  Eigen::Isometry3d X_CW = Eigen::Isometry3d::Identity();
  X_CW.linear() = R_CW;
  X_CW.translation() = origin_C;
  return X_CW.inverse();
}

WorldPlane FloorInWorld(const FloorPlane& floor, const Eigen::Isometry3d& X_WC) {
  WorldPlane plane;
  plane.normal_W = X_WC.linear() * floor.normal_C;
  plane.offset_m = floor.offset_m + plane.normal_W.dot(X_WC.translation());
  return plane;
}

}  // namespace softid::ingest
