#include "core/diagnosis/decision.h"

#include <gtest/gtest.h>

namespace softid::diagnosis {
namespace {

CandidateTest Passing(Extension extension) {
  CandidateTest t;
  t.extension = extension;
  t.cost_before = 2e-5;
  t.cost_after = 1e-5;
  t.heldout_before = 2e-5;
  t.heldout_after = 1e-5;
  t.lr = 50.0;
  t.plausible = true;
  return t;
}

// Every gate of the pre-registered rule can reject on its own.
TEST(DecisionRule, EachGateRejects) {
  const DecisionOptions options;
  const Candidate& friction = GetCandidate(Extension::kFriction);
  CandidateTest t = Passing(Extension::kFriction);
  ApplyDecisionRule(options, friction, &t);
  EXPECT_TRUE(t.accepted) << t.Reason();
  EXPECT_NEAR(t.critical_value, 5.412, 1e-3);  // boundary mixture at 1 %

  CandidateTest weak = Passing(Extension::kFriction);
  weak.lr = 5.0;
  ApplyDecisionRule(options, friction, &weak);
  EXPECT_FALSE(weak.accepted);
  EXPECT_NE(weak.Reason().find("LR"), std::string::npos);

  CandidateTest heldout = Passing(Extension::kFriction);
  heldout.heldout_after = 0.95 * heldout.heldout_before;
  ApplyDecisionRule(options, friction, &heldout);
  EXPECT_FALSE(heldout.accepted);
  EXPECT_NE(heldout.Reason().find("held-out"), std::string::npos);

  CandidateTest residual = Passing(Extension::kFriction);
  residual.still_flagged = {"sliding"};
  ApplyDecisionRule(options, friction, &residual);
  EXPECT_FALSE(residual.accepted);
  EXPECT_NE(residual.Reason().find("sliding"), std::string::npos);

  CandidateTest implausible = Passing(Extension::kFriction);
  implausible.plausible = false;
  ApplyDecisionRule(options, friction, &implausible);
  EXPECT_FALSE(implausible.accepted);

  CandidateTest vague = Passing(Extension::kFriction);
  vague.identifiable = false;
  ApplyDecisionRule(options, friction, &vague);
  EXPECT_FALSE(vague.accepted);
}

// The stiffness split axis is chosen among 3 on the same data: its level is alpha / 3.
TEST(DecisionRule, BonferroniForChosenVariants) {
  CandidateTest t = Passing(Extension::kHeterogeneousStiffness);
  ApplyDecisionRule(DecisionOptions(), GetCandidate(Extension::kHeterogeneousStiffness), &t);
  EXPECT_GT(t.critical_value, 6.635);  // chi2_1 at 1 % / 3
}

// Not flagged -> none; a winning nuisance -> none; nothing accepted -> unexplained; otherwise the
// accepted physics with the largest LR.
TEST(DecisionRule, Decide) {
  int winner = 0;
  EXPECT_EQ(Decide(false, {}, &winner), "none");
  EXPECT_EQ(winner, -1);
  CandidateTest friction = Passing(Extension::kFriction);
  CandidateTest drag = Passing(Extension::kAirDrag);
  CandidateTest spin = Passing(Extension::kInitialSpin);
  for (CandidateTest* t : {&friction, &drag, &spin}) {
    ApplyDecisionRule(DecisionOptions(), GetCandidate(t->extension), t);
    ASSERT_TRUE(t->accepted);
  }
  drag.lr = 80.0;
  EXPECT_EQ(Decide(true, {friction, drag}, &winner), "air_drag");
  EXPECT_EQ(winner, 1);
  spin.lr = 200.0;
  EXPECT_EQ(Decide(true, {friction, spin}, &winner), "none");
  EXPECT_EQ(winner, 1);
  friction.accepted = false;
  EXPECT_EQ(Decide(true, {friction}, &winner), "unexplained");
}

TEST(DecisionOptions, ValidateNamesTheField) {
  DecisionOptions options;
  options.misfit_threshold = 0.9;
  EXPECT_NE(options.Validate().message().find("decision.misfit_threshold = 0.9"), std::string::npos)
      << options.Validate().message();
  options = DecisionOptions();
  options.alpha = 0.7;
  EXPECT_NE(options.Validate().message().find("decision.alpha"), std::string::npos);
}

}  // namespace
}  // namespace softid::diagnosis
