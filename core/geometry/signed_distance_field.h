// Signed distance field of a triangle mesh sampled at the nodes of a regular grid: the object
// representation of the embedded FEM (Weiss et al. CVPR 2020).
#pragma once

#include <Eigen/Core>
#include <limits>
#include <span>
#include <vector>

#include "core/common/status.h"
#include "core/geometry/regular_grid.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::geometry {

struct SignedDistanceOptions {
  int cells_along_longest_side = 20;  // resolution when cell_size == 0 [-], >= 2
  double cell_size = 0.0;             // h [m]; when > 0 it overrides cells_along_longest_side
  int padding_cells = 4;  // empty cells added on every side of the mesh bounds, >= 1 (room for
                          // the narrow band the cost needs)
  int num_threads = 0;    // worker threads; 0 = std::thread::hardware_concurrency(), >= 0
  // Per axis, a coordinate a plane of grid nodes must pass through [m]; NaN (the default): none,
  // the grid is centred on the mesh bounds. An aligned axis gets one more cell of padding on each
  // side, so that moving the nodes by up to a cell keeps padding_cells. Used to put nodes on a
  // clamp's face, which otherwise falls between nodes wherever the grid puts them.
  Eigen::Vector3d node_plane = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  // Samples per cell edge in cut cells (corners of mixed sign) [-]: 1, 2, 4 or 8. Above 1 the
  // distance is also sampled on a lattice of spacing h / n inside each cut cell, so that the
  // cell's inside region (cut_cell_weights.h) follows sharp features to h / n instead of rounding
  // them at the scale of h.
  int cut_cell_samples = 1;
  // InvalidArgument naming the field and value, e.g.
  // "SignedDistanceOptions.padding_cells = 0: must be >= 1".
  Status Validate() const;
};

struct SignedDistanceField {
  RegularGrid grid;
  std::vector<double> phi;  // per grid node [m]; negative inside
  // SignedDistanceOptions::cut_cell_samples n; above 1, every cut cell's lattice of (n + 1)^3
  // values at the cell's first node + h (i, j, k) / n, index i + (n + 1) (j + (n + 1) k), whose
  // corners are phi's values at the cell's nodes.
  int cut_cell_samples = 1;
  std::vector<int> cut_cell_lattice;  // per grid cell: its lattice's index, -1 when not cut
  std::vector<double> cut_cell_phi;   // the lattices, one after another [m]
  // The cell's lattice; empty when the cell is not cut or cut_cell_samples is 1.
  std::span<const double> CellLattice(int cell) const;
  // Trilinear interpolation of phi [m]; p outside the grid clamps to the nearest boundary point.
  double Interpolate(const Eigen::Vector3d& p) const;
};

// Grid = mesh bounds padded by padding_cells * h on every side: cell count per axis =
// ceil(extent / h) + 2 * padding, with the mesh centred in the grid. |phi| = exact distance to the
// triangles (MeshDistance: Embree BVH point query); sign = inside iff |generalised winding number|
// >= 0.5 (fast winding number, robust to holes; the absolute value also gives a consistently
// inward-oriented scan an inside). Multithreaded over nodes. InvalidArgument for an empty or
// broken mesh ("mesh: ..."), invalid options, or a grid above 2^27 nodes.
Result<SignedDistanceField> ComputeSignedDistanceField(const TriangleMesh& mesh,
                                                       const SignedDistanceOptions& options);

}  // namespace softid::geometry
