#include "core/fem/linear_solver.h"

#include <Eigen/CholmodSupport>
#include <Eigen/SparseLU>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <mutex>
#include <utility>

#include "core/common/check.h"
#include "core/fem/numeric_runtime.h"
#include "core/fem/reduced_precision_factor.h"
#include "core/fem/thread_team.h"

namespace softid::fem {

namespace {

// CHOLMOD's supernodal factor, with access to its cholmod_factor.
class SupernodalLlt
    : public Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double, Eigen::ColMajor, int>,
                                         Eigen::Lower> {
 public:
  const cholmod_factor& factor() const { return *m_cholmodFactor; }
};

}  // namespace

struct LinearSolver::Factor {
  SupernodalLlt llt;
  // From CHOLMOD's symbolic analysis: flops of one numeric factorisation and nonzeros of L.
  double flops = 0.0;
  double factor_nonzeros = 0.0;
};

struct LinearSolver::FactorSnapshot {
  ReducedPrecisionFactor reduced;
  Eigen::Matrix3d reference_rotation = Eigen::Matrix3d::Identity();
  double factor_nonzeros = 0.0;
  // Work of the factorisation that made it, including failed shifted attempts (work-model units).
  double factor_work = 0.0;
};

LinearSolver::LinearSolver() {
  ConfigureNumericRuntime();
}
LinearSolver::~LinearSolver() {
  FinishFactorize();
}

double LinearSolver::ParallelShare() const {
  return current_ != nullptr ? current_->reduced.parallel_share() : 0.0;
}

void LinearSolver::SetThreadTeam(ThreadTeam* team) {
  FinishFactorize();
  team_ = team;
  const int threads = team != nullptr ? team->size() : 1;
  if (current_ != nullptr && current_->reduced.threads() != threads)
    current_->reduced.SetThreads(threads);
}

void LinearSolver::UseFactor(const std::shared_ptr<FactorSnapshot>& factor) {
  if (factor == nullptr || factor == current_) return;
  DiscardFactorize();
  current_ = factor;
  const int threads = team_ != nullptr ? team_->size() : 1;
  if (current_->reduced.threads() != threads) current_->reduced.SetThreads(threads);
  refactor_rule_.Restart();
}

size_t LinearSolver::FactorBytes(const FactorSnapshot& factor) {
  return factor.reduced.bytes();
}

LinearSolver::LinearSolver(LinearSolver&&) noexcept = default;
LinearSolver& LinearSolver::operator=(LinearSolver&&) noexcept = default;

bool LinearSolver::HasFactor() const {
  return current_ != nullptr;
}

bool LinearSolver::RefactorPays() const {
  return current_ != nullptr && refactor_rule_.Pays(current_->factor_work);
}

bool LinearSolver::Pattern::Matches(const Matrix& a) const {
  return a.cols() + 1 == static_cast<Eigen::Index>(outer.size()) &&
         a.nonZeros() == static_cast<Eigen::Index>(inner.size()) &&
         std::equal(outer.begin(), outer.end(), a.outerIndexPtr()) &&
         std::equal(inner.begin(), inner.end(), a.innerIndexPtr());
}

void LinearSolver::Pattern::Assign(const Matrix& a) {
  outer.assign(a.outerIndexPtr(), a.outerIndexPtr() + a.cols() + 1);
  inner.assign(a.innerIndexPtr(), a.innerIndexPtr() + a.nonZeros());
}

void LinearSolver::SymmetricPart(const Matrix& a, Symmetry symmetry, Matrix* out) {
  // The consistent tangent is not symmetric; its symmetric part is what a Cholesky factor can
  // approximate (the lower triangle alone can be far from positive definite).
  SOFTID_ASSERT(symmetry == Symmetry::kGeneral ||
                (a - Matrix(a.transpose())).norm() <= 1e-12 * a.norm());
  // Assigning to a matrix of the same size and pattern reuses its storage: a fresh ~10 MB copy
  // cost ~40 ms of first-touch page faults per factorisation on the dev VM (~14 us per page).
  *out = a;
  if (symmetry == Symmetry::kSymmetric) return;
  // (a + a^T) / 2 in place, through the position of each entry's transpose (the assembly's
  // pattern is structurally symmetric; computed once per pattern).
  if (!transposed_pattern_.Matches(a)) {
    transposed_pattern_.Assign(a);
    transpose_position_.assign(a.nonZeros(), -1);
    const int* outer = a.outerIndexPtr();
    const int* inner = a.innerIndexPtr();
    for (int j = 0; j < a.cols(); ++j) {
      for (int p = outer[j]; p < outer[j + 1]; ++p) {
        const int i = inner[p];  // entry (i, j); its transpose (j, i) is in column i
        const int* begin = inner + outer[i];
        const int* end = inner + outer[i + 1];
        const int* hit = std::lower_bound(begin, end, j);
        if (hit != end && *hit == j) transpose_position_[p] = static_cast<int>(hit - inner);
      }
    }
    structurally_symmetric_ = std::find(transpose_position_.begin(), transpose_position_.end(),
                                        -1) == transpose_position_.end();
  }
  if (!structurally_symmetric_ || !a.isCompressed()) {
    *out = 0.5 * (a + Matrix(a.transpose()));
    return;
  }
  const double* values = a.valuePtr();
  double* symmetric = out->valuePtr();
  for (Eigen::Index p = 0; p < a.nonZeros(); ++p)
    symmetric[p] = 0.5 * (values[p] + values[transpose_position_[p]]);
}

namespace {
// CHOLMOD's analysis tries METIS beside AMD once AMD's fill is poor (a few thousand unknowns), and
// the METIS inside Debian's CHOLMOD keeps its random-number state in globals: two analyses at
// once (concurrent optimiser starts) interleaved their draws, so the same matrix got another
// ordering (402 vs 410 supernodes at 8,370 unknowns), another factor, and two runs of one fit
// parted in the fifth digit after a few iterations. METIS reseeds on every call, so one analysis
// at a time makes the ordering a function of the matrix alone.
std::mutex& AnalysisMutex() {
  static std::mutex mutex;
  return mutex;
}
}  // namespace

void LinearSolver::PrepareWorkspace(const Matrix& symmetric) {
  // The assembly pattern is fixed, so the fill-reducing ordering and symbolic analysis (METIS
  // dominates a factorisation at ~10^4 unknowns) are done once and reused.
  if (!analysed_pattern_.Matches(symmetric)) {
    analysed_pattern_.Assign(symmetric);
    workspace_.reset();  // analysed for another pattern (the current factor still preconditions)
  }
  if (workspace_ == nullptr) {
    workspace_ = std::make_unique<Factor>();
    workspace_->llt.cholmod().print = 0;  // failures are handled below, not printed to stderr
    {
      const std::lock_guard<std::mutex> lock(AnalysisMutex());
      workspace_->llt.analyzePattern(symmetric);
    }
    workspace_->flops = workspace_->llt.cholmod().fl;
    workspace_->factor_nonzeros = workspace_->llt.cholmod().lnz;
  }
}

int LinearSolver::FactorNumerically(const Matrix& symmetric, int threads, Factor* workspace,
                                    FactorSnapshot* fresh) {
  SupernodalLlt& llt = workspace->llt;
  llt.setShift(0.0);
  llt.factorize(symmetric);
  int attempts = 1;
  // Under strong compression the consistent tangent's geometric part makes the matrix indefinite.
  // As a preconditioner a factor of A + shift I serves as well: try growing shifts relative to the
  // mean diagonal.
  const double mean_diagonal = symmetric.diagonal().cwiseAbs().mean();
  for (double relative_shift : {1e-4, 1e-2, 1e-1, 1.0}) {
    if (llt.info() == Eigen::Success) break;
    llt.setShift(relative_shift * mean_diagonal);
    llt.factorize(symmetric);
    ++attempts;
  }
  if (llt.info() != Eigen::Success) return -attempts;
  fresh->reduced.Assign(llt.factor(), threads);
  fresh->factor_nonzeros = workspace->factor_nonzeros;
  return attempts;
}

void LinearSolver::Adopt(std::shared_ptr<FactorSnapshot> fresh, const Eigen::Matrix3d& rotation,
                         int attempts, Eigen::Index matrix_nonzeros) {
  fresh->reference_rotation = rotation;
  // A failed attempt stops at its first non-positive pivot; counting it in full errs towards
  // keeping a factor that was hard to get.
  fresh->factor_work = attempts * kFactorFlopWeight * workspace_->flops +
                       kFactorWorkPerMatrixEntry * static_cast<double>(matrix_nonzeros);
  current_ = std::move(fresh);
  ++num_factorizations_;
  refactor_rule_.Restart();
}

Status LinearSolver::Factorize(const Matrix& a, const Eigen::Matrix3d& rotation,
                               Symmetry symmetry) {
  DiscardFactorize();  // replaced at once: computing or adopting it would be wasted
  SymmetricPart(a, symmetry, &factor_input_);
  const Matrix& symmetric = factor_input_;
  PrepareWorkspace(symmetric);
  auto fresh = std::make_shared<FactorSnapshot>();
  const int attempts = FactorNumerically(symmetric, team_ != nullptr ? team_->size() : 1,
                                         workspace_.get(), fresh.get());
  if (attempts < 0) {
    return Status::FailedPrecondition(
        "step matrix is far from positive definite (Cholesky failed)");
  }
  Adopt(std::move(fresh), rotation, attempts, a.nonZeros());
  return Status::Ok();
}

// A factorisation StartFactorize began, owned by the solver until FinishFactorize: the matrix (a
// copy: the caller's changes on) and the outcome, written by the background thread only, if it
// runs in the background (on a team; else FinishFactorize computes it). Destroying it waits for
// the job (a solver moved onto or destroyed never leaves it running on freed memory; pending_ is
// declared before the workspace, so a move assignment joins before it replaces it).
struct LinearSolver::PendingFactorization {
  explicit PendingFactorization(ThreadTeam* team) : team(team) {}
  ~PendingFactorization() {
    if (team != nullptr) team->WaitForBackground();
  }
  PendingFactorization(const PendingFactorization&) = delete;
  PendingFactorization& operator=(const PendingFactorization&) = delete;
  ThreadTeam* team;  // null: not in the background
  Matrix symmetric;
  Eigen::Matrix3d rotation;
  Eigen::Index matrix_nonzeros = 0;
  std::shared_ptr<FactorSnapshot> fresh = std::make_shared<FactorSnapshot>();
  int attempts = 0;  // negative: failed
  // For FinishFactorizeWhenDue: the factorisation's work (one attempt) and the solver's work and
  // calls since it started, in work-model units.
  double expected_work = 0.0;
  double overlapped_work = 0.0;
  int calls = 0;
};

Status LinearSolver::StartFactorize(const Matrix& a, const Eigen::Matrix3d& rotation,
                                    Symmetry symmetry) {
  FinishFactorize();
  const bool background = team_ != nullptr && team_->size() >= 2;
  pending_ = std::make_unique<PendingFactorization>(background ? team_ : nullptr);
  // The pending record borrows factor_input_'s storage until FinishFactorize.
  pending_->symmetric.swap(factor_input_);
  SymmetricPart(a, symmetry, &pending_->symmetric);
  pending_->rotation = rotation;
  pending_->matrix_nonzeros = a.nonZeros();
  PrepareWorkspace(pending_->symmetric);
  pending_->expected_work = kFactorFlopWeight * workspace_->flops +
                            kFactorWorkPerMatrixEntry * static_cast<double>(a.nonZeros());
  // On one thread FinishFactorize computes it: the factor is adopted at the same point either way,
  // so a run's Newton iterates do not depend on the number of threads.
  if (!background) return Status::Ok();
  // The job touches only the pending record and the workspace, both on the heap and left alone
  // by the solver until FinishFactorize joins it.
  PendingFactorization* pending = pending_.get();
  Factor* workspace = workspace_.get();
  const int threads = team_->size();
  team_->StartBackground([pending, workspace, threads] {
    try {
      pending->attempts =
          FactorNumerically(pending->symmetric, threads, workspace, pending->fresh.get());
    } catch (const std::exception&) {
      pending->attempts = -1;  // out of memory, say: the previous factor stays
    }
  });
  return Status::Ok();
}

void LinearSolver::DiscardFactorize() {
  if (pending_ == nullptr) return;
  if (pending_->team != nullptr) pending_->team->WaitForBackground();
  factor_input_.swap(pending_->symmetric);
  pending_.reset();
}

bool LinearSolver::FinishFactorizeWhenDue(int max_calls) {
  if (pending_ == nullptr) return false;
  ++pending_->calls;
  if (pending_->overlapped_work < pending_->expected_work && pending_->calls < max_calls)
    return false;
  return FinishFactorize();
}

bool LinearSolver::FinishFactorize() {
  if (pending_ == nullptr) return false;
  if (pending_->team != nullptr) {
    pending_->team->WaitForBackground();
  } else {
    pending_->attempts =
        FactorNumerically(pending_->symmetric, team_ != nullptr ? team_->size() : 1,
                          workspace_.get(), pending_->fresh.get());
  }
  const std::unique_ptr<PendingFactorization> pending = std::move(pending_);
  factor_input_.swap(pending->symmetric);
  if (pending->attempts < 0) return false;
  Adopt(std::move(pending->fresh), pending->rotation, pending->attempts, pending->matrix_nonzeros);
  return true;
}

namespace {
// y_i = Q x_i for every 3-block.
void RotateBlocks(const Eigen::Matrix3d& q, const Eigen::Ref<const Eigen::VectorXd>& x,
                  Eigen::VectorXd* y) {
  const Eigen::Index n = x.size() / 3;
  for (Eigen::Index i = 0; i < n; ++i) y->segment<3>(3 * i).noalias() = q * x.segment<3>(3 * i);
}

// z = P^-1 r = Q A_ref^-1 Q^T r on a factor's reduced-precision copy (see the header).
class RotatedFactorPreconditioner final : public LinearOperator {
 public:
  // For the body at `rotation`; `rotated`: work storage, resized to the system's size `n`.
  RotatedFactorPreconditioner(LinearSolver::FactorSnapshot& factor, const Eigen::Matrix3d& rotation,
                              ThreadTeam* team, Eigen::Index n, Eigen::VectorXd* rotated)
      : factor_(factor.reduced),
        factor_nonzeros_(factor.factor_nonzeros),
        q_(rotation * factor.reference_rotation.transpose()),
        team_(team),
        rotated_(rotated) {
    rotated_->resize(n);
  }
  Eigen::Index size() const override { return rotated_->size(); }
  void Apply(const Eigen::Ref<const Eigen::VectorXd>& r, Eigen::VectorXd* z) override {
    RotateBlocks(q_.transpose(), r, rotated_);
    factor_.Solve(rotated_->data(), rotated_->data(), team_);
    RotateBlocks(q_, *rotated_, z);
  }
  // The two triangular solves alone (2 nnz(L) flops each, at the reduced-precision weight).
  double SolveWork() const { return kReducedPrecisionSolveWeight * 4.0 * factor_nonzeros_; }
  // With the two block rotations (15 flops per 3-block each).
  double ApplyWork() const override {
    return SolveWork() + 2.0 * 15.0 / 3.0 * static_cast<double>(size());
  }

 private:
  ReducedPrecisionFactor& factor_;
  double factor_nonzeros_;
  Eigen::Matrix3d q_;
  ThreadTeam* team_;
  Eigen::VectorXd* rotated_;
};

// Multiplicative Schwarz: the factor's estimate x1 = P^-1 r, then an exact solve of the
// remaining residual on the correction's nodes (subdomain_correction.h).
class CorrectedPreconditioner final : public LinearOperator {
 public:
  CorrectedPreconditioner(RotatedFactorPreconditioner& factor, SubdomainCorrection& correction)
      : factor_(factor), correction_(correction) {}
  Eigen::Index size() const override { return factor_.size(); }
  void Apply(const Eigen::Ref<const Eigen::VectorXd>& r, Eigen::VectorXd* z) override {
    factor_.Apply(r, z);
    correction_.Correct(r, z);
  }
  double ApplyWork() const override { return factor_.ApplyWork() + correction_.CorrectWork(); }

 private:
  RotatedFactorPreconditioner& factor_;
  SubdomainCorrection& correction_;
};
}  // namespace

bool LinearSolver::SetCorrection(const std::vector<int>& nodes,
                                 SubdomainCorrection::RowMatrix rows) {
  return correction_.Assign(nodes, std::move(rows));
}

void LinearSolver::Precondition(const Eigen::VectorXd& b, const Eigen::Matrix3d& rotation,
                                Eigen::VectorXd* x) {
  SOFTID_DEMAND(HasFactor());
  x->resize(b.size());
  RotatedFactorPreconditioner preconditioner(*current_, rotation, team_, b.size(), &rotated_);
  preconditioner.Apply(b, x);
  if (pending_ != nullptr) pending_->overlapped_work += preconditioner.SolveWork();
}

namespace {
// b = 0: x = 0 solves op(a) x = b exactly.
LinearSolver::Summary SolvedByZero(Eigen::VectorXd* x) {
  x->setZero();
  LinearSolver::Summary summary;
  summary.relative_residual = 0.0;
  summary.converged = true;
  return summary;
}
}  // namespace

LinearSolver::Summary LinearSolver::SolveDirect(const Matrix& a, const Eigen::VectorXd& b,
                                                const Options& options, Eigen::VectorXd* x,
                                                Operator op) {
  Summary summary;
  const double b_norm = b.norm();
  if (b_norm == 0.0) return SolvedByZero(x);
  Eigen::SparseLU<Matrix, Eigen::COLAMDOrdering<int>> lu;
  if (op == Operator::kTransposed) {
    const Matrix transposed = a.transpose();
    lu.compute(transposed);
  } else {
    lu.compute(a);
  }
  if (lu.info() != Eigen::Success) return summary;
  *x = lu.solve(b);
  if (lu.info() != Eigen::Success || !x->allFinite()) return summary;
  summary.iterations = 1;
  const Eigen::VectorXd residual = op == Operator::kTransposed
                                       ? Eigen::VectorXd(b - a.transpose() * *x)
                                       : Eigen::VectorXd(b - a * *x);
  summary.relative_residual = residual.norm() / b_norm;
  summary.converged = summary.relative_residual <= options.relative_tolerance;
  return summary;
}

LinearSolver::Summary LinearSolver::Solve(const Matrix& a, const Eigen::VectorXd& b,
                                          const Eigen::Matrix3d& rotation, const Options& options,
                                          Eigen::VectorXd* x, Operator op) {
  matrix_operator_.Bind(a, op == Operator::kTransposed, team_);
  return Solve(matrix_operator_, b, rotation, options, x);
}

LinearSolver::Summary LinearSolver::Solve(LinearOperator& a, const Eigen::VectorXd& b,
                                          const Eigen::Matrix3d& rotation, const Options& options,
                                          Eigen::VectorXd* x) {
  SOFTID_DEMAND(HasFactor());
  SOFTID_DEMAND(a.size() == b.size());
  // b = 0 is no solve: it would set the refactorisation rule's baseline at 0 iterations.
  if (b.norm() == 0.0) return SolvedByZero(x);
  RotatedFactorPreconditioner preconditioner(*current_, rotation, team_, b.size(), &rotated_);
  CorrectedPreconditioner corrected(preconditioner, correction_);
  LinearOperator& chosen = correction_.empty() ? static_cast<LinearOperator&>(preconditioner)
                                               : static_cast<LinearOperator&>(corrected);
  const GmresSummary gmres = gmres_.Solve(a, chosen, b, options, x);
  if (pending_ != nullptr) pending_->overlapped_work += gmres.work;
  refactor_rule_.RecordSolve(gmres.iterations, gmres.work);
  Summary summary;
  summary.iterations = gmres.iterations;
  summary.relative_residual = gmres.relative_residual;
  summary.converged = gmres.converged;
  return summary;
}

}  // namespace softid::fem
