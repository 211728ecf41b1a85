#include "core/fem/surface_embedding.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/common/check.h"

namespace softid::fem {

namespace {

// A point exactly max_clamp_cells from the fuller element (a box whose faces sit mid-cell) is
// clamped in every frame: a turned copy of the body measures it a few 1e-13 cells off, and a
// mesh read in single precision 1e-7 of its size off.
constexpr double kClampTieCells = 1e-3;

// Elements allowed to carry points: those filled to min_volume_fraction; all of them when none
// is full enough.
std::vector<char> EligibleElements(const HexMesh& mesh, double min_volume_fraction) {
  const double h = mesh.grid.cell_size;
  const double h3 = h * h * h;
  std::vector<char> eligible(mesh.NumElements(), 1);
  if (min_volume_fraction > 0.0) {
    bool any = false;
    for (int e = 0; e < mesh.NumElements(); ++e) {
      eligible[e] = mesh.element_weights[e].volume >= min_volume_fraction * h3;
      any |= eligible[e] != 0;
    }
    if (!any) eligible.assign(mesh.NumElements(), 1);
  }
  return eligible;
}

// The eligible element of a grid cell, -1 if none.
int EligibleElementOfCell(const HexMesh& mesh, const std::vector<char>& eligible, int cell) {
  const int e = mesh.grid_cell_to_element[cell];
  return e >= 0 && eligible[e] ? e : -1;
}

// The eligible element whose centre is nearest to `point`, searching rings of cells of growing
// radius around `cell` (features thinner than a cell may have lost all their cells); -1 if none.
int NearestEligibleElement(const HexMesh& mesh, const std::vector<char>& eligible, int cell,
                           const Eigen::Vector3d& point) {
  const auto& grid = mesh.grid;
  const Eigen::Vector3i c0 = grid.CellCoords(cell);
  const int max_radius = grid.num_cells.maxCoeff();
  double best = std::numeric_limits<double>::infinity();
  int element = -1;
  for (int radius = 1; radius <= max_radius && element < 0; ++radius) {
    for (int dz = -radius; dz <= radius; ++dz) {
      for (int dy = -radius; dy <= radius; ++dy) {
        for (int dx = -radius; dx <= radius; ++dx) {
          if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != radius) continue;
          const Eigen::Vector3i c = c0 + Eigen::Vector3i(dx, dy, dz);
          if ((c.array() < 0).any() || (c.array() >= grid.num_cells.array()).any()) continue;
          const int e = EligibleElementOfCell(mesh, eligible, grid.CellIndex(c.x(), c.y(), c.z()));
          if (e < 0) continue;
          const double d = (mesh.ElementCentre(e) - point).squaredNorm();
          if (d < best) {
            best = d;
            element = e;
          }
        }
      }
    }
  }
  return element;
}

}  // namespace

SurfaceEmbedding EmbedPoints(const HexMesh& mesh, const std::vector<Eigen::Vector3d>& points,
                             bool clamp_to_element, double min_volume_fraction,
                             double max_clamp_cells) {
  SurfaceEmbedding embedding;
  const auto& grid = mesh.grid;
  const double h = grid.cell_size;
  embedding.element.reserve(points.size());
  embedding.weights.reserve(points.size());
  embedding.rest_positions = points;
  const std::vector<char> eligible = EligibleElements(mesh, min_volume_fraction);
  for (size_t p = 0; p < points.size(); ++p) {
    Eigen::Vector3d local;
    const int cell = grid.LocateCell(points[p], &local);
    int element = EligibleElementOfCell(mesh, eligible, cell);
    if (element < 0) {
      element = NearestEligibleElement(mesh, eligible, cell, points[p]);
      SOFTID_THROW_UNLESS(element >= 0, "surface point " + std::to_string(p) +
                                            " has no simulated element anywhere in the grid");
    }
    Eigen::Vector3i c = grid.CellCoords(mesh.element_cell[element]);
    local = (points[p] - grid.origin) / h - c.cast<double>();
    const int own = mesh.grid_cell_to_element[cell];
    if (clamp_to_element && own >= 0 && own != element && std::isfinite(max_clamp_cells) &&
        (local.cwiseMax(0.0).cwiseMin(1.0) - local).norm() > max_clamp_cells + kClampTieCells) {
      element = own;
      c = grid.CellCoords(mesh.element_cell[element]);
      local = (points[p] - grid.origin) / h - c.cast<double>();
    }
    if (clamp_to_element) {
      local = local.cwiseMax(0.0).cwiseMin(1.0);
      embedding.rest_positions[p] = grid.origin + h * (c.cast<double>() + local);
    }
    embedding.element.push_back(element);
    embedding.weights.push_back(geometry::TrilinearWeights(local));
  }
  return embedding;
}

}  // namespace softid::fem
