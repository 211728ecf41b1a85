// A block dropped tilted onto a frictionless floor with no damping: it rocks from corner to corner
// after it lands, a chaotic motion (the grid and time-step choices' tests).
#pragma once

#include <Eigen/Geometry>
#include <algorithm>

#include "core/fem/physical_parameters.h"
#include "core/geometry/primitives.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::inverse::testing {

// 12 x 8 x 6 cm, turned 0.17 rad about x and 0.35 rad about y, its lowest corner 4 cm above z = 0.
inline geometry::TriangleMesh TiltedBlock() {
  geometry::TriangleMesh block = geometry::MakeBox(Eigen::Vector3d(0.12, 0.08, 0.06), 0.02);
  const Eigen::Matrix3d tilt = (Eigen::AngleAxisd(0.35, Eigen::Vector3d::UnitY()) *
                                Eigen::AngleAxisd(0.17, Eigen::Vector3d::UnitX()))
                                   .toRotationMatrix();
  double lowest = 0.0;
  for (Eigen::Vector3d& v : block.vertices) {
    v = tilt * v;
    lowest = std::min(lowest, v.z());
  }
  for (Eigen::Vector3d& v : block.vertices) v.z() += 0.04 - lowest;
  return block;
}

// E 86 kPa, nu 0.35, 400 kg/m^3, gravity along -z, the floor z = 0, no damping of any kind.
inline fem::PhysicalParameters UndampedBlockOnAFloor() {
  fem::PhysicalParameters parameters;
  parameters.youngs_modulus = 86e3;
  parameters.poisson_ratio = 0.35;
  parameters.density = 400.0;
  parameters.gravity = Eigen::Vector3d(0.0, 0.0, -9.81);
  parameters.ground = fem::GroundPlane{};
  return parameters;
}

}  // namespace softid::inverse::testing
