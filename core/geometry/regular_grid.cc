#include "core/geometry/regular_grid.h"

#include <algorithm>
#include <cmath>

#include "core/common/check.h"

namespace softid::geometry {

int RegularGrid::NumNodes() const {
  const Eigen::Vector3i n = NumNodesPerAxis();
  return n.x() * n.y() * n.z();
}

int RegularGrid::NumCells() const {
  return num_cells.x() * num_cells.y() * num_cells.z();
}

int RegularGrid::NodeIndex(int i, int j, int k) const {
  const Eigen::Vector3i n = NumNodesPerAxis();
  SOFTID_ASSERT(i >= 0 && j >= 0 && k >= 0 && i < n.x() && j < n.y() && k < n.z());
  return i + n.x() * (j + n.y() * k);
}

int RegularGrid::CellIndex(int i, int j, int k) const {
  SOFTID_ASSERT(i >= 0 && j >= 0 && k >= 0 && i < num_cells.x() && j < num_cells.y() &&
                k < num_cells.z());
  return i + num_cells.x() * (j + num_cells.y() * k);
}

Eigen::Vector3i RegularGrid::NodeCoords(int node) const {
  const Eigen::Vector3i n = NumNodesPerAxis();
  SOFTID_ASSERT(node >= 0 && node < NumNodes());
  return {node % n.x(), (node / n.x()) % n.y(), node / (n.x() * n.y())};
}

Eigen::Vector3i RegularGrid::CellCoords(int cell) const {
  SOFTID_ASSERT(cell >= 0 && cell < NumCells());
  return {cell % num_cells.x(), (cell / num_cells.x()) % num_cells.y(),
          cell / (num_cells.x() * num_cells.y())};
}

Eigen::Vector3d RegularGrid::NodePosition(int node) const {
  return origin + cell_size * NodeCoords(node).cast<double>();
}

std::array<int, 8> RegularGrid::CellNodes(int cell) const {
  const Eigen::Vector3i c = CellCoords(cell);
  const Eigen::Vector3i n = NumNodesPerAxis();
  const int base = NodeIndex(c.x(), c.y(), c.z());
  const int dy = n.x(), dz = n.x() * n.y();
  return {base,      base + 1,      base + dy,      base + dy + 1,
          base + dz, base + dz + 1, base + dz + dy, base + dz + dy + 1};
}

int RegularGrid::LocateCell(const Eigen::Vector3d& p, Eigen::Vector3d* local) const {
  SOFTID_DEMAND(NumCells() > 0 && cell_size > 0.0);
  const Eigen::Vector3d t = (p - origin) / cell_size;
  Eigen::Vector3i c;
  for (int a = 0; a < 3; ++a) {
    // Clamp in double first so that huge or non-finite coordinates cannot overflow the int cast.
    const double f = std::clamp(std::floor(t[a]), 0.0, static_cast<double>(num_cells[a] - 1));
    c[a] = std::isnan(f) ? 0 : static_cast<int>(f);
  }
  if (local != nullptr) *local = t - c.cast<double>();
  return CellIndex(c.x(), c.y(), c.z());
}

std::array<double, 8> TrilinearWeights(const Eigen::Vector3d& xi) {
  std::array<double, 8> w;
  for (int c = 0; c < 8; ++c) {
    const double wx = (c & 1) ? xi.x() : 1.0 - xi.x();
    const double wy = (c & 2) ? xi.y() : 1.0 - xi.y();
    const double wz = (c & 4) ? xi.z() : 1.0 - xi.z();
    w[c] = wx * wy * wz;
  }
  return w;
}

std::array<Eigen::Vector3d, 8> TrilinearGradients(const Eigen::Vector3d& xi) {
  std::array<Eigen::Vector3d, 8> g;
  for (int c = 0; c < 8; ++c) {
    const double wx = (c & 1) ? xi.x() : 1.0 - xi.x();
    const double wy = (c & 2) ? xi.y() : 1.0 - xi.y();
    const double wz = (c & 4) ? xi.z() : 1.0 - xi.z();
    const double sx = (c & 1) ? 1.0 : -1.0;
    const double sy = (c & 2) ? 1.0 : -1.0;
    const double sz = (c & 4) ? 1.0 : -1.0;
    g[c] = Eigen::Vector3d(sx * wy * wz, wx * sy * wz, wx * wy * sz);
  }
  return g;
}

}  // namespace softid::geometry
