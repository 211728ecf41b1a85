// Restarted flexible GMRES with right preconditioning (Saad 1993): solves a x = b for a square
// operator `a` given by its products, with a preconditioner z = P^-1 r that is itself a linear
// operator. The preconditioned basis Z is kept, so the preconditioner may be inexact (a
// reduced-precision factor) without costing the solution's accuracy: A Z = V H holds to round-off.
// Work storage is kept between solves (no allocation per solve once sized).
#pragma once

#include <Eigen/Core>

#include "core/fem/linear_operator.h"

namespace softid::fem {

struct GmresOptions {
  double relative_tolerance = 1e-10;  // ||A x - b|| <= tol ||b||, > 0
  int max_iterations = 500;           // total, over restarts, >= 0
  int restart = 40;                   // Krylov basis size before a restart, >= 1
};

struct GmresSummary {
  int iterations = 0;
  double relative_residual = -1.0;  // the last one known (recurrence or true residual)
  bool converged = false;           // relative_residual <= 10 x tolerance
  // Work of the solve in the units of LinearOperator::ApplyWork (memory-bound flops): the
  // operators' products and the Gram-Schmidt, update and residual vector operations.
  double work = 0.0;
};

class FlexibleGmres {
 public:
  // Solves a x = b; x holds the initial guess on entry (a zero guess saves the first product).
  // @pre a.size() == preconditioner.size() == b.size()
  GmresSummary Solve(LinearOperator& a, LinearOperator& preconditioner, const Eigen::VectorXd& b,
                     const GmresOptions& options, Eigen::VectorXd* x);

 private:
  // Sizes the work storage for n unknowns and a basis of m.
  void Reserve(Eigen::Index n, int m);
  // One cycle of at most `m` iterations from the residual in r_ (norm beta): x += Z y. Returns
  // the recurrence's relative residual; adds its iterations and work to `summary`.
  double Cycle(LinearOperator& a, LinearOperator& preconditioner, double beta, double b_norm,
               const GmresOptions& options, Eigen::VectorXd* x, GmresSummary* summary);

  // Krylov basis V, preconditioned basis Z, Hessenberg matrix H, Givens rotations and the rotated
  // residual g; r and w are the residual and a product.
  Eigen::MatrixXd basis_, preconditioned_;
  Eigen::MatrixXd hessenberg_;
  Eigen::VectorXd givens_c_, givens_s_, g_;
  Eigen::VectorXd r_, w_;
};

}  // namespace softid::fem
