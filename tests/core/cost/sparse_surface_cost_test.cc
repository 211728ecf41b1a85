#include "core/cost/sparse_surface_cost.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <random>
#include <stdexcept>
#include <string>

#include "core/cost/trilinear_inversion.h"
#include "core/cost/tukey_loss.h"
#include "core/fem/simulator.h"
#include "tests/core/cost/cost_test_util.h"

namespace softid::cost {
namespace {

using testing::Deform;
using testing::MakeSphereScene;
using testing::MakeTorusScene;
using testing::SampleOnNodes;
using testing::Scene;
using testing::TorusNormal;

std::vector<Eigen::Vector3d> Translated(const std::vector<Eigen::Vector3d>& points,
                                        const Eigen::Vector3d& t) {
  std::vector<Eigen::Vector3d> result = points;
  for (auto& p : result) p += t;
  return result;
}

// Rest surface vertices carried by the extended displacement u (exact matches: phi_0 = 0 up to
// the trilinear interpolation of the SDF).
std::vector<Eigen::Vector3d> DeformedSurface(const Scene& scene, const Eigen::VectorXd& u,
                                             int band_cells = 3) {
  DisplacementExtension extension(scene.mesh, band_cells);
  Eigen::VectorXd u_domain;
  extension.Extend(u, &u_domain);
  std::vector<Eigen::Vector3d> points;
  for (const Eigen::Vector3d& v : scene.surface.vertices) {
    points.push_back(Deform(scene.mesh.grid, extension, u_domain, v));
  }
  return points;
}

// The same rule as SparseSurfaceCost, by a scan over every candidate cell: the reference for the
// binned search. Speed-up that cannot lose a match: x = sum_c N_c x_c with N_c >= 0 summing to 1
// lies in the convex hull of the corners, hence within their largest distance from the centroid.
std::vector<PointMatch> BruteForceMatches(const Scene& scene, const SparseSurfaceCost& cost,
                                          const Eigen::VectorXd& u,
                                          const std::vector<Eigen::Vector3d>& points) {
  DisplacementExtension extension(scene.mesh, cost.options().band_cells,
                                  cost.options().extension_mode);
  Eigen::VectorXd u_domain;
  extension.Extend(u, &u_domain);
  const geometry::RegularGrid& grid = scene.mesh.grid;
  const double phi_max = cost.truncation_distance();
  std::vector<PointMatch> matches(points.size());
  for (auto& m : matches) m.cost = TukeyLoss(phi_max, phi_max);
  for (int i = 0; i < cost.num_candidate_cells(); ++i) {
    const int cell = cost.candidate_cell(i);
    const std::array<int, 8> nodes = grid.CellNodes(cell);
    std::array<Eigen::Vector3d, 8> corners;
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int c = 0; c < 8; ++c) {
      corners[c] =
          grid.NodePosition(nodes[c]) + u_domain.segment<3>(3 * extension.domain_node(nodes[c]));
      centroid += corners[c] / 8.0;
    }
    double radius = 0.0;
    for (int c = 0; c < 8; ++c) radius = std::max(radius, (corners[c] - centroid).norm());
    radius = 1.01 * radius + 1e-6 * grid.cell_size;
    for (size_t p = 0; p < points.size(); ++p) {
      if (!((points[p] - centroid).norm() <= radius)) continue;
      const TrilinearInversion inversion = InvertTrilinearMap(corners, points[p]);
      if (!inversion.converged || (inversion.xi.array() < -1e-9).any() ||
          (inversion.xi.array() > 1.0 + 1e-9).any()) {
        continue;
      }
      const std::array<double, 8> w = geometry::TrilinearWeights(inversion.xi);
      double phi = 0.0;
      for (int c = 0; c < 8; ++c) phi += w[c] * scene.sdf.phi[nodes[c]];
      const double rho = TukeyLoss(phi, phi_max);
      PointMatch& best = matches[p];
      if (best.matched && (phi > best.phi || (phi == best.phi && cell > best.cell))) continue;
      best = {true, phi, rho, Eigen::Vector3d::Zero(), cell};
    }
  }
  return matches;
}

double Mean(const std::vector<PointMatch>& matches) {
  double sum = 0.0;
  for (const auto& m : matches) sum += m.cost;
  return sum / static_cast<double>(matches.size());
}

TEST(SurfaceCostOptions, ValidateNamesFieldAndValue) {
  EXPECT_TRUE(SurfaceCostOptions().Validate().ok());
  SurfaceCostOptions options;
  options.band_cells = 0;
  EXPECT_EQ(options.Validate().message(), "SurfaceCostOptions.band_cells = 0: must be >= 1");
  options = SurfaceCostOptions();
  options.truncation_cells = -1.5;
  EXPECT_EQ(options.Validate().message(),
            "SurfaceCostOptions.truncation_cells = -1.5: must be positive and finite");
  EXPECT_EQ(options.Validate().code(), StatusCode::kInvalidArgument);
}

// Bad options, a foreign SDF, a band cut off by the grid where the cost is not yet truncated, and
// a wrong-sized u all throw, naming what is wrong.
TEST(SparseSurfaceCost, RejectsBadInput) {
  const Scene scene = MakeSphereScene(/*cells=*/8, /*padding=*/4);
  SurfaceCostOptions options;
  options.band_cells = 0;
  try {
    SparseSurfaceCost cost(scene.mesh, scene.sdf, options);
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("SurfaceCostOptions.band_cells = 0"), std::string::npos);
  }
  geometry::SignedDistanceField shifted = scene.sdf;
  shifted.grid.origin.x() += 1e-3;
  EXPECT_THROW(SparseSurfaceCost(scene.mesh, shifted), std::invalid_argument);

  // Padding 1: the grid boundary lies about half a cell outside the mesh bounds, well inside
  // phi_max = 2 h.
  const Scene tight = MakeSphereScene(/*cells=*/8, /*padding=*/1);
  try {
    SparseSurfaceCost cost(tight.mesh, tight.sdf);
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("SurfaceCostOptions.band_cells = 3: the band is cut off"),
              std::string::npos)
        << e.what();
  }
  // ... but a small truncation fits.
  options = SurfaceCostOptions();
  options.truncation_cells = 0.25;
  EXPECT_NO_THROW(SparseSurfaceCost(tight.mesh, tight.sdf, options));

  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const std::vector<Eigen::Vector3d> points = scene.surface.vertices;
  Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * scene.mesh.NumNodes() + 3);
  EXPECT_THROW(cost.Evaluate(u, points, nullptr), std::invalid_argument);
  u = Eigen::VectorXd::Zero(3 * scene.mesh.NumNodes());
  u[5] = std::nan("");
  EXPECT_THROW(cost.Evaluate(u, points, nullptr), std::invalid_argument);
}

// The default options fit the band in the grid padding, and the cost reaches its truncated value
// before the band ends (so it is continuous).
TEST(SparseSurfaceCost, DefaultBandCoversTruncation) {
  const Scene scene = MakeTorusScene();
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  EXPECT_DOUBLE_EQ(cost.truncation_distance(), 2.0 * scene.h());
  EXPECT_GE(cost.band_edge_distance(), cost.truncation_distance());
  EXPECT_FALSE(cost.extension().clipped());
  EXPECT_GT(cost.num_candidate_cells(), scene.mesh.NumElements());
}

// u = 0, points on the rest surface: every point matches, and the cost is only the trilinear
// interpolation error of the SDF.
TEST(SparseSurfaceCost, RestSurfaceHasSmallCost) {
  const Scene scene = MakeTorusScene();
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * scene.mesh.NumNodes());
  std::vector<PointMatch> matches;
  Eigen::VectorXd gradient;
  const double c = cost.Evaluate(u, scene.surface.vertices, &gradient, &matches);
  const double phi_max = cost.truncation_distance();
  ASSERT_EQ(matches.size(), scene.surface.vertices.size());
  double worst_phi = 0.0;
  for (size_t p = 0; p < matches.size(); ++p) {
    ASSERT_TRUE(matches[p].matched) << p;
    worst_phi = std::max(worst_phi, std::abs(matches[p].phi));
    // At u = 0 the matched material point is the observed point itself.
    EXPECT_LT((matches[p].rest_position - scene.surface.vertices[p]).norm(), 1e-12);
  }
  std::printf("rest surface: C = %.3g phi_max^2, max |phi| = %.3g h\n", c / (phi_max * phi_max),
              worst_phi / scene.h());
  EXPECT_LT(c, 3e-4 * phi_max * phi_max);
  EXPECT_LT(worst_phi, 0.1 * scene.h());
  EXPECT_NEAR(c, Mean(matches), 1e-15);
  EXPECT_EQ(gradient.size(), u.size());
}

// A rigid translation of the body and of the points leaves the cost unchanged (constants are
// extended exactly), also far from the rest pose.
TEST(SparseSurfaceCost, TranslationInvariance) {
  const Scene scene = MakeTorusScene();
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(3 * scene.mesh.NumNodes());
  std::vector<PointMatch> rest_matches, moved_matches;
  const double rest = cost.Evaluate(zero, scene.surface.vertices, nullptr, &rest_matches);
  const std::vector<Eigen::Vector3d> translations = {Eigen::Vector3d(0.3, -0.2, 0.1) * scene.h(),
                                                     Eigen::Vector3d(0.35, -1.2, 0.8)};
  for (const Eigen::Vector3d& t : translations) {
    Eigen::VectorXd u(zero.size());
    for (int i = 0; i < scene.mesh.NumNodes(); ++i) u.segment<3>(3 * i) = t;
    const double moved =
        cost.Evaluate(u, Translated(scene.surface.vertices, t), nullptr, &moved_matches);
    EXPECT_NEAR(moved, rest, 1e-9 * rest) << t.transpose();
    for (size_t p = 0; p < rest_matches.size(); ++p) {
      ASSERT_TRUE(moved_matches[p].matched);
      EXPECT_NEAR(moved_matches[p].phi, rest_matches[p].phi, 1e-9 * scene.h());
    }
  }
}

// Points offset along the outward normal by 0.5 h measure phi = 0.5 h up to the trilinear
// interpolation error of the SDF; inward offsets measure -0.5 h. At u = 0 every point is its own
// material point, so the cost is exactly the mean of rho(trilinearly interpolated phi_0).
TEST(SparseSurfaceCost, NormalOffsetMeasuresDistance) {
  const Scene scene = MakeTorusScene();
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const double h = scene.h(), phi_max = cost.truncation_distance();
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * scene.mesh.NumNodes());
  for (double offset : {0.5 * h, -0.5 * h}) {
    std::vector<Eigen::Vector3d> points;
    double interpolated = 0.0;
    for (const auto& v : scene.surface.vertices) {
      points.push_back(v + offset * TorusNormal(v));
      interpolated += TukeyLoss(scene.sdf.Interpolate(points.back()), phi_max);
    }
    interpolated /= static_cast<double>(points.size());
    std::vector<PointMatch> matches;
    const double c = cost.Evaluate(u, points, nullptr, &matches);
    const double expected = TukeyLoss(offset, phi_max);
    std::printf("offset %+.1f h: C = %.4g, rho(offset) = %.4g\n", offset / h, c, expected);
    EXPECT_NEAR(c, interpolated, 1e-12 * c);
    // The distance function is convex outside the (locally convex) tube and concave inside, so
    // linear interpolation overestimates phi on both sides: ~+10 % / -15 % in rho at h = r / 2.9.
    EXPECT_NEAR(c, expected, 0.2 * expected) << offset;
    for (const auto& m : matches) {
      ASSERT_TRUE(m.matched);
      EXPECT_NEAR(m.phi, offset, 0.1 * h);
    }
  }
}

// Points that match nothing (outside the band, or not finite) cost exactly phi_max^2 / 6 and have
// no gradient; matched points beyond phi_max cost the same and have no gradient either.
TEST(SparseSurfaceCost, OutliersCostTruncatedValue) {
  const Scene scene = MakeTorusScene();
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const double h = scene.h(), phi_max = cost.truncation_distance();
  const double truncated = phi_max * phi_max / 6.0;
  const Eigen::VectorXd u = 0.2 * SampleOnNodes(scene.mesh, h);

  const std::vector<Eigen::Vector3d> far = {
      Eigen::Vector3d(1.0, 2.0, 3.0), Eigen::Vector3d(0.0, 0.0, 0.3),
      Eigen::Vector3d(0.0, 0.0, 0.5), Eigen::Vector3d(-5.0, 0.1, 0.0),
      Eigen::Vector3d(std::nan(""), 0.0, 0.0)};
  Eigen::VectorXd gradient;
  std::vector<PointMatch> matches;
  EXPECT_EQ(cost.Evaluate(u, far, &gradient, &matches), truncated);
  EXPECT_EQ(gradient.size(), u.size());
  EXPECT_EQ(gradient.norm(), 0.0);
  for (const auto& m : matches) {
    EXPECT_FALSE(m.matched);
    EXPECT_EQ(m.cost, truncated);
    EXPECT_EQ(m.cell, -1);
  }

  // In the band but beyond phi_max (2.5 h outside the top of the tube): matched, truncated.
  const std::vector<Eigen::Vector3d> band = {Eigen::Vector3d(0.1, 0.0, 0.04 + 2.5 * h),
                                             Eigen::Vector3d(0.0, -0.1, -0.04 - 2.5 * h)};
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(u.size());
  EXPECT_EQ(cost.Evaluate(zero, band, &gradient, &matches), truncated);
  EXPECT_EQ(gradient.norm(), 0.0);
  for (const auto& m : matches) {
    EXPECT_TRUE(m.matched);
    EXPECT_GT(m.phi, phi_max);
  }

  // Mixed with inliers: outliers add exactly their constant share.
  const std::vector<Eigen::Vector3d> inliers = DeformedSurface(scene, u);
  std::vector<Eigen::Vector3d> mixed = inliers;
  mixed.insert(mixed.end(), far.begin(), far.end());
  Eigen::VectorXd inlier_gradient;
  const double c_in = cost.Evaluate(u, inliers, &inlier_gradient);
  const double c_mixed = cost.Evaluate(u, mixed, &gradient);
  const double n_in = static_cast<double>(inliers.size()), n = static_cast<double>(mixed.size());
  EXPECT_NEAR(c_mixed, (c_in * n_in + truncated * static_cast<double>(far.size())) / n, 1e-15);
  EXPECT_LT((gradient - inlier_gradient * (n_in / n)).norm(), 1e-12 * gradient.norm());
}

// No points: C = 0 and a zero gradient of the right size.
TEST(SparseSurfaceCost, EmptyPointSet) {
  const Scene scene = MakeSphereScene();
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const Eigen::VectorXd u = SampleOnNodes(scene.mesh, 0.3 * scene.h());
  Eigen::VectorXd gradient = Eigen::VectorXd::Ones(7);
  std::vector<PointMatch> matches(3);
  EXPECT_EQ(cost.Evaluate(u, {}, &gradient, &matches), 0.0);
  EXPECT_EQ(gradient.size(), u.size());
  EXPECT_EQ(gradient.norm(), 0.0);
  EXPECT_TRUE(matches.empty());
}

// Dropping a random half of the points (depth dropout) barely changes the per-point mean cost, for
// exact matches of a deformed body and for points offset from it.
TEST(SparseSurfaceCost, DropoutKeepsCost) {
  const Scene scene = MakeTorusScene();
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const double h = scene.h(), phi_max = cost.truncation_distance();
  const Eigen::VectorXd u = SampleOnNodes(scene.mesh, 0.3 * h);
  const std::vector<Eigen::Vector3d> exact = DeformedSurface(scene, u);
  std::mt19937 rng(5);
  for (double offset : {0.0, 0.5 * h}) {
    // Offset along the deformed surface is not available directly; offset the rest point along the
    // torus normal and carry it with u instead (same material-space distance to first order).
    std::vector<Eigen::Vector3d> points = exact;
    if (offset != 0.0) {
      Scene moved = scene;
      for (auto& v : moved.surface.vertices) v += offset * TorusNormal(v);
      points = DeformedSurface(moved, u);
    }
    std::vector<Eigen::Vector3d> half;
    std::bernoulli_distribution keep(0.5);
    for (const auto& p : points) {
      if (keep(rng)) half.push_back(p);
    }
    const double full = cost.Evaluate(u, points, nullptr);
    const double kept = cost.Evaluate(u, half, nullptr);
    std::printf("dropout, offset %.1f h: full %.4g, half %.4g phi_max^2\n", offset / h,
                full / (phi_max * phi_max), kept / (phi_max * phi_max));
    if (offset == 0.0) {
      EXPECT_LT(full, 3e-4 * phi_max * phi_max);
      EXPECT_LT(kept, 3e-4 * phi_max * phi_max);
    } else {
      EXPECT_NEAR(full, TukeyLoss(offset, phi_max), 0.2 * TukeyLoss(offset, phi_max));
    }
    EXPECT_NEAR(kept, full, 0.1 * full + 1e-6 * phi_max * phi_max);
  }
}

// The gradient equals central finite differences of Evaluate with respect to every entry of u, for
// a non-rigid displacement and noisy points with outliers and truncated points.
// (A coarse grid keeps the 2 x (number of dofs) evaluations quick.)
void ExpectGradientMatchesFiniteDifferences(const Scene& scene, SparseSurfaceCost& cost,
                                            const char* label) {
  const double h = scene.h();
  const Eigen::VectorXd u = SampleOnNodes(scene.mesh, 0.3 * h);
  std::vector<Eigen::Vector3d> points = DeformedSurface(scene, u);
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 0.3 * h);
  for (auto& p : points) p += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
  // Points near the truncation (|phi| ~ 1.2 .. 2.4 h) and outliers.
  for (int i = 0; i < 60; ++i) {
    const Eigen::Vector3d& v = scene.surface.vertices[7 * i];
    points.push_back(v + (1.2 + 0.02 * i) * h * v.normalized());
  }
  points.push_back(Eigen::Vector3d(1.0, 1.0, 1.0));

  // A point within round-off of a face shared by two cells switches cells under the FD step, and
  // phi is only C^0 across faces (its normal derivative jumps): drop such points (none expected
  // with random noise, but the check makes the comparison well posed).
  std::vector<PointMatch> matches;
  cost.Evaluate(u, points, nullptr, &matches);
  std::vector<Eigen::Vector3d> kept;
  int matched = 0, truncated = 0;
  for (size_t p = 0; p < points.size(); ++p) {
    if (matches[p].matched) {
      const Eigen::Vector3d xi = (matches[p].rest_position - scene.mesh.grid.origin) / h -
                                 scene.mesh.grid.CellCoords(matches[p].cell).cast<double>();
      if ((xi.array() < 1e-6).any() || (xi.array() > 1.0 - 1e-6).any()) continue;
      ++matched;
      truncated += std::abs(matches[p].phi) >= cost.truncation_distance();
    }
    kept.push_back(points[p]);
  }
  ASSERT_GT(matched, 500);
  EXPECT_GT(truncated, 5);

  Eigen::VectorXd gradient;
  cost.Evaluate(u, kept, &gradient);
  const double step = 1e-7 * h;
  Eigen::VectorXd fd(u.size());
  Eigen::VectorXd perturbed = u;
  for (int k = 0; k < u.size(); ++k) {
    perturbed[k] = u[k] + step;
    const double plus = cost.Evaluate(perturbed, kept, nullptr);
    perturbed[k] = u[k] - step;
    const double minus = cost.Evaluate(perturbed, kept, nullptr);
    perturbed[k] = u[k];
    fd[k] = (plus - minus) / (2.0 * step);
  }
  const double error = (gradient - fd).norm() / gradient.norm();
  std::printf("gradient vs FD (%s): %d dofs, %zu points, relative error %.2e\n", label,
              static_cast<int>(u.size()), kept.size(), error);
  EXPECT_LT(error, 1e-5);
  EXPECT_GT(gradient.norm(), 0.0);
}

class GradientTest : public ::testing::TestWithParam<ExtensionMode> {};

TEST_P(GradientTest, MatchesFiniteDifferences) {
  const Scene scene = MakeSphereScene(/*cells=*/6, /*padding=*/4, /*subdivisions=*/3);
  SurfaceCostOptions options;
  options.extension_mode = GetParam();
  SparseSurfaceCost cost(scene.mesh, scene.sdf, options);
  ExpectGradientMatchesFiniteDifferences(scene, cost, ToString(GetParam()));
}

// The same with surface-fitted rest SDF values: the gradient interpolates the values the cost
// interpolates.
TEST(SparseSurfaceCost, SurfaceFittedGradientMatchesFiniteDifferences) {
  const Scene scene = MakeSphereScene(/*cells=*/6, /*padding=*/4, /*subdivisions=*/3);
  SparseSurfaceCost cost(scene.mesh, scene.sdf, scene.surface);
  ASSERT_GT(cost.surface_fit_summary().num_fitted_nodes, 0);
  ExpectGradientMatchesFiniteDifferences(scene, cost, "surface-fitted values");
}

// With the exact rest distance too; its gradient d phi / d X is the unit vector from the closest
// surface point.
TEST(SparseSurfaceCost, ExactGradientMatchesFiniteDifferences) {
  const Scene scene = MakeSphereScene(/*cells=*/6, /*padding=*/4, /*subdivisions=*/3);
  SurfaceCostOptions options;
  options.rest_sdf = RestSdf::kExact;
  SparseSurfaceCost cost(scene.mesh, scene.sdf, scene.surface, options);
  ExpectGradientMatchesFiniteDifferences(scene, cost, "exact rest distance");
}

// The exact mode measures signed distances: points 0.5 h outside and inside the torus read
// +-0.5 h (to the facets' deviation from the smooth torus), with the right sign everywhere.
TEST(SparseSurfaceCost, ExactModeMeasuresSignedDistance) {
  const Scene scene = MakeTorusScene(/*cells=*/16, /*padding=*/4);
  const double h = scene.h();
  SurfaceCostOptions options;
  options.rest_sdf = RestSdf::kExact;
  SparseSurfaceCost cost(scene.mesh, scene.sdf, scene.surface, options);
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(3 * scene.mesh.NumNodes());
  for (double offset : {0.1 * h, 0.5 * h, -0.1 * h, -0.5 * h, 1.5 * h}) {
    std::vector<Eigen::Vector3d> points;
    for (const auto& v : scene.surface.vertices) points.push_back(v + offset * TorusNormal(v));
    std::vector<PointMatch> matches;
    cost.Evaluate(zero, points, nullptr, &matches);
    double worst = 0.0;
    for (const PointMatch& m : matches) {
      ASSERT_TRUE(m.matched);
      worst = std::max(worst, std::abs(m.phi - offset));
    }
    EXPECT_LT(worst, 0.01 * h) << offset / h;
  }
}

// The cost floor at the true state: points on the rest surface carried by a smooth deformation
// (where observations of a correct simulation lie) cost far less with surface-fitted values than
// with the sampled distances, at rest and deformed, and points 0.5 h off the surface still cost
// about rho(0.5 h).
TEST(SparseSurfaceCost, SurfaceFittedValuesLowerTheFloor) {
  const Scene scene = MakeTorusScene(/*cells=*/16, /*padding=*/4);
  const double h = scene.h();
  SparseSurfaceCost sampled(scene.mesh, scene.sdf);
  SparseSurfaceCost fitted(scene.mesh, scene.sdf, scene.surface);
  SurfaceCostOptions exact_options;
  exact_options.rest_sdf = RestSdf::kExact;
  SparseSurfaceCost exact(scene.mesh, scene.sdf, scene.surface, exact_options);
  SurfaceCostOptions sampled_options;
  sampled_options.rest_sdf = RestSdf::kSampled;
  SparseSurfaceCost sampled_with_surface(scene.mesh, scene.sdf, scene.surface, sampled_options);
  EXPECT_EQ(sampled_with_surface.rest_sdf().phi, scene.sdf.phi);
  EXPECT_EQ(sampled_with_surface.surface_fit_summary().num_fitted_nodes, 0);
  EXPECT_NE(fitted.rest_sdf().phi, scene.sdf.phi);

  // Points the fit did not sample: the vertices of a finer tessellation of the same torus lie on
  // the curved torus, off the fitted polygonal surface by up to 0.3 mm (~0.02 h), so use the mesh's
  // own edge midpoints instead (on the polygonal surface, between the fit's samples).
  std::vector<Eigen::Vector3d> rest_points;
  for (const Eigen::Vector3i& t : scene.surface.triangles) {
    rest_points.push_back(0.5 * (scene.surface.vertices[t[0]] + scene.surface.vertices[t[1]]));
  }
  const double phi_max = fitted.truncation_distance();
  for (double amplitude : {0.0, 0.3 * h}) {
    const Eigen::VectorXd u = SampleOnNodes(scene.mesh, amplitude);
    Scene moved = scene;
    moved.surface.vertices = rest_points;
    const std::vector<Eigen::Vector3d> points = DeformedSurface(moved, u);
    std::vector<PointMatch> matches;
    const double before = sampled.Evaluate(u, points, nullptr);
    const double after = fitted.Evaluate(u, points, nullptr, &matches);
    double worst = 0.0;
    for (const PointMatch& m : matches) {
      ASSERT_TRUE(m.matched);
      worst = std::max(worst, std::abs(m.phi));
    }
    std::printf(
        "torus 16 cells, deformation %.1f h: floor C = %.3g phi_max^2 sampled, %.3g "
        "surface-fitted (max |phi| %.4f h)\n",
        amplitude / h, before / (phi_max * phi_max), after / (phi_max * phi_max), worst / h);
    EXPECT_LT(after, 0.25 * before);
    EXPECT_LT(worst, 0.06 * h);
    // The exact distance leaves only Newton's tolerance: the points are exact images of X.
    const double exact_floor = exact.Evaluate(u, points, nullptr);
    std::printf("  exact rest distance: floor C = %.3g phi_max^2\n",
                exact_floor / (phi_max * phi_max));
    EXPECT_LT(exact_floor, 1e-6 * before);
  }
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(3 * scene.mesh.NumNodes());
  for (double offset : {0.5 * h, -0.5 * h}) {
    std::vector<Eigen::Vector3d> points;
    for (const auto& v : scene.surface.vertices) points.push_back(v + offset * TorusNormal(v));
    const double expected = TukeyLoss(offset, phi_max);
    EXPECT_NEAR(fitted.Evaluate(zero, points, nullptr), expected, 0.2 * expected) << offset;
  }
}

INSTANTIATE_TEST_SUITE_P(SparseSurfaceCost, GradientTest,
                         ::testing::Values(ExtensionMode::kHarmonic,
                                           ExtensionMode::kAffinePlusHarmonic),
                         [](const auto& info) {
                           return info.param == ExtensionMode::kHarmonic ? "Harmonic"
                                                                         : "AffinePlusHarmonic";
                         });

// A rigidly rotated body seen by rotated points: with kAffinePlusHarmonic the cost equals the
// unrotated one (the whole band turns rigidly); the plain harmonic extension distorts the band of a
// rotated body, so points off the surface read a wrong phi or fall out of the band.
TEST(SparseSurfaceCost, RotatedBodyNeedsAffineExtension) {
  const Scene scene = MakeTorusScene();
  const double h = scene.h();
  std::vector<Eigen::Vector3d> rest_points;
  for (const auto& v : scene.surface.vertices) rest_points.push_back(v + 0.5 * h * TorusNormal(v));
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(3 * scene.mesh.NumNodes());
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d(1.0, 0.3, 0.0).normalized()).toRotationMatrix();
  const Eigen::Vector3d shift(0.02, -0.5, 0.1);
  Eigen::VectorXd u(zero.size());
  for (int i = 0; i < scene.mesh.NumNodes(); ++i) {
    const Eigen::Vector3d& x = scene.mesh.rest_positions[i];
    u.segment<3>(3 * i) = rotation * x + shift - x;
  }
  std::vector<Eigen::Vector3d> points;
  for (const auto& p : rest_points) points.push_back(rotation * p + shift);

  SurfaceCostOptions affine_options;
  affine_options.extension_mode = ExtensionMode::kAffinePlusHarmonic;
  SparseSurfaceCost affine(scene.mesh, scene.sdf, affine_options);
  SurfaceCostOptions harmonic_options;
  harmonic_options.extension_mode = ExtensionMode::kHarmonic;
  SparseSurfaceCost harmonic(scene.mesh, scene.sdf, harmonic_options);
  const double reference = affine.Evaluate(zero, rest_points, nullptr);
  EXPECT_EQ(harmonic.Evaluate(zero, rest_points, nullptr), reference);  // same at rest

  std::vector<PointMatch> matches;
  EXPECT_NEAR(affine.Evaluate(u, points, nullptr, &matches), reference, 1e-9 * reference);
  for (const auto& m : matches) ASSERT_TRUE(m.matched);
  const double distorted = harmonic.Evaluate(u, points, nullptr, &matches);
  const auto unmatched =
      std::count_if(matches.begin(), matches.end(), [](const PointMatch& m) { return !m.matched; });
  std::printf(
      "torus turned 90 deg, points 0.5 h outside: C = %.3g (affine + harmonic), %.3g "
      "(harmonic, %ld of %zu points unmatched)\n",
      reference, distorted, static_cast<long>(unmatched), matches.size());
  EXPECT_GT(distorted, 1.5 * reference);
  EXPECT_GT(unmatched, 0);
}

// The binned search finds exactly what a scan over all candidate cells finds, including ties at
// deformed grid nodes shared by up to 8 cells (smallest phi, then smallest cell).
TEST(SparseSurfaceCost, BinningMatchesBruteForce) {
  const Scene scene = MakeTorusScene(/*cells=*/12, /*padding=*/4);
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const double h = scene.h();
  const Eigen::VectorXd u = SampleOnNodes(scene.mesh, 0.5 * h);
  DisplacementExtension extension(scene.mesh, cost.options().band_cells,
                                  cost.options().extension_mode);
  Eigen::VectorXd u_domain;
  extension.Extend(u, &u_domain);
  Eigen::AlignedBox3d bounds;
  std::vector<Eigen::Vector3d> nodes;
  for (int d = 0; d < extension.num_domain_nodes(); ++d) {
    nodes.push_back(scene.mesh.grid.NodePosition(extension.grid_node(d)) +
                    u_domain.segment<3>(3 * d));
    bounds.extend(nodes.back());
  }
  std::mt19937 rng(2);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 1000; ++i) {
    Eigen::Vector3d t;
    for (int a = 0; a < 3; ++a) t[a] = std::uniform_real_distribution<double>(-0.1, 1.1)(rng);
    points.push_back(bounds.min() + t.cwiseProduct(bounds.sizes()));
  }
  for (size_t d = 0; d < nodes.size(); d += 29) points.push_back(nodes[d]);

  // Compares the binned matches with the brute force for displacement field `field`.
  const auto compare = [&](const Eigen::VectorXd& field, const std::vector<Eigen::Vector3d>& at,
                           const char* label) {
    std::vector<PointMatch> binned;
    cost.Evaluate(field, at, nullptr, &binned);
    const std::vector<PointMatch> brute = BruteForceMatches(scene, cost, field, at);
    for (size_t p = 0; p < at.size(); ++p) {
      EXPECT_EQ(binned[p].matched, brute[p].matched) << label << ", point " << p;
      EXPECT_EQ(binned[p].cell, brute[p].cell) << label << ", point " << p;
      EXPECT_EQ(binned[p].phi, brute[p].phi) << label << ", point " << p;
      EXPECT_EQ(binned[p].cost, brute[p].cost) << label << ", point " << p;
    }
    return binned;
  };
  const std::vector<PointMatch> smooth = compare(u, points, "smooth");
  const int matched = static_cast<int>(
      std::count_if(smooth.begin(), smooth.end(), [](const PointMatch& m) { return m.matched; }));
  EXPECT_GT(matched, 200);
  EXPECT_LT(matched, static_cast<int>(points.size()));

  // One FE node thrown 20 h away stretches its cells over more bins than the per-candidate limit
  // (they go to the overflow list, checked for every point); one thrown 1000 h away makes the
  // bins coarsen to keep their number bounded. Points along the stretched cells must still be
  // found exactly as by the scan.
  for (double distance : {20.0, 1000.0}) {
    Eigen::VectorXd wild = u;
    const int node = scene.mesh.NumNodes() / 2;
    const Eigen::Vector3d kick(distance * h, 0.3 * h, 0.0);
    wild.segment<3>(3 * node) += kick;
    std::vector<Eigen::Vector3d> near = points;
    const Eigen::Vector3d from = scene.mesh.rest_positions[node] + u.segment<3>(3 * node);
    for (int i = 0; i <= 100; ++i) {
      const Eigen::Vector3d jitter(0.0, (i % 7 - 3) * 0.1 * h, (i % 5 - 2) * 0.1 * h);
      near.push_back(from + (i / 100.0) * std::min(1.0, 40.0 / distance) * kick + jitter);
    }
    const std::vector<PointMatch> found = compare(wild, near, distance < 100 ? "20 h" : "1000 h");
    // The stretched cells catch some of the points along the kick.
    EXPECT_GT(std::count_if(found.begin() + static_cast<std::ptrdiff_t>(points.size()), found.end(),
                            [](const PointMatch& m) { return m.matched; }),
              10)
        << distance;
  }
}

// Where two parts of the deformed object overlap (a fold, or a state no real body can reach), a
// point there is inside material, whatever other sheet of surface passes through it: the cost
// takes the most inside preimage (the signed distance of the union of the cells' images). Picking
// the preimage closest to any surface instead made crumpled states cheaper than the truth.
TEST(SparseSurfaceCost, OverlappingMaterialCountsAsInside) {
  const Scene scene = MakeTorusScene(/*cells=*/20, /*padding=*/4);
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  // The half x > 0 of the torus (major radius 0.1 m, tube radius 0.04 m) moved by -0.22 m along x:
  // its tube near y = 0 now lies 2 cm beyond the other half's, overlapping it.
  const Eigen::Vector3d shift(-0.22, 0.0, 0.0);
  Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * scene.mesh.NumNodes());
  for (int i = 0; i < scene.mesh.NumNodes(); ++i) {
    if (scene.mesh.rest_positions[i].x() > 0.0) u.segment<3>(3 * i) = shift;
  }
  // Observed points on the outer side of the unmoved half's surface near y = 0: their preimage
  // in the moved half lies 2 cm from its tube's centre line, 2 cm inside.
  std::vector<Eigen::Vector3d> points;
  for (const Eigen::Vector3d& v : scene.surface.vertices) {
    if (std::abs(v.y()) < 0.02 && v.x() < -0.13 && std::abs(v.z()) < 0.01) points.push_back(v);
  }
  ASSERT_GE(points.size(), 4u);
  std::vector<PointMatch> matches;
  const double at_rest = cost.Evaluate(Eigen::VectorXd::Zero(u.size()), points, nullptr, &matches);
  for (const PointMatch& m : matches) ASSERT_LT(std::abs(m.phi), 0.1 * scene.h());
  const double overlapped = cost.Evaluate(u, points, nullptr, &matches);
  for (size_t p = 0; p < points.size(); ++p) {
    ASSERT_TRUE(matches[p].matched) << p;
    // The rest SDF at the moved half's preimage, about -2 cm.
    EXPECT_LT(matches[p].phi, -0.015) << p;
    EXPECT_GT(matches[p].rest_position.x(), 0.0) << p;  // matched in the moved half
  }
  std::printf("points on a surface overlapped by the other half: C = %.3g (at rest %.3g)\n",
              overlapped, at_rest);
  EXPECT_GT(overlapped, 100.0 * at_rest);
}

// With the Simulator's own grid (default padding) the default cost fits, and the simulator's
// deformed surface is an exact match.
TEST(SparseSurfaceCost, WorksWithSimulatorDefaults) {
  fem::SimulationOptions options;
  options.cells_along_longest_side = 16;
  fem::Simulator sim(geometry::MakeTorus(0.1, 0.04, 48, 24), fem::PhysicalParameters(), options);
  SparseSurfaceCost cost(sim.hex_mesh(), sim.signed_distance());
  const double phi_max = cost.truncation_distance();
  std::printf("simulator grid: band clipped by the grid: %s, band edge at %.2f h\n",
              cost.extension().clipped() ? "yes" : "no",
              cost.band_edge_distance() / sim.hex_mesh().CellSize());
  fem::SimulationState state = sim.state();
  state.u = SampleOnNodes(sim.hex_mesh(), 0.3 * sim.hex_mesh().CellSize());
  sim.SetState(state);
  std::vector<PointMatch> matches;
  const double c = cost.Evaluate(state.u, sim.SurfacePositions(), nullptr, &matches);
  for (const auto& m : matches) ASSERT_TRUE(m.matched);
  // A coarser grid (16 cells) than the other tests: larger SDF interpolation error.
  EXPECT_LT(c, 5e-4 * phi_max * phi_max);
}

// Cost of one Evaluate with gradient at a realistic size (printed, not asserted: machine load
// varies). Also checks that repeated calls give identical results (no state leaks between calls).
class TimingTest : public ::testing::TestWithParam<int> {};

TEST_P(TimingTest, OneEvaluate) {
  const Scene scene = MakeTorusScene(/*cells=*/GetParam(), /*padding=*/4);
  SparseSurfaceCost cost(scene.mesh, scene.sdf);
  const double h = scene.h();
  const Eigen::VectorXd u = SampleOnNodes(scene.mesh, 0.3 * h);
  Scene fine = scene;
  fine.surface = geometry::MakeTorus(0.1, 0.04, 80, 50);
  std::vector<Eigen::Vector3d> points = DeformedSurface(fine, u);
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.2 * h);
  for (auto& p : points) p += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
  Eigen::VectorXd gradient, first_gradient;
  const double first = cost.Evaluate(u, points, &first_gradient);
  const int repeats = 20;
  // Thread CPU time as well as wall time: the shared build machine is often loaded.
  const auto cpu_ms = [] {
    timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
  };
  const double cpu_start = cpu_ms();
  const auto start = std::chrono::steady_clock::now();
  double c = 0.0;
  for (int r = 0; r < repeats; ++r) c = cost.Evaluate(u, points, &gradient);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count() /
      repeats;
  const double cpu = (cpu_ms() - cpu_start) / repeats;
  const double cpu_start_value = cpu_ms();
  for (int r = 0; r < repeats; ++r) cost.Evaluate(u, points, nullptr);
  const double cpu_value = (cpu_ms() - cpu_start_value) / repeats;
  std::printf(
      "Evaluate: %zu points, %d FE nodes, %d band nodes, %d candidate cells: with gradient "
      "%.2f ms wall, %.2f ms CPU; cost only %.2f ms CPU\n",
      points.size(), scene.mesh.NumNodes(), cost.extension().num_band_nodes(),
      cost.num_candidate_cells(), ms, cpu, cpu_value);
  EXPECT_EQ(c, first);
  EXPECT_EQ(gradient, first_gradient);

  SurfaceCostOptions affine_options;
  affine_options.extension_mode = ExtensionMode::kAffinePlusHarmonic;
  SparseSurfaceCost affine(scene.mesh, scene.sdf, affine_options);
  affine.Evaluate(u, points, &gradient);
  const double cpu_start_affine = cpu_ms();
  for (int r = 0; r < repeats; ++r) affine.Evaluate(u, points, &gradient);
  std::printf("  kAffinePlusHarmonic: with gradient %.2f ms CPU\n",
              (cpu_ms() - cpu_start_affine) / repeats);
}

INSTANTIATE_TEST_SUITE_P(SparseSurfaceCost, TimingTest, ::testing::Values(20, 30));

}  // namespace
}  // namespace softid::cost
