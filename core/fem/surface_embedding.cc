#include "core/fem/surface_embedding.h"

#include <limits>
#include <string>

#include "core/common/check.h"

namespace softid::fem {

SurfaceEmbedding EmbedPoints(const HexMesh& mesh, const std::vector<Eigen::Vector3d>& points) {
  SurfaceEmbedding embedding;
  const auto& grid = mesh.grid;
  const double h = grid.cell_size;
  embedding.element.reserve(points.size());
  embedding.weights.reserve(points.size());
  embedding.rest_positions = points;
  for (size_t p = 0; p < points.size(); ++p) {
    Eigen::Vector3d local;
    const int cell = grid.LocateCell(points[p], &local);
    int element = mesh.grid_cell_to_element[cell];
    if (element < 0) {
      // Nearest element centre within two rings of cells.
      const Eigen::Vector3i c0 = grid.CellCoords(cell);
      double best = std::numeric_limits<double>::infinity();
      for (int dz = -2; dz <= 2; ++dz) {
        for (int dy = -2; dy <= 2; ++dy) {
          for (int dx = -2; dx <= 2; ++dx) {
            const Eigen::Vector3i c = c0 + Eigen::Vector3i(dx, dy, dz);
            if ((c.array() < 0).any() || (c.array() >= grid.num_cells.array()).any()) continue;
            const int e = mesh.grid_cell_to_element[grid.CellIndex(c.x(), c.y(), c.z())];
            if (e < 0) continue;
            const double d = (mesh.ElementCentre(e) - points[p]).squaredNorm();
            if (d < best) {
              best = d;
              element = e;
            }
          }
        }
      }
      SOFTID_THROW_UNLESS(element >= 0, "surface point " + std::to_string(p) +
                                            " lies more than two cells from the simulated body");
    }
    const Eigen::Vector3i c = grid.CellCoords(mesh.element_cell[element]);
    local = (points[p] - grid.origin) / h - c.cast<double>();
    embedding.element.push_back(element);
    embedding.weights.push_back(geometry::TrilinearWeights(local));
  }
  return embedding;
}

}  // namespace softid::fem
