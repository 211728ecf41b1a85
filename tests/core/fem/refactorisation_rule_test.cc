#include "core/fem/refactorisation_rule.h"

#include <gtest/gtest.h>

namespace softid::fem {
namespace {

// The first solve after a factorisation sets the baseline; only the share of later solves' work
// spent in iterations above it counts towards a new factorisation.
TEST(RefactorisationRule, CountsOnlyTheWorkAboveTheFirstSolve) {
  RefactorisationRule rule;
  rule.RecordSolve(10, 100.0);  // baseline: 10 iterations
  EXPECT_FALSE(rule.Pays(0.0));
  rule.RecordSolve(8, 80.0);  // fewer than the baseline: nothing
  EXPECT_FALSE(rule.Pays(0.0));
  rule.RecordSolve(15, 150.0);  // 5 of 15 iterations above it: 50
  EXPECT_TRUE(rule.Pays(49.0));
  EXPECT_FALSE(rule.Pays(50.0));
  rule.RecordSolve(20, 200.0);  // 10 of 20: another 100
  EXPECT_TRUE(rule.Pays(149.0));
  EXPECT_FALSE(rule.Pays(150.0));
}

TEST(RefactorisationRule, RestartForgetsTheBaselineAndTheExcess) {
  RefactorisationRule rule;
  rule.RecordSolve(2, 20.0);
  rule.RecordSolve(40, 400.0);
  EXPECT_TRUE(rule.Pays(100.0));
  rule.Restart();
  EXPECT_FALSE(rule.Pays(0.0));
  rule.RecordSolve(40, 400.0);  // the new baseline
  EXPECT_FALSE(rule.Pays(0.0));
}

}  // namespace
}  // namespace softid::fem
