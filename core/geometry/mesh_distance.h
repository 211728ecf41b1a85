// Exact closest-point queries against a triangle mesh, on an Embree BVH (rtcPointQuery).
#pragma once

#include <Eigen/Core>
#include <memory>

#include "core/common/status.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::geometry {

// Closest point of a triangle mesh to a query point.
struct ClosestPoint {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();  // on the mesh [m]
  double distance = 0.0;                            // |query - point| [m]
  int triangle = -1;                                // index into mesh.triangles
};

// Embree BVH over the triangles (float bounds) with a double-precision closest-point-on-triangle
// callback, so distances are exact to double rounding. Queries are thread-safe. Movable, not
// copyable; keeps its own copy of the mesh.
class MeshDistance {
 public:
  // InvalidArgument when the mesh has no triangles, an index out of range or a non-finite vertex;
  // Internal when Embree fails.
  static Result<MeshDistance> Create(const TriangleMesh& mesh);

  MeshDistance(MeshDistance&&) noexcept;
  MeshDistance& operator=(MeshDistance&&) noexcept;
  ~MeshDistance();

  ClosestPoint Closest(const Eigen::Vector3d& p) const;
  double Distance(const Eigen::Vector3d& p) const { return Closest(p).distance; }

 private:
  struct Impl;
  explicit MeshDistance(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// Checks that a mesh can be queried: triangles present, indices in range, finite vertices.
// Messages start with "mesh: ".
Status ValidateTriangleMesh(const TriangleMesh& mesh);

}  // namespace softid::geometry
