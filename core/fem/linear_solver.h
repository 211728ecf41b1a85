// Solves the step systems A x = b (nearly symmetric: the corotated consistent tangent is not) by
// restarted GMRES, right-preconditioned with a sparse Cholesky factor (CHOLMOD, supernodal) of the
// lower triangle of a reference matrix A_ref, rotated with the body: P^-1 = Q A_ref^-1 Q^T with
// Q = blockdiag(R R_ref^T). A tumbling body's matrix is (nearly) R A_rest R^T, so one factor serves
// many steps; refactorising every step would cost ~0.2-0.4 s at 10k DOFs. The caller renews the
// factor when RefactorPays() (refactorisation_rule.h); GMRES itself is flexible_gmres.h. The
// triangular solves run on a reduced-precision copy of the factor (single-precision diagonal
// blocks, half-precision blocks below them where the CPU converts halves: about a third of the
// double factor's memory traffic); GMRES keeps the preconditioned basis (flexible GMRES), so
// solutions are as accurate as with the double factor.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <memory>
#include <vector>

#include "core/common/status.h"
#include "core/fem/flexible_gmres.h"
#include "core/fem/linear_operator.h"
#include "core/fem/refactorisation_rule.h"
#include "core/fem/sparse_matrix_operator.h"
#include "core/fem/subdomain_correction.h"

namespace softid::fem {

class ThreadTeam;

class LinearSolver {
 public:
  using Matrix = Eigen::SparseMatrix<double, Eigen::ColMajor, int>;
  using Options = GmresOptions;
  struct Summary {
    int iterations = 0;
    double relative_residual = -1.0;
    bool converged = false;
  };

  LinearSolver();
  // The triangular solves and products with the matrix run on `team` (not owned; it must outlive
  // the solver, or be replaced before it goes). Null: on the calling thread.
  void SetThreadTeam(ThreadTeam* team);
  ~LinearSolver();
  LinearSolver(LinearSolver&&) noexcept;
  LinearSolver& operator=(LinearSolver&&) noexcept;

  // Whether a matrix passed to Factorize is symmetric up to round-off (then its lower triangle is
  // factored as it is) or general (its symmetric part (a + a^T) / 2 is formed first, which costs
  // a transposed copy: ~15 % of a factorisation at 13k unknowns).
  enum class Symmetry { kGeneral, kSymmetric };
  // Factorises `a`'s symmetric part as the reference, taken at body rotation `rotation`, dropping
  // a pending factorisation (DiscardFactorize). Fails when that is not positive definite; a
  // previous factor is then kept.
  Status Factorize(const Matrix& a, const Eigen::Matrix3d& rotation,
                   Symmetry symmetry = Symmetry::kGeneral);
  // Factorize, adopted later: the current factor keeps preconditioning until FinishFactorize,
  // which the caller calls at a point of its own choosing, so that the result depends neither on
  // timing nor on the number of threads. On a team of two or more it runs in the background
  // meanwhile (the team's parallel regions then run on the calling thread alone): a
  // factorisation of ~10^4 unknowns takes ~100 ms, several Newton iterations' worth, which the
  // caller's work overlaps. Otherwise FinishFactorize computes it. Returns Ok (a failure shows in
  // FinishFactorize).
  Status StartFactorize(const Matrix& a, const Eigen::Matrix3d& rotation,
                        Symmetry symmetry = Symmetry::kGeneral);
  // Completes a factorisation StartFactorize began (waits for it, or computes it without a team)
  // and makes it current when it succeeded (a failed one leaves the previous factor). Returns
  // whether a new factor became current.
  bool FinishFactorize();
  // FinishFactorize once it is due: when the solves since StartFactorize have done about the
  // factorisation's work (work model: the point does not depend on timing), or at the max_calls-th
  // call, whichever comes first. Until then the current factor keeps preconditioning, and the
  // caller's work overlaps the factorisation instead of waiting for it. Returns whether a new
  // factor became current.
  bool FinishFactorizeWhenDue(int max_calls);
  // Drops a factorisation StartFactorize began (after waiting for it in the background): the
  // current factor stays.
  void DiscardFactorize();
  bool FactorizationPending() const { return pending_ != nullptr; }
  bool HasFactor() const;

  // A factor as a handle: its reduced-precision copy of L (~11 MB at 12.9k unknowns), reference
  // rotation and work, shared by the solver and whoever keeps the handle. A forward pass's factors
  // serve its adjoint pass again (UseFactor), whose step matrices they approximate as well, so
  // the adjoint need not factorise them anew.
  struct FactorSnapshot;
  // The current factor; null without one.
  std::shared_ptr<FactorSnapshot> CurrentFactor() const { return current_; }
  // Makes `factor` current, dropping a pending factorisation (DiscardFactorize); the
  // refactorisation rule starts over as after a factorisation. Null or the current factor: nothing
  // changes.
  void UseFactor(const std::shared_ptr<FactorSnapshot>& factor);
  // Memory a factor holds [bytes].
  static size_t FactorBytes(const FactorSnapshot& factor);
  // Share of the factor's entries that the team's members solve concurrently in a preconditioner
  // application (its elimination tree's subtrees); the rest (the top separators) runs on one
  // thread. 0 without a team or a factor.
  double ParallelShare() const;
  int num_factorizations() const { return num_factorizations_; }
  // Whether renewing the factor pays (refactorisation_rule.h): true once the GMRES work spent
  // beyond what the fresh factor needed exceeds the work of one factorisation.
  bool RefactorPays() const;

  // Which operator Solve inverts: a, or its transpose (the adjoint's systems). The preconditioner
  // approximates the symmetric part, which both share.
  enum class Operator { kMatrix, kTransposed };

  // x = P^-1 b: the preconditioner alone, an estimate of the solution of a x = b. @pre HasFactor()
  void Precondition(const Eigen::VectorXd& b, const Eigen::Matrix3d& rotation, Eigen::VectorXd* x);

  // Solves op(a) x = b; x holds the initial guess on entry. @pre HasFactor()
  Summary Solve(const Matrix& a, const Eigen::VectorXd& b, const Eigen::Matrix3d& rotation,
                const Options& options, Eigen::VectorXd* x, Operator op = Operator::kMatrix);
  // Solves a x = b with `a` given by its products (e.g. the unassembled step matrix); x holds the
  // initial guess on entry. The factor must approximate a's symmetric part. @pre HasFactor()
  Summary Solve(LinearOperator& a, const Eigen::VectorXd& b, const Eigen::Matrix3d& rotation,
                const Options& options, Eigen::VectorXd* x);

  // Corrects the preconditioner of the following solves on the unknowns of `nodes` with `rows`,
  // the solved operator's rows on them (subdomain_correction.h): each application then costs a
  // product with those rows and a pair of small triangular solves. Returns false (no correction)
  // when their block on the nodes is singular. Until ClearCorrection or the next call.
  bool SetCorrection(const std::vector<int>& nodes, SubdomainCorrection::RowMatrix rows);
  void ClearCorrection() { correction_.Clear(); }
  // Unknowns' nodes the current correction covers (0: none).
  int CorrectionNodes() const { return correction_.num_nodes(); }

  // Solves op(a) x = b by sparse LU (Eigen's SparseLU, COLAMD ordering), without the factor: the
  // fallback for the rare system GMRES stagnates on, e.g. the exact (indefinite, non-symmetric)
  // tangent of a block sticking under strong friction. Slow (a fresh LU each call) but exact; the
  // summary reports the true relative residual, and converged is false when the LU is singular or
  // misses `options.relative_tolerance`.
  static Summary SolveDirect(const Matrix& a, const Eigen::VectorXd& b, const Options& options,
                             Eigen::VectorXd* x, Operator op = Operator::kMatrix);

 private:
  struct Factor;
  struct PendingFactorization;
  // out = a's symmetric part (a itself when kSymmetric), in out's storage when it fits.
  void SymmetricPart(const Matrix& a, Symmetry symmetry, Matrix* out);
  // The factorisations' input matrix, kept to reuse its storage, and per entry of the last
  // general matrix's pattern the position of its transpose.
  Matrix factor_input_;
  std::vector<int> transpose_position_;
  bool structurally_symmetric_ = false;
  // Readies workspace_ for a's pattern (a new symbolic analysis when it changed).
  void PrepareWorkspace(const Matrix& symmetric);
  // Numeric factorisation in `workspace` (shifted when indefinite) and its reduced-precision copy
  // into `fresh`, planned for `threads`: the number of attempts, negative when every one failed.
  // Touches only `workspace` and `fresh`.
  static int FactorNumerically(const Matrix& symmetric, int threads, Factor* workspace,
                               FactorSnapshot* fresh);
  void Adopt(std::shared_ptr<FactorSnapshot> fresh, const Eigen::Matrix3d& rotation, int attempts,
             Eigen::Index matrix_nonzeros);
  ThreadTeam* team_ = nullptr;
  std::unique_ptr<PendingFactorization> pending_;
  // CHOLMOD's factor, analysed for the pattern below; each factorisation refills it.
  std::unique_ptr<Factor> workspace_;
  std::shared_ptr<FactorSnapshot> current_;
  // A sparse matrix's pattern (outer and inner indices), to tell whether another has the same.
  struct Pattern {
    std::vector<int> outer, inner;
    bool Matches(const Matrix& a) const;
    void Assign(const Matrix& a);
  };
  Pattern analysed_pattern_;    // of workspace_'s symbolic analysis
  Pattern transposed_pattern_;  // of transpose_position_
  int num_factorizations_ = 0;
  RefactorisationRule refactor_rule_;  // for the current factor
  FlexibleGmres gmres_;
  Eigen::VectorXd rotated_;  // the preconditioner's work storage
  SubdomainCorrection correction_;
  // Products with a matrix passed to Solve, on team_.
  SparseMatrixOperator matrix_operator_;
};

}  // namespace softid::fem
