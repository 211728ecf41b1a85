#include "core/fem/flexible_gmres.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <Eigen/SparseCore>
#include <vector>

#include "core/fem/sparse_matrix_operator.h"

namespace softid::fem {
namespace {

using Matrix = SparseMatrixOperator::Matrix;

// A 1-D Laplacian plus a small non-symmetric convection term: nearly symmetric, like the step
// systems, and ill-conditioned enough that unpreconditioned GMRES needs many iterations.
Matrix ConvectionDiffusion(int n) {
  std::vector<Eigen::Triplet<double>> entries;
  for (int i = 0; i < n; ++i) {
    entries.emplace_back(i, i, 2.0);
    if (i > 0) entries.emplace_back(i, i - 1, -1.0 - 0.05);
    if (i + 1 < n) entries.emplace_back(i, i + 1, -1.0 + 0.05);
  }
  Matrix a(n, n);
  a.setFromTriplets(entries.begin(), entries.end());
  return a;
}

// The identity as a preconditioner, with no work.
class Identity final : public LinearOperator {
 public:
  explicit Identity(Eigen::Index n) : n_(n) {}
  Eigen::Index size() const override { return n_; }
  void Apply(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::VectorXd* y) override { *y = x; }
  double ApplyWork() const override { return 0.0; }

 private:
  Eigen::Index n_;
};

// The exact inverse, perturbed by `relative_error` (an inexact preconditioner, like a
// reduced-precision factor).
class PerturbedInverse final : public LinearOperator {
 public:
  PerturbedInverse(const Matrix& a, double relative_error)
      : inverse_(Eigen::MatrixXd(a).inverse()) {
    inverse_ += relative_error * inverse_.norm() / inverse_.rows() *
                Eigen::MatrixXd::Random(inverse_.rows(), inverse_.cols());
  }
  Eigen::Index size() const override { return inverse_.rows(); }
  void Apply(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::VectorXd* y) override {
    *y = inverse_ * x;
  }
  double ApplyWork() const override { return 2.0 * inverse_.size(); }

 private:
  Eigen::MatrixXd inverse_;
};

double TrueResidual(const Matrix& a, const Eigen::VectorXd& b, const Eigen::VectorXd& x) {
  return (b - a * x).norm() / b.norm();
}

TEST(FlexibleGmres, ConvergesThroughRestartsWithoutAPreconditioner) {
  const int n = 120;
  const Matrix a = ConvectionDiffusion(n);
  SparseMatrixOperator op;
  op.Bind(a, false, nullptr);
  Identity identity(n);
  const Eigen::VectorXd b = Eigen::VectorXd::LinSpaced(n, -1.0, 2.0);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
  GmresOptions options;
  options.relative_tolerance = 1e-10;
  options.restart = 20;  // far fewer than n: several restarts
  options.max_iterations = 5000;
  FlexibleGmres gmres;
  const GmresSummary summary = gmres.Solve(op, identity, b, options, &x);
  EXPECT_TRUE(summary.converged);
  EXPECT_GT(summary.iterations, options.restart);
  EXPECT_LE(TrueResidual(a, b, x), 10 * options.relative_tolerance);
  EXPECT_GT(summary.work, summary.iterations * op.ApplyWork());
}

// An inexact preconditioner costs iterations, never accuracy (the flexible variant keeps Z).
TEST(FlexibleGmres, AnInexactPreconditionerStillReachesATightTolerance) {
  const int n = 60;
  const Matrix a = ConvectionDiffusion(n);
  SparseMatrixOperator op;
  op.Bind(a, false, nullptr);
  const Eigen::VectorXd b = Eigen::VectorXd::Ones(n);
  GmresOptions options;
  options.relative_tolerance = 1e-12;  // below the recurrence's trusted range: true residual
  FlexibleGmres gmres;
  PerturbedInverse exact(a, 0.0);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n);
  const GmresSummary with_exact = gmres.Solve(op, exact, b, options, &x);
  EXPECT_TRUE(with_exact.converged);
  EXPECT_LE(with_exact.iterations, 2);
  PerturbedInverse inexact(a, 1e-3);
  x.setZero();
  const GmresSummary with_inexact = gmres.Solve(op, inexact, b, options, &x);
  EXPECT_TRUE(with_inexact.converged);
  EXPECT_LE(TrueResidual(a, b, x), 10 * options.relative_tolerance);
  EXPECT_GE(with_inexact.iterations, with_exact.iterations);
}

TEST(FlexibleGmres, ZeroRightHandSideAndIterationLimit) {
  const int n = 80;
  const Matrix a = ConvectionDiffusion(n);
  SparseMatrixOperator op;
  op.Bind(a, false, nullptr);
  Identity identity(n);
  FlexibleGmres gmres;
  Eigen::VectorXd x = Eigen::VectorXd::Ones(n);
  const GmresSummary zero = gmres.Solve(op, identity, Eigen::VectorXd::Zero(n), {}, &x);
  EXPECT_TRUE(zero.converged);
  EXPECT_EQ(zero.iterations, 0);
  EXPECT_TRUE(x.isZero(0.0));

  GmresOptions options;
  options.max_iterations = 5;
  x.setZero();
  const GmresSummary limited = gmres.Solve(op, identity, Eigen::VectorXd::Ones(n), options, &x);
  EXPECT_EQ(limited.iterations, 5);
  EXPECT_FALSE(limited.converged);
  EXPECT_GT(limited.relative_residual, 1e-3);
}

}  // namespace
}  // namespace softid::fem
