// Closest point on a triangle (Ericson, Real-Time Collision Detection, 5.1.5).
#pragma once

#include <Eigen/Core>

namespace softid::geometry {

// The point of triangle (a, b, c) closest to p [m], by Voronoi regions of the vertices, edges and
// face. Degenerate (zero-area) triangles fall back to the closest point on their edges.
Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c);

// The point of segment [a, b] closest to p [m].
Eigen::Vector3d ClosestPointOnSegment(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                      const Eigen::Vector3d& b);

}  // namespace softid::geometry
