#include "core/fem/hex_mesh.h"

#include "core/common/check.h"

namespace softid::fem {

double HexMesh::Volume() const {
  double volume = 0.0;
  for (const auto& w : element_weights) volume += w.volume;
  return volume;
}

Eigen::Vector3d HexMesh::ElementCentre(int element) const {
  const Eigen::Vector3i c = grid.CellCoords(element_cell[element]);
  return grid.origin + grid.cell_size * (c.cast<double>() + Eigen::Vector3d::Constant(0.5));
}

HexMesh BuildHexMesh(const geometry::SignedDistanceField& sdf, double min_volume_fraction) {
  SOFTID_DEMAND(static_cast<int>(sdf.phi.size()) == sdf.grid.NumNodes());
  HexMesh mesh;
  mesh.grid = sdf.grid;
  const double h = sdf.grid.cell_size;
  const double min_volume = min_volume_fraction * h * h * h;
  mesh.grid_cell_to_element.assign(sdf.grid.NumCells(), -1);
  mesh.grid_node_to_node.assign(sdf.grid.NumNodes(), -1);

  for (int cell = 0; cell < sdf.grid.NumCells(); ++cell) {
    const std::array<int, 8> nodes = sdf.grid.CellNodes(cell);
    std::array<double, 8> corner_phi;
    bool any_inside = false;
    for (int c = 0; c < 8; ++c) {
      corner_phi[c] = sdf.phi[nodes[c]];
      any_inside |= corner_phi[c] < 0.0;
    }
    if (!any_inside) continue;
    const std::span<const double> lattice = sdf.CellLattice(cell);
    const geometry::CutCellWeights weights =
        lattice.empty() ? geometry::ComputeCutCellWeights(corner_phi, h)
                        : geometry::ComputeCutCellWeights(lattice, sdf.cut_cell_samples, h);
    if (weights.volume <= min_volume) continue;
    std::array<int, 8> fe_nodes;
    for (int c = 0; c < 8; ++c) {
      int& fe = mesh.grid_node_to_node[nodes[c]];
      if (fe < 0) {
        fe = static_cast<int>(mesh.rest_positions.size());
        mesh.rest_positions.push_back(sdf.grid.NodePosition(nodes[c]));
        mesh.node_grid_index.push_back(nodes[c]);
      }
      fe_nodes[c] = fe;
    }
    mesh.grid_cell_to_element[cell] = static_cast<int>(mesh.element_cell.size());
    mesh.element_cell.push_back(cell);
    mesh.element_nodes.push_back(fe_nodes);
    mesh.element_weights.push_back(weights);
  }
  return mesh;
}

}  // namespace softid::fem
