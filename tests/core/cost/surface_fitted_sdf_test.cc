#include "core/cost/surface_fitted_sdf.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "tests/core/cost/cost_test_util.h"

namespace softid::cost {
namespace {

using testing::MakeScene;
using testing::Scene;

// Random points on the surface triangles (area-uniform), not the fit's own sample points.
std::vector<Eigen::Vector3d> RandomSurfacePoints(const geometry::TriangleMesh& mesh, int count,
                                                 unsigned seed) {
  std::vector<double> areas;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    areas.push_back(0.5 * (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                              .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]])
                              .norm());
  }
  std::mt19937 rng(seed);
  std::discrete_distribution<int> pick(areas.begin(), areas.end());
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < count; ++i) {
    const Eigen::Vector3i& t = mesh.triangles[pick(rng)];
    double a = unit(rng), b = unit(rng);
    if (a + b > 1.0) a = 1.0 - a, b = 1.0 - b;
    points.push_back(mesh.vertices[t[0]] + a * (mesh.vertices[t[1]] - mesh.vertices[t[0]]) +
                     b * (mesh.vertices[t[2]] - mesh.vertices[t[0]]));
  }
  return points;
}

double RmsInterpolated(const geometry::SignedDistanceField& sdf,
                       const std::vector<Eigen::Vector3d>& points, double offset = 0.0,
                       const std::vector<Eigen::Vector3d>* normals = nullptr) {
  double sum = 0.0;
  for (size_t p = 0; p < points.size(); ++p) {
    const Eigen::Vector3d x = normals ? Eigen::Vector3d(points[p] + offset * (*normals)[p])
                                      : points[p];
    const double e = sdf.Interpolate(x) - offset;
    sum += e * e;
  }
  return std::sqrt(sum / static_cast<double>(points.size()));
}

TEST(SurfaceFitOptions, ValidateNamesFieldAndValue) {
  EXPECT_TRUE(SurfaceFitOptions().Validate().ok());
  SurfaceFitOptions options;
  options.samples_per_cell = 0;
  EXPECT_EQ(options.Validate().message(), "SurfaceFitOptions.samples_per_cell = 0: must be >= 1");
  options = SurfaceFitOptions();
  options.smoothness_weight = 0.0;
  EXPECT_EQ(options.Validate().message(),
            "SurfaceFitOptions.smoothness_weight = 0.0: must be positive and finite");
  options = SurfaceFitOptions();
  options.value_weight = -1.0;
  EXPECT_EQ(options.Validate().message(),
            "SurfaceFitOptions.value_weight = -1.0: must be finite and >= 0");
}

// Invalid options, a surface outside the grid and an SDF whose values do not match its grid throw,
// naming what is wrong.
TEST(FitSdfToSurface, RejectsBadInput) {
  const Scene scene = testing::MakeSphereScene(/*cells=*/6);
  SurfaceFitOptions options;
  options.samples_per_cell = 0;
  EXPECT_THROW(FitSdfToSurface(scene.sdf, scene.surface, options), std::invalid_argument);
  geometry::TriangleMesh moved = scene.surface;
  moved.vertices[3].x() += 10.0;
  try {
    FitSdfToSurface(scene.sdf, moved);
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("surface: vertex 3 at"), std::string::npos) << e.what();
  }
  geometry::SignedDistanceField broken = scene.sdf;
  broken.phi.pop_back();
  EXPECT_THROW(FitSdfToSurface(broken, scene.surface), std::invalid_argument);
  EXPECT_THROW(FitSdfToSurface(scene.sdf, geometry::TriangleMesh{}), std::invalid_argument);
}

struct FitCase {
  const char* name;
  bool torus;
  int cells;
};

class SurfaceFitTest : public ::testing::TestWithParam<FitCase> {};

// The interpolant of the fitted values nearly vanishes on the surface (at points the fit did not
// sample), while 0.5 h off the surface it still reads +-0.5 h as well as the sampled distances do:
// the fix moves the zero set without bending phi's slope.
TEST_P(SurfaceFitTest, ZeroSetOnSurfaceSlopeKept) {
  const FitCase& c = GetParam();
  const Scene scene = c.torus ? MakeScene(geometry::MakeTorus(0.1, 0.04, 64, 32), c.cells, 4)
                              : MakeScene(geometry::MakeSphere(0.1, 4), c.cells, 4);
  const double h = scene.h();
  SurfaceFitSummary summary;
  const geometry::SignedDistanceField fitted =
      FitSdfToSurface(scene.sdf, scene.surface, {}, &summary);
  ASSERT_EQ(fitted.phi.size(), scene.sdf.phi.size());

  const std::vector<Eigen::Vector3d> points = RandomSurfacePoints(scene.surface, 4000, 7);
  std::vector<Eigen::Vector3d> normals;
  for (const Eigen::Vector3d& p : points) {
    normals.push_back(c.torus ? testing::TorusNormal(p) : p.normalized());
  }
  const double before = RmsInterpolated(scene.sdf, points);
  const double after = RmsInterpolated(fitted, points);
  std::printf(
      "%s: %d samples, %d nodes fitted; surface rms |phi| %.4f h -> %.4f h (samples: %.4f -> "
      "%.4f h, max %.3f -> %.3f h), largest correction %.3f h\n",
      c.name, summary.num_samples, summary.num_fitted_nodes, before / h, after / h,
      summary.rms_before / h, summary.rms_after / h, summary.max_before / h,
      summary.max_after / h, summary.max_correction / h);
  // A trilinear interpolant cannot follow the facets' creases inside a cell, so ~0.01 h remains.
  EXPECT_LT(after, 0.45 * before);
  EXPECT_LT(after, 0.02 * h);
  EXPECT_NEAR(summary.rms_after, after, 0.5 * after + 1e-4 * h);  // samples see the same
  EXPECT_LT(summary.max_correction, 0.2 * h);

  for (double offset : {0.5 * h, -0.5 * h}) {
    const double sampled = RmsInterpolated(scene.sdf, points, offset, &normals);
    const double refit = RmsInterpolated(fitted, points, offset, &normals);
    std::printf("  offset %+.1f h: rms error of phi %.4f h sampled, %.4f h fitted\n", offset / h,
                sampled / h, refit / h);
    EXPECT_LT(refit, sampled);
  }
  // Nodes far from the surface keep their exact distances.
  int far = 0;
  for (size_t n = 0; n < fitted.phi.size(); ++n) {
    if (std::abs(scene.sdf.phi[n]) > 2.0 * h) {
      ++far;
      ASSERT_EQ(fitted.phi[n], scene.sdf.phi[n]) << n;
    }
  }
  EXPECT_GT(far, 0);
}

INSTANTIATE_TEST_SUITE_P(FitSdfToSurface, SurfaceFitTest,
                         ::testing::Values(FitCase{"sphere_6", false, 6},
                                           FitCase{"sphere_16", false, 16},
                                           FitCase{"torus_12", true, 12},
                                           FitCase{"torus_16", true, 16},
                                           FitCase{"torus_30", true, 30}),
                         [](const auto& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace softid::cost
