#include "core/geometry/signed_distance_field.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <span>

#include "core/geometry/cut_cell_weights.h"
#include "core/geometry/mesh_distance.h"
#include "core/geometry/primitives.h"
#include "tests/core/geometry/mesh_test_util.h"

namespace softid::geometry {
namespace {

using std::numbers::pi;

// Sum over all cells of the inside volume of {trilinear phi < 0} [m^3].
double CutCellVolume(const SignedDistanceField& field) {
  double volume = 0.0;
  for (int cell = 0; cell < field.grid.NumCells(); ++cell) {
    const std::array<int, 8> nodes = field.grid.CellNodes(cell);
    std::array<double, 8> phi;
    for (int c = 0; c < 8; ++c) phi[c] = field.phi[nodes[c]];
    volume += ComputeCutCellWeights(phi, field.grid.cell_size).volume;
  }
  return volume;
}

SignedDistanceOptions Cells(int n) {
  SignedDistanceOptions options;
  options.cells_along_longest_side = n;
  return options;
}

// Invalid options are rejected naming the field and the value.
TEST(SignedDistanceField, OptionsValidate) {
  EXPECT_TRUE(SignedDistanceOptions().Validate().ok());
  SignedDistanceOptions options;
  options.cells_along_longest_side = 1;
  EXPECT_EQ(options.Validate().message(),
            "SignedDistanceOptions.cells_along_longest_side = 1: must be >= 2");
  options = SignedDistanceOptions();
  options.padding_cells = 0;
  EXPECT_EQ(options.Validate().message(), "SignedDistanceOptions.padding_cells = 0: must be >= 1");
  options = SignedDistanceOptions();
  options.cell_size = -0.01;
  EXPECT_NE(options.Validate().message().find("SignedDistanceOptions.cell_size = -0.01"),
            std::string::npos);
  const auto result = ComputeSignedDistanceField(MakeSphere(0.1, 1), options);
  EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument);
}

// An empty mesh is an error; a huge grid is refused instead of allocated.
TEST(SignedDistanceField, RejectsEmptyMeshAndHugeGrids) {
  const auto empty = ComputeSignedDistanceField(TriangleMesh(), SignedDistanceOptions());
  EXPECT_EQ(empty.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(empty.status().message().find("mesh"), std::string::npos);
  SignedDistanceOptions options;
  options.cell_size = 1e-6;
  EXPECT_EQ(ComputeSignedDistanceField(MakeSphere(0.1, 1), options).status().code(),
            StatusCode::kInvalidArgument);
}

// The grid covers the mesh bounds plus the padding on every side with the mesh centred.
TEST(SignedDistanceField, GridLayout) {
  const TriangleMesh box = MakeBox(Eigen::Vector3d(0.2, 0.1, 0.05), 0.05);
  SignedDistanceOptions options = Cells(20);
  options.padding_cells = 3;
  const auto field = ComputeSignedDistanceField(box, options);
  ASSERT_TRUE(field.ok()) << field.status().ToString();
  const RegularGrid& grid = field->grid;
  EXPECT_DOUBLE_EQ(grid.cell_size, 0.01);
  EXPECT_EQ(grid.num_cells, Eigen::Vector3i(26, 16, 11));  // ceil(extent/h) + 6
  EXPECT_EQ(static_cast<int>(field->phi.size()), grid.NumNodes());
  const Eigen::Vector3d far_corner = grid.origin + grid.cell_size * grid.num_cells.cast<double>();
  EXPECT_TRUE((0.5 * (grid.origin + far_corner)).isZero(1e-12));
  EXPECT_LE(grid.origin.x(), -0.1 - 3 * 0.01 + 1e-12);
  EXPECT_LE(grid.origin.z(), -0.025 - 3 * 0.01 + 1e-12);
  // cell_size overrides the cell count.
  options.cell_size = 0.02;
  const auto coarse = ComputeSignedDistanceField(box, options);
  ASSERT_TRUE(coarse.ok());
  EXPECT_EQ(coarse->grid.num_cells, Eigen::Vector3i(16, 11, 9));
}

// A box read from a file in single precision measures a whole number of cells only to ~1e-7:
// 0.1 x 0.06 x 0.04 m at 15 cells is 9.0000004 cells deep. It must not gain a cell there, which
// would put both faces in the middle of cells (a cut-cell layer on each, 4 % stiffer modes on a
// thrown block): every face lies on a node plane, and every cell is whole or empty (0.987 at the
// box's edges and corners, where the distance is not trilinear).
TEST(SignedDistanceField, SinglePrecisionBoxFacesLieOnNodePlanes) {
  // Depth and height off by single precision's relative rounding (6e-8), as in a mesh file.
  const TriangleMesh box =
      MakeBox(Eigen::Vector3d(0.1, 0.06 * (1 + 6e-8), 0.04 * (1 + 6e-8)), 0.01);
  SignedDistanceOptions options = Cells(15);
  options.padding_cells = 3;
  const auto field = ComputeSignedDistanceField(box, options);
  ASSERT_TRUE(field.ok()) << field.status().ToString();
  EXPECT_EQ(field->grid.num_cells, Eigen::Vector3i(21, 15, 12));  // 15, 9 and 6 cells + 6
  const double h = field->grid.cell_size;
  for (int cell = 0; cell < field->grid.NumCells(); ++cell) {
    const std::array<int, 8> nodes = field->grid.CellNodes(cell);
    std::array<double, 8> phi;
    for (int c = 0; c < 8; ++c) phi[c] = field->phi[nodes[c]];
    const double fraction = ComputeCutCellWeights(phi, h).volume / (h * h * h);
    EXPECT_TRUE(fraction < 1e-3 || fraction > 0.98) << "cell " << cell << ": " << fraction;
  }
}

// A node plane can be asked for per axis: the grid moves by less than a cell, keeps its padding,
// and an axis left NaN stays centred.
TEST(SignedDistanceField, GridPutsNodesOnRequestedPlanes) {
  const TriangleMesh box = MakeBox(Eigen::Vector3d(0.2, 0.1, 0.05), 0.05);
  for (const int cells : {7, 12, 20, 33}) {
    SignedDistanceOptions options = Cells(cells);
    options.padding_cells = 2;
    options.node_plane.x() = -0.0817;
    const auto field = ComputeSignedDistanceField(box, options);
    ASSERT_TRUE(field.ok()) << field.status().ToString();
    const RegularGrid& grid = field->grid;
    const double h = grid.cell_size;
    const double steps = (-0.0817 - grid.origin.x()) / h;
    EXPECT_NEAR(steps, std::round(steps), 1e-9) << cells << " cells";
    const Eigen::Vector3d far_corner = grid.origin + h * grid.num_cells.cast<double>();
    EXPECT_LE(grid.origin.x(), -0.1 - 2 * h + 1e-12) << cells << " cells";
    EXPECT_GE(far_corner.x(), 0.1 + 2 * h - 1e-12) << cells << " cells";
    EXPECT_NEAR(0.5 * (grid.origin.y() + far_corner.y()), 0.0, 1e-12);
  }
  SignedDistanceOptions options;
  options.node_plane.z() = std::numeric_limits<double>::infinity();
  EXPECT_NE(options.Validate().message().find("SignedDistanceOptions.node_plane[2] = inf"),
            std::string::npos)
      << options.Validate().message();
}

// For a box the signed distance is known in closed form at every node.
TEST(SignedDistanceField, BoxMatchesAnalyticDistance) {
  const Eigen::Vector3d half(0.1, 0.05, 0.04);
  const auto field = ComputeSignedDistanceField(MakeBox(2.0 * half, 0.03), Cells(16));
  ASSERT_TRUE(field.ok());
  for (int node = 0; node < field->grid.NumNodes(); ++node) {
    const Eigen::Vector3d q = field->grid.NodePosition(node).cwiseAbs() - half;
    const double exact = q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
    ASSERT_NEAR(field->phi[node], exact, 1e-12) << field->grid.NodePosition(node).transpose();
  }
}

// Sphere: |phi| is the exact distance to the polygonal mesh and phi matches |x| - r to within
// the mesh's chord error (< 1e-3 h for the 82k-triangle icosphere).
TEST(SignedDistanceField, SphereMatchesDistance) {
  const double r = 0.1;
  const TriangleMesh sphere = MakeSphere(r, 6);
  double chord = 0.0;  // max depth of a triangle plane below the sphere
  for (const Eigen::Vector3i& t : sphere.triangles) {
    const Eigen::Vector3d n = (sphere.vertices[t[1]] - sphere.vertices[t[0]])
                                  .cross(sphere.vertices[t[2]] - sphere.vertices[t[0]])
                                  .normalized();
    chord = std::max(chord, r - std::abs(n.dot(sphere.vertices[t[0]])));
  }
  const auto field = ComputeSignedDistanceField(sphere, Cells(20));
  ASSERT_TRUE(field.ok());
  const double h = field->grid.cell_size;
  EXPECT_LT(chord, 1e-3 * h);
  const Result<MeshDistance> distance = MeshDistance::Create(sphere);
  ASSERT_TRUE(distance.ok());
  int inside = 0;
  for (int node = 0; node < field->grid.NumNodes(); ++node) {
    const Eigen::Vector3d p = field->grid.NodePosition(node);
    ASSERT_NEAR(field->phi[node], p.norm() - r, chord + 1e-12) << p.transpose();
    if (node % 7 == 0) {
      ASSERT_NEAR(std::abs(field->phi[node]), distance->Distance(p), 1e-15);
    }
    inside += field->phi[node] < 0.0;
  }
  EXPECT_GT(inside, 1000);
  // Interpolate reproduces the nodes, interpolates between them and clamps outside the grid.
  const int node = field->grid.NodeIndex(7, 9, 11);
  const Eigen::Vector3d p = field->grid.NodePosition(node);
  EXPECT_NEAR(field->Interpolate(p), field->phi[node], 1e-15);
  EXPECT_NEAR(field->Interpolate(p + Eigen::Vector3d(0.5 * h, 0, 0)),
              0.5 * (field->phi[node] + field->phi[field->grid.NodeIndex(8, 9, 11)]), 1e-15);
  EXPECT_NEAR(field->Interpolate(Eigen::Vector3d(0.3, 0.0, 0.0)),
              field->Interpolate(
                  Eigen::Vector3d(0.3, 0.0, 0.0)
                      .cwiseMin(field->grid.origin + h * field->grid.num_cells.cast<double>())),
              1e-15);
  EXPECT_NEAR(field->Interpolate(Eigen::Vector3d(5.0, 0.0, 0.0)),
              field->Interpolate(Eigen::Vector3d(0.3, 0.0, 0.0)), 1e-15);
}

// Cut-cell volumes at 20 cells along the longest side are within 2 % of sphere and torus.
TEST(SignedDistanceField, CutCellVolumeOfSphereAndTorus) {
  const double r = 0.1;
  const auto sphere = ComputeSignedDistanceField(MakeSphere(r, 5), Cells(20));
  ASSERT_TRUE(sphere.ok());
  const double ball = 4.0 / 3.0 * pi * r * r * r;
  EXPECT_NEAR(CutCellVolume(*sphere), ball, 0.02 * ball);
  // Fat enough that the tube spans ~4 cells: the trilinear interpolant of the distance loses
  // about h^2 / (6 a^2) of a tube's volume (1.2 % here).
  const double R = 0.1, a = 0.06;
  const auto torus = ComputeSignedDistanceField(MakeTorus(R, a, 128, 64), Cells(20));
  ASSERT_TRUE(torus.ok());
  const double ring = 2.0 * pi * pi * R * a * a;
  EXPECT_NEAR(CutCellVolume(*torus), ring, 0.02 * ring);
  // The hole of the torus is outside.
  EXPECT_GT(torus->Interpolate(Eigen::Vector3d::Zero()), 0.03);
  EXPECT_LT(torus->Interpolate(Eigen::Vector3d(R, 0, 0)), -0.8 * a);
}

// With cut_cell_samples, every cut cell (and only those) carries a lattice of the same distance
// as the nodes, whose corners are the nodes' values; the cut cells then describe a box's edges
// and corners closely: its volume comes out within 0.3 %, where the corners alone lose over 1 %.
TEST(SignedDistanceField, CutCellLatticesSampleTheDistanceAndKeepABoxsEdges) {
  const Eigen::Vector3d half(0.1, 0.05, 0.04);
  SignedDistanceOptions options = Cells(13);
  options.cut_cell_samples = 4;
  const auto field = ComputeSignedDistanceField(MakeBox(2.0 * half, 0.03), options);
  ASSERT_TRUE(field.ok());
  const auto exact = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3d q = p.cwiseAbs() - half;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
  };
  const double h = field->grid.cell_size;
  int cut = 0;
  double lattice_volume = 0.0;
  for (int cell = 0; cell < field->grid.NumCells(); ++cell) {
    const std::array<int, 8> nodes = field->grid.CellNodes(cell);
    int negative = 0;
    for (int node : nodes) negative += field->phi[node] < 0.0;
    const std::span<const double> lattice = field->CellLattice(cell);
    if (negative == 0 || negative == 8) {
      ASSERT_TRUE(lattice.empty()) << cell;
      if (negative == 8) lattice_volume += h * h * h;
      continue;
    }
    ++cut;
    ASSERT_EQ(lattice.size(), 125u);
    for (int c = 0; c < 8; ++c) {
      ASSERT_EQ(lattice[4 * (c & 1) + 20 * ((c >> 1) & 1) + 100 * ((c >> 2) & 1)],
                field->phi[nodes[c]]);
    }
    const Eigen::Vector3d origin = field->grid.NodePosition(nodes[0]);
    for (int index : {31, 62, 93}) {
      const Eigen::Vector3d p =
          origin + h / 4 * Eigen::Vector3d(index % 5, index / 5 % 5, index / 25);
      ASSERT_NEAR(lattice[index], exact(p), 1e-12) << p.transpose();
    }
    lattice_volume += ComputeCutCellWeights(lattice, 4, h).volume;
  }
  EXPECT_GT(cut, 100);
  const double box = 8.0 * half.prod();
  EXPECT_NEAR(lattice_volume, box, 3e-3 * box);
  EXPECT_LT(CutCellVolume(*field), (1.0 - 1e-2) * box) << CutCellVolume(*field) / box;
  options.cut_cell_samples = 3;
  EXPECT_EQ(options.Validate().message(),
            "SignedDistanceOptions.cut_cell_samples = 3: must be 1, 2, 4 or 8");
}

// A sphere with a hole still has its inside; an inward-oriented sphere gets the same field.
TEST(SignedDistanceField, RobustToHolesAndOrientation) {
  TriangleMesh sphere = MakeSphere(0.1, 4);
  const auto reference = ComputeSignedDistanceField(sphere, Cells(16));
  ASSERT_TRUE(reference.ok());
  TriangleMesh flipped = sphere;
  for (Eigen::Vector3i& t : flipped.triangles) std::swap(t[1], t[2]);
  const auto inverted = ComputeSignedDistanceField(flipped, Cells(16));
  ASSERT_TRUE(inverted.ok());
  ASSERT_EQ(inverted->phi.size(), reference->phi.size());
  for (size_t i = 0; i < reference->phi.size(); ++i) {
    ASSERT_NEAR(inverted->phi[i], reference->phi[i], 1e-15);
  }
  std::vector<Eigen::Vector3i> kept;
  for (const Eigen::Vector3i& t : sphere.triangles) {
    const Eigen::Vector3d c =
        (sphere.vertices[t[0]] + sphere.vertices[t[1]] + sphere.vertices[t[2]]) / 3.0;
    if (c.z() < 0.095) kept.push_back(t);  // cap of radius ~3 cm removed
  }
  sphere.triangles = kept;
  const auto holed = ComputeSignedDistanceField(sphere, Cells(16));
  ASSERT_TRUE(holed.ok());
  const double full = CutCellVolume(*reference);
  EXPECT_NEAR(CutCellVolume(*holed), full, 0.02 * full);
  EXPECT_LT(holed->Interpolate(Eigen::Vector3d::Zero()), -0.09);
}

// One thread and several threads give identical fields.
TEST(SignedDistanceField, ThreadCountDoesNotChangeResult) {
  const TriangleMesh torus = MakeTorus(0.1, 0.03, 32, 16);
  SignedDistanceOptions options = Cells(24);
  options.num_threads = 1;
  const auto single = ComputeSignedDistanceField(torus, options);
  options.num_threads = 3;
  const auto multi = ComputeSignedDistanceField(torus, options);
  ASSERT_TRUE(single.ok() && multi.ok());
  EXPECT_EQ(single->phi, multi->phi);
}

// Acceptance: the scanned bunny and dragon (with holes) get a plausible inside: the cut-cell
// volume at 40 cells along the longest side is within 5 % of |SignedVolume(mesh)|.
void ExpectPlausibleInside(const std::string& name) {
  const auto path = testing::SharedMesh(name);
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not available";
  const Result<TriangleMesh> mesh = ReadTriangleMesh(path);
  ASSERT_TRUE(mesh.ok()) << mesh.status().ToString();
  const auto start = std::chrono::steady_clock::now();
  const auto field = ComputeSignedDistanceField(*mesh, Cells(40));
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(field.ok()) << field.status().ToString();
  const double expected = std::abs(SignedVolume(*mesh));
  const double volume = CutCellVolume(*field);
  std::printf("%s: %zu triangles, %d nodes, SDF %.3f s, cut-cell volume %.4g m^3 vs %.4g m^3\n",
              name.c_str(), mesh->triangles.size(), field->grid.NumNodes(), seconds, volume,
              expected);
  EXPECT_NEAR(volume, expected, 0.05 * expected);
}

TEST(SignedDistanceField, ScannedBunnyHasPlausibleInside) {
  ExpectPlausibleInside("stanford_bunny_res3.ply");
}

TEST(SignedDistanceField, ScannedDragonHasPlausibleInside) {
  ExpectPlausibleInside("stanford_dragon_res4.ply");
}

}  // namespace
}  // namespace softid::geometry
