// The finite-element discretisation: the active cells of a regular grid (cells where the rest
// signed distance is negative at a corner), their nodes, and cut-cell integration weights.
#pragma once

#include <Eigen/Core>
#include <array>
#include <vector>

#include "core/geometry/cut_cell_weights.h"
#include "core/geometry/regular_grid.h"
#include "core/geometry/signed_distance_field.h"

namespace softid::fem {

struct HexMesh {
  geometry::RegularGrid grid;
  // Per element (active cell):
  std::vector<int> element_cell;                  // grid cell index
  std::vector<std::array<int, 8>> element_nodes;  // FE node of corner c = dx + 2dy + 4dz
  std::vector<geometry::CutCellWeights> element_weights;
  // Per FE node:
  std::vector<int> node_grid_index;             // grid node index
  std::vector<Eigen::Vector3d> rest_positions;  // X_i [m]
  // Per grid node / grid cell: FE node / element index, or -1.
  std::vector<int> grid_node_to_node;
  std::vector<int> grid_cell_to_element;

  int NumNodes() const { return static_cast<int>(rest_positions.size()); }
  int NumElements() const { return static_cast<int>(element_cell.size()); }
  double CellSize() const { return grid.cell_size; }
  // Sum of the elements' inside volumes [m^3].
  double Volume() const;
  Eigen::Vector3d ElementCentre(int element) const;
};

// @pre sdf.phi.size() == sdf.grid.NumNodes(); min_volume_fraction in [0, 0.5).
HexMesh BuildHexMesh(const geometry::SignedDistanceField& sdf, double min_volume_fraction);

}  // namespace softid::fem
