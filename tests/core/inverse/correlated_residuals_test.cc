#include "core/inverse/correlated_residuals.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cstdio>
#include <random>
#include <vector>

namespace softid::inverse {
namespace {

// A linear least-squares problem y = J x + e with G frames of n points each. Columns of J: a
// constant and the frame's time (as a fall's position depends on gravity and a launch), plus a
// per-point part (where on the surface the point lies).
struct Problem {
  Eigen::MatrixXd jacobian;
  std::vector<int> frame_sizes;
};

Problem MakeProblem(int frames, int points, std::mt19937& rng) {
  std::normal_distribution<double> normal;
  Problem problem;
  problem.jacobian.resize(frames * points, 2);
  for (int k = 0; k < frames; ++k) {
    const double t = double(k) / frames;
    for (int i = 0; i < points; ++i) {
      problem.jacobian(k * points + i, 0) = 1.0 + 0.3 * normal(rng);
      problem.jacobian(k * points + i, 1) = t + 0.3 * normal(rng);
    }
    problem.frame_sizes.push_back(points);
  }
  return problem;
}

struct Variances {
  Eigen::Vector2d laplace, sandwich;
};

// Both estimates from the residuals at the least-squares solution for the errors `e`.
Variances Estimate(const Problem& problem, const Eigen::VectorXd& e, Eigen::Vector2d* solution) {
  const Eigen::MatrixXd& j = problem.jacobian;
  const Eigen::Matrix2d h_inv = (j.transpose() * j).inverse();
  *solution = h_inv * j.transpose() * e;  // the truth is x = 0
  const Eigen::VectorXd r = e - j * *solution;
  const double s2 = r.squaredNorm() / (r.size() - 2);
  Variances out;
  out.laplace = (s2 * h_inv).diagonal();
  const std::vector<Eigen::VectorXd> gradients = FrameGradients(j, r, problem.frame_sizes);
  out.sandwich = CorrelatedResidualCovariance(h_inv, gradients).diagonal();
  return out;
}

// Andrews' rule: no window for independent frames, a wide one for a persistent drift.
TEST(CorrelatedResiduals, BandwidthFollowsThePersistenceOfTheErrors) {
  std::mt19937 rng(4);
  std::normal_distribution<double> normal;
  for (double rho : {0.0, 0.6, 0.9}) {
    std::vector<Eigen::VectorXd> g(200, Eigen::VectorXd::Zero(2));
    for (size_t k = 1; k < g.size(); ++k)
      for (int c = 0; c < 2; ++c) g[k][c] = rho * g[k - 1][c] + normal(rng);
    const int bandwidth = AutomaticBandwidth(g);
    std::printf("autocorrelation %.1f: window %d frames\n", rho, bandwidth);
    if (rho == 0.0) EXPECT_LE(bandwidth, 1);
    if (rho == 0.6) EXPECT_GE(bandwidth, 6);
    if (rho == 0.9) EXPECT_GE(bandwidth, 15);
  }
  EXPECT_EQ(AutomaticBandwidth({}), 0);
}

TEST(CorrelatedResiduals, FrameGradientsSumToTheGradient) {
  std::mt19937 rng(3);
  const Problem problem = MakeProblem(7, 5, rng);
  Eigen::VectorXd r = Eigen::VectorXd::LinSpaced(35, -1.0, 2.0);
  const std::vector<Eigen::VectorXd> g = FrameGradients(problem.jacobian, r, problem.frame_sizes);
  ASSERT_EQ(g.size(), 7u);
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(2);
  for (const Eigen::VectorXd& gk : g) sum += gk;
  EXPECT_LT((sum - problem.jacobian.transpose() * r).norm(), 1e-12);
}

// With independent errors the sandwich agrees with the Laplace figure (on average over datasets;
// each single estimate is noisy), so widening by it changes little where the model is right.
TEST(CorrelatedResiduals, IndependentErrorsAgreeWithLaplace) {
  std::mt19937 rng(1);
  std::normal_distribution<double> normal;
  const Problem problem = MakeProblem(60, 30, rng);
  Eigen::Vector2d laplace = Eigen::Vector2d::Zero(), sandwich = Eigen::Vector2d::Zero();
  const int datasets = 200;
  for (int d = 0; d < datasets; ++d) {
    Eigen::VectorXd e(problem.jacobian.rows());
    for (int i = 0; i < e.size(); ++i) e[i] = 1e-3 * normal(rng);
    Eigen::Vector2d x;
    const Variances v = Estimate(problem, e, &x);
    laplace += v.laplace / datasets;
    sandwich += v.sandwich / datasets;
  }
  for (int c = 0; c < 2; ++c) {
    std::printf("variable %d: sandwich / laplace variance %.3f\n", c, sandwich[c] / laplace[c]);
    EXPECT_NEAR(sandwich[c] / laplace[c], 1.0, 0.15) << c;
  }
}

// An error shared by the points of a frame, drifting slowly from frame to frame (a model that is
// off, as after a chaotic impact): the Laplace variance, which counts 30 independent points per
// frame, falls far short of the estimates' true spread over datasets; the sandwich finds it. A
// variance estimated from 40 correlated frames scatters widely (quartiles about 0.5 and 1.5 times
// the truth here), so its median is held to a factor of two.
TEST(CorrelatedResiduals, SharedAndDriftingFrameErrorsWidenToTheTrueSpread) {
  std::mt19937 rng(2);
  std::normal_distribution<double> normal;
  const int frames = 40, points = 30;
  const Problem problem = MakeProblem(frames, points, rng);
  const int datasets = 400;
  std::vector<Eigen::Vector2d> sandwiches;
  Eigen::Vector2d laplace = Eigen::Vector2d::Zero();
  Eigen::Vector2d mean = Eigen::Vector2d::Zero(), square = Eigen::Vector2d::Zero();
  for (int d = 0; d < datasets; ++d) {
    Eigen::VectorXd e(problem.jacobian.rows());
    double shared = 0.0;
    for (int k = 0; k < frames; ++k) {
      shared = 0.6 * shared + 0.8 * 1e-3 * normal(rng);  // AR(1), correlation 0.6 per frame
      for (int i = 0; i < points; ++i) e[k * points + i] = shared + 1e-3 * normal(rng);
    }
    Eigen::Vector2d x;
    const Variances v = Estimate(problem, e, &x);
    laplace += v.laplace / datasets;
    sandwiches.push_back(v.sandwich);
    mean += x / datasets;
    square += x.cwiseAbs2() / datasets;
  }
  const Eigen::Vector2d spread = square - mean.cwiseAbs2();
  for (int c = 0; c < 2; ++c) {
    std::vector<double> values;
    for (const Eigen::Vector2d& v : sandwiches) values.push_back(v[c]);
    std::sort(values.begin(), values.end());
    const double median = values[datasets / 2];
    std::printf(
        "variable %d: true variance %.3g, laplace %.3g, sandwich quartiles %.3g %.3g %.3g\n", c,
        spread[c], laplace[c], values[datasets / 4], median, values[3 * datasets / 4]);
    EXPECT_LT(laplace[c], spread[c] / 5.0) << c;
    EXPECT_GT(median, 0.5 * spread[c]) << c;
    EXPECT_LT(median, 2.0 * spread[c]) << c;
  }
}

}  // namespace
}  // namespace softid::inverse
