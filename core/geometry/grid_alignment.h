// The orientation of a hexahedral grid that best fits a body's flat faces. A grid at an angle to a
// flat face cuts it into a staircase of cut cells whose shape changes with the resolution: the
// CalculiX cube square to its 25-degree ramp moved its simulated surface 6.4 mm between 8 and 12
// cells on a world-aligned grid, and 0.4 mm on a grid turned with it (docs/benchmarks.md,
// "Independent validation").
#pragma once

#include <Eigen/Core>

#include "core/geometry/triangle_mesh.h"

namespace softid::geometry {

struct GridAlignment {
  // Columns: the grid's axes in the mesh's frame (a proper rotation). Of the 24 rotations that
  // leave a grid's axes in place, the one closest to the identity.
  Eigen::Matrix3d mesh_from_grid = Eigen::Matrix3d::Identity();
  double score = 0.0;           // AxisAlignmentScore of mesh_from_grid
  double identity_score = 0.0;  // AxisAlignmentScore of the mesh's own axes
};

// How much of the surface faces along the grid's axes: the area-weighted mean over the triangles
// of sum_a (n . e_a)^4, n the unit normal and e_a the grid's axes (the columns of mesh_from_grid).
// 1 when every face is normal to an axis (a box aligned with the grid); 0.6 for normals spread
// evenly over the sphere (a ball, in any orientation). 0 for a mesh without area.
double AxisAlignmentScore(const TriangleMesh& mesh, const Eigen::Matrix3d& mesh_from_grid);

// The rotation with the highest AxisAlignmentScore, searched globally (directions on a sphere
// lattice, turns about each) and then refined locally. Deterministic.
GridAlignment AlignGridToSurface(const TriangleMesh& mesh);

// The bounds of the mesh's vertices in a grid's frame, turned by mesh_from_grid^T about the
// origin [m] (their sizes are those of a grid laid along mesh_from_grid's columns).
Eigen::AlignedBox3d BoundsInGrid(const TriangleMesh& mesh, const Eigen::Matrix3d& mesh_from_grid);

}  // namespace softid::geometry
