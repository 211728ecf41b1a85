#include "core/fem/refactorisation_rule.h"

namespace softid::fem {

void RefactorisationRule::Restart() {
  baseline_iterations_ = -1;
  excess_work_ = 0.0;
}

void RefactorisationRule::RecordSolve(int iterations, double work) {
  if (baseline_iterations_ < 0) baseline_iterations_ = iterations;
  if (iterations > baseline_iterations_) {
    excess_work_ += work * (iterations - baseline_iterations_) / iterations;
  }
}

}  // namespace softid::fem
