// When to renew a preconditioner's factor: the ski-rental rule, and the work model it counts in.
//
// A factor of the reference matrix preconditions the step systems of many steps (linear_solver.h),
// but each solve on an older factor needs more GMRES iterations. The rule renews the factor once
// the iterations spent beyond what the fresh factor needed cost as much as one factorisation: never
// worse than twice the best offline choice. Work is counted by a deterministic model, never timed,
// so that the same inputs refactorise at the same solves and a cost evaluated twice is bitwise the
// same (line searches, finite differences).
#pragma once

namespace softid::fem {

// The work model, in "memory-bound flops": the flops of sparse products, triangular solves and
// vector updates, which all run at about the same rate (bounded by memory traffic). A
// factorisation's flops run as dense BLAS-3 blocks, several times faster; kFactorFlopWeight
// converts them. Measured on the idle 2-core AMD EPYC dev host (OpenBLAS 0.3.21, CHOLMOD 3.0.14
// with its OpenMP regions serialised, torus-drop at 3100 cells: 12.9k unknowns, nnz(A) 0.85e6,
// nnz(L) 3.5e6, 1.48e9 factorisation flops): Factorize 90-100 ms (~16 GFlop/s), one
// preconditioner application 1.4 ms, one product with A 0.6 ms: a factorisation costs ~45
// iterations, which the weight 0.28 reproduces (0.15 and 0.4 measured no better in bench). The
// rule only needs the ratio to within a factor of ~1.5: a wrong weight shifts the balance between
// refactorisations and extra iterations, never the result's accuracy.
inline constexpr double kFactorFlopWeight = 0.28;
// The solves run on the reduced-precision copy of L: in single precision they measured 1.7x
// faster than CHOLMOD's double solves on the same host and problem (4.3 vs 7.5 ms under the same
// load), with the blocks below the diagonal in half precision another ~1.4x (BM_Precondition,
// interleaved runs: 0.75-0.9 vs 1.2 ms). With the weight 0.6 of single precision the rule
// refactorised as before, now that iterations are cheaper too often: 0.4 ran pillow-ramp (1 s),
// ball-bounce (0.5 s) and torus-drop's impact (0.3 s) 21 %, 12 % and 3 % faster, torus-drop over
// 1 s 30 % slower (a factor taken at the impact then served its rest).
inline constexpr double kReducedPrecisionSolveWeight = 0.4;
// Forming the symmetric part and CHOLMOD's permuted transpose before each factorisation:
// ~10 memory-bound flops per entry of A.
inline constexpr double kFactorWorkPerMatrixEntry = 10.0;

class RefactorisationRule {
 public:
  // A new factor became current: the counts start over.
  void Restart();
  // A solve on the current factor took `iterations` and `work` (work-model units). The first
  // solve after a restart sets the baseline; later ones add the share of their work spent in
  // iterations above it.
  void RecordSolve(int iterations, double work);
  // Whether the excess work so far exceeds `factor_work`, one factorisation's work.
  bool Pays(double factor_work) const { return excess_work_ > factor_work; }

 private:
  int baseline_iterations_ = -1;  // of the first solve after the factorisation; -1: none yet
  double excess_work_ = 0.0;      // GMRES work beyond the baseline since the factorisation
};

}  // namespace softid::fem
