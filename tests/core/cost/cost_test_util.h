// Helpers shared by the cost tests: small embedded-FEM scenes and smooth displacement fields.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <array>
#include <cmath>
#include <vector>

#include "core/cost/displacement_extension.h"
#include "core/fem/hex_mesh.h"
#include "core/geometry/primitives.h"
#include "core/geometry/regular_grid.h"
#include "core/geometry/signed_distance_field.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::cost::testing {

struct Scene {
  geometry::TriangleMesh surface;  // rest surface [m]
  geometry::SignedDistanceField sdf;
  fem::HexMesh mesh;
  double h() const { return mesh.CellSize(); }
};

inline Scene MakeScene(const geometry::TriangleMesh& surface, int cells, int padding) {
  geometry::SignedDistanceOptions options;
  options.cells_along_longest_side = cells;
  options.padding_cells = padding;
  auto sdf = geometry::ComputeSignedDistanceField(surface, options);
  EXPECT_TRUE(sdf.ok()) << sdf.status().ToString();
  Scene scene{surface, std::move(sdf).value(), {}};
  scene.mesh = fem::BuildHexMesh(scene.sdf, /*min_volume_fraction=*/0.05);
  return scene;
}

// Torus about z: major radius 0.1 m, tube radius 0.04 m; vertices on the exact torus.
inline Scene MakeTorusScene(int cells = 20, int padding = 4) {
  return MakeScene(geometry::MakeTorus(0.1, 0.04, 64, 32), cells, padding);
}

inline Scene MakeSphereScene(int cells = 10, int padding = 4, int subdivisions = 3) {
  return MakeScene(geometry::MakeSphere(0.1, subdivisions), cells, padding);
}

// Outward unit normal of the torus above at a point near its surface.
inline Eigen::Vector3d TorusNormal(const Eigen::Vector3d& p) {
  Eigen::Vector3d ring(p.x(), p.y(), 0.0);
  ring *= 0.1 / ring.norm();
  return (p - ring).normalized();
}

// A smooth non-rigid field: u_a(X) = amplitude * sin(k_a . X + phase_a), wavelength ~0.2 m.
inline Eigen::Vector3d SmoothDisplacement(const Eigen::Vector3d& x, double amplitude) {
  const double k = 2.0 * M_PI / 0.2;
  return amplitude * Eigen::Vector3d(std::sin(k * (0.9 * x.y() + 0.4 * x.z()) + 0.3),
                                     std::sin(k * (0.7 * x.z() - 0.5 * x.x()) + 1.1),
                                     std::sin(k * (0.8 * x.x() + 0.6 * x.y()) - 0.7));
}

// The field above sampled on the FE nodes (u layout of fem::Simulator).
inline Eigen::VectorXd SampleOnNodes(const fem::HexMesh& mesh, double amplitude) {
  Eigen::VectorXd u(3 * mesh.NumNodes());
  for (int i = 0; i < mesh.NumNodes(); ++i) {
    u.segment<3>(3 * i) = SmoothDisplacement(mesh.rest_positions[i], amplitude);
  }
  return u;
}

// Where the grid's displacement carries the rest point X: X + sum_c N_c u_ext,c over the rest cell
// containing X. @pre X lies in a cell whose corners are in the extension's domain.
inline Eigen::Vector3d Deform(const geometry::RegularGrid& grid, DisplacementExtension& extension,
                              const Eigen::VectorXd& u_domain, const Eigen::Vector3d& rest) {
  Eigen::Vector3d xi;
  const int cell = grid.LocateCell(rest, &xi);
  const std::array<int, 8> nodes = grid.CellNodes(cell);
  const std::array<double, 8> w = geometry::TrilinearWeights(xi);
  Eigen::Vector3d x = rest;
  for (int c = 0; c < 8; ++c) {
    const int d = extension.domain_node(nodes[c]);
    EXPECT_GE(d, 0);
    if (d >= 0) x += w[c] * u_domain.segment<3>(3 * d);
  }
  return x;
}

}  // namespace softid::cost::testing
