#include "core/geometry/primitives.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/common/check.h"

namespace softid::geometry {

TriangleMesh MakeSphere(double radius, int subdivisions) {
  SOFTID_THROW_UNLESS(radius > 0.0 && std::isfinite(radius),
                      "MakeSphere: radius = " + std::to_string(radius) + ": must be positive");
  SOFTID_THROW_UNLESS(
      subdivisions >= 0 && subdivisions <= 10,
      "MakeSphere: subdivisions = " + std::to_string(subdivisions) + ": must be in [0, 10]");
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  TriangleMesh mesh;
  mesh.vertices = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                   {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  mesh.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (Eigen::Vector3d& v : mesh.vertices) v.normalize();
  for (int s = 0; s < subdivisions; ++s) {
    std::vector<Eigen::Vector3i> triangles;
    triangles.reserve(mesh.triangles.size() * 4);
    std::unordered_map<std::uint64_t, int> midpoint_of;
    auto midpoint = [&](int a, int b) {
      const std::uint64_t key = (static_cast<std::uint64_t>(std::min(a, b)) << 32) |
                                static_cast<std::uint32_t>(std::max(a, b));
      const auto [it, inserted] =
          midpoint_of.try_emplace(key, static_cast<int>(mesh.vertices.size()));
      if (inserted) {
        const Eigen::Vector3d m = (mesh.vertices[a] + mesh.vertices[b]).normalized();
        mesh.vertices.push_back(m);
      }
      return it->second;
    };
    for (const Eigen::Vector3i& tri : mesh.triangles) {
      const int m01 = midpoint(tri[0], tri[1]);
      const int m12 = midpoint(tri[1], tri[2]);
      const int m20 = midpoint(tri[2], tri[0]);
      triangles.emplace_back(tri[0], m01, m20);
      triangles.emplace_back(m01, tri[1], m12);
      triangles.emplace_back(m20, m12, tri[2]);
      triangles.emplace_back(m01, m12, m20);
    }
    mesh.triangles = std::move(triangles);
  }
  for (Eigen::Vector3d& v : mesh.vertices) v *= radius;
  return mesh;
}

TriangleMesh MakeTorus(double major_radius, double minor_radius, int major_segments,
                       int minor_segments) {
  SOFTID_THROW_UNLESS(minor_radius > 0.0 && major_radius > minor_radius,
                      "MakeTorus: radii (" + std::to_string(major_radius) + ", " +
                          std::to_string(minor_radius) + "): need major > minor > 0");
  SOFTID_THROW_UNLESS(major_segments >= 3 && minor_segments >= 3,
                      "MakeTorus: segments (" + std::to_string(major_segments) + ", " +
                          std::to_string(minor_segments) + "): need >= 3 each");
  TriangleMesh mesh;
  mesh.vertices.reserve(static_cast<std::size_t>(major_segments) * minor_segments);
  for (int i = 0; i < major_segments; ++i) {
    const double u = 2.0 * std::numbers::pi * i / major_segments;
    for (int j = 0; j < minor_segments; ++j) {
      const double v = 2.0 * std::numbers::pi * j / minor_segments;
      const double ring = major_radius + minor_radius * std::cos(v);
      mesh.vertices.emplace_back(ring * std::cos(u), ring * std::sin(u),
                                 minor_radius * std::sin(v));
    }
  }
  auto index = [&](int i, int j) {
    return (i % major_segments) * minor_segments + (j % minor_segments);
  };
  for (int i = 0; i < major_segments; ++i) {
    for (int j = 0; j < minor_segments; ++j) {
      // d/du x d/dv points outward, so (u, v) quads are counter-clockwise seen from outside.
      const int a = index(i, j), b = index(i + 1, j), c = index(i + 1, j + 1), d = index(i, j + 1);
      mesh.triangles.emplace_back(a, b, c);
      mesh.triangles.emplace_back(a, c, d);
    }
  }
  return mesh;
}

TriangleMesh MakeBox(const Eigen::Vector3d& size, double max_edge_length) {
  SOFTID_THROW_UNLESS((size.array() > 0.0).all() && size.allFinite(),
                      "MakeBox: size must be positive and finite");
  SOFTID_THROW_UNLESS(
      max_edge_length > 0.0 && std::isfinite(max_edge_length),
      "MakeBox: max_edge_length = " + std::to_string(max_edge_length) + ": must be positive");
  Eigen::Vector3i n;
  for (int a = 0; a < 3; ++a) {
    // A cell of sides size_a/n_a has a diagonal <= max_edge_length when each side <= L/sqrt(2).
    n[a] = std::max(
        1, static_cast<int>(std::ceil(size[a] * std::numbers::sqrt2 / max_edge_length - 1e-9)));
  }
  TriangleMesh mesh;
  // Lattice index of surface points; interior lattice points stay -1.
  const int sx = n.x() + 1, sy = n.y() + 1, sz = n.z() + 1;
  std::vector<int> lattice(static_cast<std::size_t>(sx) * sy * sz, -1);
  auto vertex = [&](const Eigen::Vector3i& ijk) {
    int& id = lattice[ijk.x() + sx * (ijk.y() + sy * ijk.z())];
    if (id < 0) {
      id = static_cast<int>(mesh.vertices.size());
      const Eigen::Vector3d frac = ijk.cast<double>().cwiseQuotient(n.cast<double>());
      mesh.vertices.push_back((frac - Eigen::Vector3d::Constant(0.5)).cwiseProduct(size));
    }
    return id;
  };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;  // e_u x e_v = +e_axis
    for (int side = 0; side < 2; ++side) {
      for (int i = 0; i < n[u]; ++i) {
        for (int j = 0; j < n[v]; ++j) {
          auto corner = [&](int di, int dj) {
            Eigen::Vector3i ijk;
            ijk[axis] = side * n[axis];
            ijk[u] = i + di;
            ijk[v] = j + dj;
            return vertex(ijk);
          };
          const int p00 = corner(0, 0), p10 = corner(1, 0), p11 = corner(1, 1), p01 = corner(0, 1);
          if (side == 1) {  // normal +axis: counter-clockwise in (u, v)
            mesh.triangles.emplace_back(p00, p10, p11);
            mesh.triangles.emplace_back(p00, p11, p01);
          } else {
            mesh.triangles.emplace_back(p00, p11, p10);
            mesh.triangles.emplace_back(p00, p01, p11);
          }
        }
      }
    }
  }
  return mesh;
}

}  // namespace softid::geometry
