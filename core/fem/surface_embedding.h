// Points carried by the grid: each point is tied to one element and moves with the trilinear
// interpolation of that element's node displacements. Points in cells that are not elements (thin
// features below the grid resolution) use the nearest element, extrapolating its trilinear map,
// which still moves rigidly with rigid motions because the weights sum to one.
#pragma once

#include <Eigen/Core>
#include <array>
#include <limits>
#include <vector>

#include "core/fem/hex_mesh.h"

namespace softid::fem {

struct SurfaceEmbedding {
  std::vector<int> element;                     // per point
  std::vector<std::array<double, 8>> weights;   // per point, corner order of the element
  std::vector<Eigen::Vector3d> rest_positions;  // per point [m]

  int NumPoints() const { return static_cast<int>(element.size()); }
  // x_p = X_p + sum_c w_c u_c; `u` holds 3 entries per FE node.
  template <typename Vector>
  Eigen::Vector3d Interpolate(const HexMesh& mesh, const Vector& u, int point) const {
    Eigen::Vector3d value = Eigen::Vector3d::Zero();
    const auto& nodes = mesh.element_nodes[element[point]];
    for (int c = 0; c < 8; ++c) value += weights[point][c] * u.template segment<3>(3 * nodes[c]);
    return value;
  }
};

// @param clamp_to_element when true, points outside their element are moved to its nearest point
//   (local coordinates clamped to [0,1]^3; rest_positions updated accordingly), and only elements
//   at least `min_volume_fraction` full may carry points. Forces use this: a feature thinner than
//   the grid resolves then pushes on the body where the body is, not on a sliver element that it
//   would crush (a nearly massless node with negative stress stiffness) or through an
//   extrapolated lever. Rendering uses the unclamped embedding.
// @param max_clamp_cells a point whose own cell holds an element too thin to carry it is clamped
//   into the nearest eligible element only when that moves it by at most this many cells; farther,
//   its own element carries it (a box's corner cell, thin by its trilinear distance, would
//   otherwise lose its corner to the neighbour).
// @throws std::invalid_argument when the mesh has no element at all.
SurfaceEmbedding EmbedPoints(const HexMesh& mesh, const std::vector<Eigen::Vector3d>& points,
                             bool clamp_to_element = false, double min_volume_fraction = 0.0,
                             double max_clamp_cells = std::numeric_limits<double>::infinity());

}  // namespace softid::fem
