// Real scanned meshes (holes as scanned) from ../shared/data/meshes: the simulator must find a
// plausible inside and simulate them. Skipped when the shared folder is absent.
#include <gtest/gtest.h>

#include <filesystem>

#include "core/fem/simulator.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::fem {
namespace {

void CheckScannedMesh(const char* file) {
  const std::filesystem::path path =
      std::filesystem::path(SOFTID_SHARED_DIR) / "data/meshes" / file;
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not present";
  const auto mesh = geometry::ReadTriangleMesh(path);
  ASSERT_TRUE(mesh.ok()) << mesh.status().ToString();
  PhysicalParameters p;
  p.youngs_modulus = 5e4;
  p.density = 300.0;
  const Eigen::AlignedBox3d bounds = mesh->Bounds();
  p.ground = GroundPlane{Eigen::Vector3d::UnitZ(), bounds.min().z() - 0.01};
  SimulationOptions options;
  options.time_step = 1.0 / 240.0;
  // Simulated volume within 5 % of the signed-tetrahedron volume about the centroid, at a grid
  // that resolves the dragon's limbs (30 cells along the longest side).
  options.cells_along_longest_side = 30;
  const double mesh_volume = std::abs(geometry::SignedVolume(*mesh));
  {
    Simulator fine(*mesh, p, options);
    EXPECT_NEAR(fine.hex_mesh().Volume(), mesh_volume, 0.05 * mesh_volume);
    EXPECT_NEAR(fine.total_mass(), p.density * fine.hex_mesh().Volume(), 1e-9 * fine.total_mass());
  }
  options.cells_along_longest_side = 20;
  Simulator sim(*mesh, p, options);
  // It falls 1 cm onto the floor (~11 steps) and lands without diverging.
  for (int step = 0; step < 24; ++step) ASSERT_FALSE(sim.Step().diverged) << "step " << step;
  double lowest = 1e9;
  for (const auto& x : sim.SurfacePositions()) lowest = std::min(lowest, x.z());
  // Features thinner than a cell are carried but not resolved: they may dip up to a cell.
  EXPECT_GT(lowest, p.ground->offset - sim.hex_mesh().CellSize());
}

TEST(ScannedMesh, BunnyHasPlausibleInsideAndSimulates) {
  CheckScannedMesh("stanford_bunny_res3.ply");
}
TEST(ScannedMesh, DragonHasPlausibleInsideAndSimulates) {
  CheckScannedMesh("stanford_dragon_res4.ply");
}

}  // namespace
}  // namespace softid::fem
