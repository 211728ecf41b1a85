// Regular grid of cubic cells (the hexahedral FEM grid) and trilinear shape functions.
#pragma once

#include <Eigen/Core>
#include <array>

namespace softid::geometry {

// Regular grid of cubic cells. Node (i,j,k) sits at origin + h*(i,j,k); cell (i,j,k) spans nodes
// (i..i+1, j..j+1, k..k+1). Indices are x-fastest: i + nx*(j + ny*k).
struct RegularGrid {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // position of node (0,0,0) [m]
  double cell_size = 0.0;                            // h [m]
  Eigen::Vector3i num_cells = Eigen::Vector3i::Zero();

  Eigen::Vector3i NumNodesPerAxis() const { return num_cells + Eigen::Vector3i::Ones(); }
  int NumNodes() const;
  int NumCells() const;
  // i + nx*(j + ny*k), nx,ny = nodes per axis.
  int NodeIndex(int i, int j, int k) const;
  // i + cx*(j + cy*k), cx,cy = cells per axis.
  int CellIndex(int i, int j, int k) const;
  Eigen::Vector3i NodeCoords(int node) const;
  Eigen::Vector3i CellCoords(int cell) const;
  // origin + h * NodeCoords(node) [m].
  Eigen::Vector3d NodePosition(int node) const;
  // The 8 node indices of a cell, corner c = dx + 2*dy + 4*dz with d* in {0,1}.
  std::array<int, 8> CellNodes(int cell) const;
  // Cell containing p (clamped into the grid) and p's local coordinates in that cell (in [0,1]^3
  // when p is inside the grid). Outside the grid the local coordinates are not clamped: they fall
  // outside [0,1] and extrapolate the boundary cell. `local` may be null. @pre NumCells() > 0.
  int LocateCell(const Eigen::Vector3d& p, Eigen::Vector3d* local) const;
};

// Trilinear shape functions N_c(xi) for corner c = dx + 2dy + 4dz, xi in [0,1]^3 local coordinates.
std::array<double, 8> TrilinearWeights(const Eigen::Vector3d& xi);
// Gradients dN_c/dxi with respect to the local coordinates (divide by h for d/dx).
std::array<Eigen::Vector3d, 8> TrilinearGradients(const Eigen::Vector3d& xi);

}  // namespace softid::geometry
