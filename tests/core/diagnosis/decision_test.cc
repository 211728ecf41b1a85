#include "core/diagnosis/decision.h"

#include <gtest/gtest.h>

#include "core/diagnosis/likelihood_ratio.h"

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

  // Gate f: an improvement that vanishes at half the step rejects; unchecked, nothing is assumed.
  CandidateTest step_bound = Passing(Extension::kFriction);
  step_bound.step_checked = true;
  step_bound.lr_at_finer_step = 3.0;
  ApplyDecisionRule(options, friction, &step_bound);
  EXPECT_FALSE(step_bound.accepted);
  EXPECT_FALSE(step_bound.step_passed);
  EXPECT_NE(step_bound.Reason().find("half the step"), std::string::npos);
  step_bound.lr_at_finer_step = 30.0;
  ApplyDecisionRule(options, friction, &step_bound);
  EXPECT_TRUE(step_bound.accepted) << step_bound.Reason();
}

// Gate c on physics another code wrote: cells the codes' own difference keeps above the threshold
// do not reject a candidate that removes most of the base's misfit above the noise floor (the
// numbers of a CalculiX ramp with friction 0.3), while one that removes half of it (the best
// candidate on the same ramp without friction) stays rejected.
TEST(DecisionRule, ACandidateThatRemovesMostOfTheExcessPassesGateC) {
  const DecisionOptions options;
  CandidateTest friction = Passing(Extension::kFriction);
  friction.cost_before = 2.218e-5;
  friction.cost_after = 1.891e-6;
  friction.floor_cost = 0.5 * 0.588e-3 * 0.588e-3;
  friction.still_flagged = {"patch 0 (-y top)", "impact"};
  ApplyDecisionRule(options, GetCandidate(Extension::kFriction), &friction);
  EXPECT_NEAR(friction.excess_explained, 0.922, 1e-3);
  EXPECT_FALSE(friction.returned_to_noise);
  EXPECT_TRUE(friction.misfit_passed);
  EXPECT_TRUE(friction.accepted) << friction.Reason();

  CandidateTest split = Passing(Extension::kHeterogeneousStiffness);
  split.cost_before = 4.843e-7;
  split.cost_after = 3.416e-7;
  split.floor_cost = 0.5 * 0.6056e-3 * 0.6056e-3;
  split.still_flagged = {"patch 3 (+x top)"};
  ApplyDecisionRule(options, GetCandidate(Extension::kHeterogeneousStiffness), &split);
  EXPECT_NEAR(split.excess_explained, 0.475, 1e-3);
  EXPECT_FALSE(split.accepted);
  EXPECT_NE(split.Reason().find("47.4"), std::string::npos) << split.Reason();

  // At min_excess_explained 1 only a fit down to the noise floor passes with cells still flagged.
  DecisionOptions strict;
  strict.min_excess_explained = 1.0;
  ApplyDecisionRule(strict, GetCandidate(Extension::kFriction), &friction);
  EXPECT_FALSE(friction.accepted);
  // A base already at the floor has no excess to explain.
  CandidateTest at_floor = Passing(Extension::kFriction);
  at_floor.floor_cost = at_floor.cost_before;
  at_floor.still_flagged = {"sliding"};
  ApplyDecisionRule(options, GetCandidate(Extension::kFriction), &at_floor);
  EXPECT_EQ(at_floor.excess_explained, 0.0);
  EXPECT_FALSE(at_floor.accepted);
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

// The situation of a 2x stiffness contrast whose release also fits a small spin: both improve the
// fit against the base and pass every gate there; the spin's LR is the larger one (its residuals
// are less correlated, so its n_eff is larger), which is no evidence between two models that are
// not nested.
struct SpinAndStiffness {
  CandidateTest spin = Passing(Extension::kInitialSpin);
  CandidateTest stiffness = Passing(Extension::kHeterogeneousStiffness);
  SpinAndStiffness() {
    spin.cost_after = 1.80e-6;
    spin.heldout_after = 1.77e-6;
    spin.lr = 3000.0;
    stiffness.cost_after = 1.57e-6;
    stiffness.heldout_after = 1.61e-6;
    stiffness.lr = 2000.0;
    ApplyDecisionRule(DecisionOptions(), GetCandidate(Extension::kInitialSpin), &spin);
    ApplyDecisionRule(DecisionOptions(), GetCandidate(Extension::kHeterogeneousStiffness),
                      &stiffness);
  }
  // The joint refit (base + spin + stiffness) tested against the spin model (the null) and
  // checked against the stiffness model; n_eff as the refits have it.
  CandidateTest Joint(double cost, double heldout, double n_eff = 4000.0) const {
    CandidateTest t = Passing(Extension::kHeterogeneousStiffness);
    t.conditional = true;
    t.given = Extension::kInitialSpin;
    t.cost_before = spin.cost_after;
    t.heldout_before = spin.heldout_after;
    t.cost_after = cost;
    t.heldout_after = heldout;
    t.n_eff = n_eff;
    t.lr = LikelihoodRatioStatistic(t.cost_before, t.cost_after, n_eff);
    t.physics_cost = stiffness.cost_after;
    t.physics_heldout = stiffness.heldout_after;
    t.nuisance_lr = LikelihoodRatioStatistic(t.physics_cost, t.cost_after, n_eff);
    ApplyDecisionRule(DecisionOptions(), GetCandidate(Extension::kHeterogeneousStiffness), &t);
    ApplyNuisanceCheck(DecisionOptions(), GetCandidate(Extension::kInitialSpin), &t);
    return t;
  }
};

// The nuisance's own test: both its LR against the physics model and the held-out gate must pass
// for it to be needed once the physics is in; its critical value is chi2_3 at 1 %.
TEST(DecisionRule, NuisanceCheckNeedsLikelihoodAndHeldOut) {
  const SpinAndStiffness s;
  const CandidateTest needed = s.Joint(1.30e-6, 1.40e-6);
  EXPECT_NEAR(needed.nuisance_critical_value, 11.345, 1e-3);
  EXPECT_TRUE(needed.nuisance_needed) << needed.nuisance_lr;
  // Fits the fitted frames better, the held-out frames hardly: not needed.
  EXPECT_FALSE(s.Joint(1.30e-6, 1.59e-6).nuisance_needed);
  // Held-out better but the fitted cost barely moves (LR = 4000 log(1.57 / 1.566) ~ 10 < 11.3).
  EXPECT_FALSE(s.Joint(1.566e-6, 1.40e-6).nuisance_needed);
}

// Without a joint fit the larger LR against the base decides: the spin, "none" (the behaviour
// that missed the 2x contrast). With the joint fit the stiffness is tested given the spin.
TEST(DecisionRule, PhysicsIsTestedGivenTheNuisance) {
  const SpinAndStiffness s;
  int winner = -1;
  EXPECT_EQ(Decide(true, {s.spin, s.stiffness}, &winner), "none");
  EXPECT_EQ(winner, 0);

  // Given the spin the stiffness passes every gate, and the spin is still needed given the
  // stiffness: the physics is found in the joint model.
  const CandidateTest both = s.Joint(1.30e-6, 1.40e-6);
  ASSERT_TRUE(both.accepted) << both.Reason();
  ASSERT_TRUE(both.nuisance_needed);
  EXPECT_EQ(Decide(true, {s.spin, s.stiffness, both}, &winner), "heterogeneous_stiffness");
  EXPECT_EQ(winner, 2);
  // Accepted given the spin while the spin does not pass its held-out gate given the stiffness:
  // still the joint model (the spin's parameters are nuisance parameters, fitted when they lower
  // the cost significantly; leaving them out would bias the stiffness ratio).
  const CandidateTest joint = s.Joint(1.50e-6, 1.58e-6);
  ASSERT_TRUE(joint.accepted) << joint.Reason();
  ASSERT_FALSE(joint.nuisance_needed);
  EXPECT_EQ(Decide(true, {s.spin, s.stiffness, joint}, &winner), "heterogeneous_stiffness");
  EXPECT_EQ(winner, 2);

  // Given the spin the stiffness lowers the cost significantly but the held-out frames by only
  // 1.61 / 1.77 - 1 = 9 % (< 10 %: the spin model is already close to the noise floor), while the
  // spin adds nothing to the stiffness model: the spin only imitated the physics, which stands
  // on its own refit.
  const CandidateTest imitated = s.Joint(1.565e-6, 1.61e-6);
  ASSERT_FALSE(imitated.accepted);
  ASSERT_TRUE(imitated.lr_passed);
  ASSERT_FALSE(imitated.nuisance_needed);
  EXPECT_EQ(Decide(true, {s.spin, s.stiffness, imitated}, &winner), "heterogeneous_stiffness");
  EXPECT_EQ(winner, 1);
}

// The nuisance explains the mismatch: the physics adds nothing significant given it (LR below the
// critical value), or it fails given the nuisance while the nuisance is still needed given it.
// Either way the decision is "none" with the nuisance, never the physics.
TEST(DecisionRule, NuisanceThatExplainsEverythingIsNeverPhysics) {
  const SpinAndStiffness s;
  int winner = -1;
  CandidateTest nothing = s.Joint(1.7995e-6, 1.77e-6);  // LR = 4000 log(1.8 / 1.7995) ~ 1
  ASSERT_FALSE(nothing.lr_passed);
  EXPECT_EQ(Decide(true, {s.spin, s.stiffness, nothing}, &winner), "none");
  EXPECT_EQ(winner, 0);

  CandidateTest still_flagged = s.Joint(1.30e-6, 1.40e-6);
  still_flagged.still_flagged = {"rebound"};
  ApplyDecisionRule(DecisionOptions(), GetCandidate(Extension::kHeterogeneousStiffness),
                    &still_flagged);
  ASSERT_TRUE(still_flagged.nuisance_needed);
  EXPECT_EQ(Decide(true, {s.spin, s.stiffness, still_flagged}, &winner), "none");
  EXPECT_EQ(winner, 0);

  // A physics candidate that was not accepted on its own and fails given the nuisance.
  CandidateTest weak_alone = s.stiffness;
  weak_alone.still_flagged = {"impact"};
  ApplyDecisionRule(DecisionOptions(), GetCandidate(Extension::kHeterogeneousStiffness),
                    &weak_alone);
  EXPECT_EQ(Decide(true, {s.spin, weak_alone, nothing}, &winner), "none");
}

// Neither model explains everything alone (each leaves the other's signature, and removes under
// min_excess_explained of the base's cost above the floor: 70 % and 75 %), the joint model does:
// the physics is found given the nuisance.
TEST(DecisionRule, JointModelExplainsWhatNeitherDoesAlone) {
  SpinAndStiffness s;
  s.spin.cost_after = 6.0e-6;
  s.stiffness.cost_after = 5.0e-6;
  s.spin.still_flagged = {"flight"};
  s.stiffness.still_flagged = {"rebound"};
  for (CandidateTest* t : {&s.spin, &s.stiffness}) {
    ApplyDecisionRule(DecisionOptions(), GetCandidate(t->extension), t);
    ASSERT_FALSE(t->accepted);
  }
  int winner = -1;
  EXPECT_EQ(Decide(true, {s.spin, s.stiffness}, &winner), "unexplained");
  const CandidateTest both = s.Joint(1.30e-6, 1.40e-6);
  EXPECT_EQ(Decide(true, {s.spin, s.stiffness, both}, &winner), "heterogeneous_stiffness");
  EXPECT_EQ(winner, 2);
}

TEST(DecisionOptions, ValidateNamesTheField) {
  DecisionOptions options;
  options.misfit_threshold = 0.9;
  EXPECT_NE(options.Validate().message().find("decision.misfit_threshold = 0.9"), std::string::npos)
      << options.Validate().message();
  options = DecisionOptions();
  options.alpha = 0.7;
  EXPECT_NE(options.Validate().message().find("decision.alpha"), std::string::npos);
  options = DecisionOptions();
  options.min_excess_explained = 0.0;
  EXPECT_NE(options.Validate().message().find("decision.min_excess_explained = 0"),
            std::string::npos)
      << options.Validate().message();
}

}  // namespace
}  // namespace softid::diagnosis
