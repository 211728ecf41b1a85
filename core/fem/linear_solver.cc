#include "core/fem/linear_solver.h"

#include <dlfcn.h>

#include <Eigen/CholmodSupport>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>

#include "core/common/check.h"

namespace softid::fem {

struct LinearSolver::Factor {
  Eigen::CholmodSupernodalLLT<Matrix, Eigen::Lower> llt;
};

namespace {
// Our systems have at most a few 10^5 unknowns and softid parallelises across optimiser starts and
// jobs; a threaded BLAS (Debian's OpenBLAS pthread build) then spends most of its time spinning in
// sched_yield on small supernodes. Pin BLAS to one thread when the library offers the switch.
void UseSingleThreadedBlas() {
  static std::once_flag once;
  std::call_once(once, [] {
    using SetThreads = void (*)(int);
    if (auto set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) {
      set(1);
    }
  });
}
}  // namespace

LinearSolver::LinearSolver() {
  UseSingleThreadedBlas();
}
LinearSolver::~LinearSolver() = default;
LinearSolver::LinearSolver(LinearSolver&&) noexcept = default;
LinearSolver& LinearSolver::operator=(LinearSolver&&) noexcept = default;

bool LinearSolver::HasFactor() const {
  return factor_ != nullptr;
}

bool LinearSolver::RefactorPays() const {
  return factor_ != nullptr && excess_seconds_ > factor_seconds_;
}

Status LinearSolver::Factorize(const Matrix& a, const Eigen::Matrix3d& rotation) {
  const auto start = std::chrono::steady_clock::now();
  // The consistent tangent is not symmetric; its symmetric part is what a Cholesky factor can
  // approximate (the lower triangle alone can be far from positive definite).
  const Matrix symmetric = 0.5 * (a + Matrix(a.transpose()));
  // The assembly pattern is fixed, so the fill-reducing ordering and symbolic analysis (METIS
  // dominates a factorisation at ~10^4 unknowns) are done once and reused: the numeric factor
  // goes into the spare, which becomes current only when it succeeds.
  const bool same_pattern =
      symmetric.rows() + 1 == static_cast<Eigen::Index>(pattern_outer_.size()) &&
      symmetric.nonZeros() == static_cast<Eigen::Index>(pattern_inner_.size()) &&
      std::equal(pattern_outer_.begin(), pattern_outer_.end(), symmetric.outerIndexPtr()) &&
      std::equal(pattern_inner_.begin(), pattern_inner_.end(), symmetric.innerIndexPtr());
  if (!same_pattern) {
    pattern_outer_.assign(symmetric.outerIndexPtr(),
                          symmetric.outerIndexPtr() + symmetric.rows() + 1);
    pattern_inner_.assign(symmetric.innerIndexPtr(),
                          symmetric.innerIndexPtr() + symmetric.nonZeros());
    spare_.reset();  // analysed for another pattern (the current factor still preconditions)
  }
  if (spare_ == nullptr) {
    spare_ = std::make_unique<Factor>();
    spare_->llt.cholmod().print = 0;  // failures are handled below, not printed to stderr
    spare_->llt.analyzePattern(symmetric);
  }
  Factor& fresh = *spare_;
  fresh.llt.setShift(0.0);
  fresh.llt.factorize(symmetric);
  // Under strong compression the consistent tangent's geometric part makes the matrix indefinite.
  // As a preconditioner a factor of A + shift I serves as well: try growing shifts relative to the
  // mean diagonal.
  const double mean_diagonal = symmetric.diagonal().cwiseAbs().mean();
  for (double relative_shift : {1e-4, 1e-2, 1e-1, 1.0}) {
    if (fresh.llt.info() == Eigen::Success) break;
    fresh.llt.setShift(relative_shift * mean_diagonal);
    fresh.llt.factorize(symmetric);
  }
  if (fresh.llt.info() != Eigen::Success) {
    return Status::FailedPrecondition(
        "step matrix is far from positive definite (Cholesky failed)");
  }
  std::swap(factor_, spare_);
  if (!same_pattern) spare_.reset();  // the old factor has the old pattern's analysis
  reference_rotation_ = rotation;
  ++num_factorizations_;
  factor_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  baseline_iterations_ = -1;
  excess_seconds_ = 0.0;
  return Status::Ok();
}

namespace {
// y_i = Q x_i for every 3-block.
void RotateBlocks(const Eigen::Matrix3d& q, const Eigen::Ref<const Eigen::VectorXd>& x,
                  Eigen::VectorXd* y) {
  const Eigen::Index n = x.size() / 3;
  for (Eigen::Index i = 0; i < n; ++i) y->segment<3>(3 * i).noalias() = q * x.segment<3>(3 * i);
}
}  // namespace

void LinearSolver::ApplyPreconditioner(const Eigen::Ref<const Eigen::VectorXd>& r,
                                       Eigen::VectorXd* z) {
  RotateBlocks(preconditioner_rotation_.transpose(), r, &rotated_);
  rotated_ = factor_->llt.solve(rotated_);
  RotateBlocks(preconditioner_rotation_, rotated_, z);
}

LinearSolver::Summary LinearSolver::Solve(const Matrix& a, const Eigen::VectorXd& b,
                                          const Eigen::Matrix3d& rotation, const Options& options,
                                          Eigen::VectorXd* x, Operator op) {
  SOFTID_DEMAND(HasFactor());
  Summary summary;
  const Eigen::Index n = b.size();
  const int m = std::max(1, options.restart);
  if (basis_.rows() != n || basis_.cols() != m + 1) {
    basis_.resize(n, m + 1);
    preconditioned_.resize(n, m);
    hessenberg_.resize(m + 1, m);
    givens_c_.resize(m);
    givens_s_.resize(m);
    g_.resize(m + 1);
  }
  r_.resize(n);
  w_.resize(n);
  rotated_.resize(n);
  preconditioner_rotation_ = rotation * reference_rotation_.transpose();

  const double b_norm = b.norm();
  if (b_norm == 0.0) {
    x->setZero();
    summary.relative_residual = 0.0;
    summary.converged = true;
    return summary;
  }
  const auto start = std::chrono::steady_clock::now();
  // y = op(a) x. The transposed product runs over the column-major storage as row dot products:
  // no transposed copy of the matrix is made.
  const auto apply = [&](const auto& in, Eigen::VectorXd* out) {
    if (op == Operator::kTransposed)
      out->noalias() = a.transpose() * in;
    else
      out->noalias() = a * in;
  };
  double residual = 0.0;
  while (true) {
    apply(*x, &r_);
    r_ = b - r_;
    const double beta = r_.norm();
    residual = beta / b_norm;
    if (residual <= options.relative_tolerance || summary.iterations >= options.max_iterations)
      break;
    basis_.col(0) = r_ / beta;
    g_.setZero();
    g_[0] = beta;
    int j = 0;
    for (; j < m && summary.iterations < options.max_iterations; ++j) {
      ++summary.iterations;
      ApplyPreconditioner(basis_.col(j), &w_);
      preconditioned_.col(j) = w_;
      apply(preconditioned_.col(j), &w_);
      for (int i = 0; i <= j; ++i) {  // modified Gram-Schmidt
        hessenberg_(i, j) = w_.dot(basis_.col(i));
        w_ -= hessenberg_(i, j) * basis_.col(i);
      }
      const double h_next = w_.norm();
      hessenberg_(j + 1, j) = h_next;
      for (int i = 0; i < j; ++i) {  // previous Givens rotations
        const double t = givens_c_[i] * hessenberg_(i, j) + givens_s_[i] * hessenberg_(i + 1, j);
        hessenberg_(i + 1, j) =
            -givens_s_[i] * hessenberg_(i, j) + givens_c_[i] * hessenberg_(i + 1, j);
        hessenberg_(i, j) = t;
      }
      const double denom = std::hypot(hessenberg_(j, j), h_next);
      givens_c_[j] = denom > 0.0 ? hessenberg_(j, j) / denom : 1.0;
      givens_s_[j] = denom > 0.0 ? h_next / denom : 0.0;
      hessenberg_(j, j) = denom;
      hessenberg_(j + 1, j) = 0.0;
      g_[j + 1] = -givens_s_[j] * g_[j];
      g_[j] = givens_c_[j] * g_[j];
      residual = std::abs(g_[j + 1]) / b_norm;
      if (h_next > 0.0) basis_.col(j + 1) = w_ / h_next;
      if (residual <= options.relative_tolerance || h_next == 0.0) {
        ++j;
        break;
      }
    }
    // x += Z y with H y = g (upper triangular, j x j).
    const Eigen::VectorXd y =
        hessenberg_.topLeftCorner(j, j).triangularView<Eigen::Upper>().solve(g_.head(j));
    x->noalias() += preconditioned_.leftCols(j) * y;
    if (residual <= options.relative_tolerance) {
      apply(*x, &r_);  // true residual (the recurrence can drift)
      r_ = b - r_;
      residual = r_.norm() / b_norm;
      if (residual <= 10.0 * options.relative_tolerance) break;
    }
  }
  summary.relative_residual = residual;
  summary.converged = residual <= 10.0 * options.relative_tolerance;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double per_iteration = seconds / std::max(1, summary.iterations);
  seconds_per_iteration_ = seconds_per_iteration_ > 0.0
                               ? 0.8 * seconds_per_iteration_ + 0.2 * per_iteration
                               : per_iteration;
  if (baseline_iterations_ < 0) baseline_iterations_ = summary.iterations;
  excess_seconds_ +=
      std::max(0, summary.iterations - baseline_iterations_) * seconds_per_iteration_;
  return summary;
}

}  // namespace softid::fem
