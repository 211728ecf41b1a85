#include "core/diagnosis/decision.h"

#include <cmath>
#include <sstream>

#include "core/common/json_fields.h"
#include "core/diagnosis/likelihood_ratio.h"

namespace softid::diagnosis {

Status DecisionOptions::Validate() const {
  if (!(misfit_threshold > 1.0) || !std::isfinite(misfit_threshold))
    return json::Invalid("decision.misfit_threshold", misfit_threshold, "must be > 1");
  if (!(alpha > 0.0 && alpha < 0.5))
    return json::Invalid("decision.alpha", alpha, "must lie in (0, 0.5)");
  if (!(min_heldout_improvement >= 0.0 && min_heldout_improvement < 1.0))
    return json::Invalid("decision.min_heldout_improvement", min_heldout_improvement,
                         "must lie in [0, 1)");
  if (min_phase_frames < 1)
    return json::Invalid("decision.min_phase_frames", min_phase_frames, "must be >= 1");
  if (min_patch_points < 1)
    return json::Invalid("decision.min_patch_points", min_patch_points, "must be >= 1");
  if (!(min_excess_explained > 0.0 && min_excess_explained <= 1.0))
    return json::Invalid("decision.min_excess_explained", min_excess_explained,
                         "must lie in (0, 1]");
  if (max_refits < 1) return json::Invalid("decision.max_refits", max_refits, "must be >= 1");
  return Status::Ok();
}

std::string CandidateTest::Reason() const {
  if (accepted) return "";
  if (!refit_error.empty()) return "refit failed: " + refit_error;
  std::ostringstream why;
  auto sep = [&] { return why.tellp() > 0 ? "; " : ""; };
  if (!lr_passed) why << sep() << "LR " << lr << " <= critical " << critical_value;
  if (!heldout_passed) {
    why << sep() << "held-out cost changed by "
        << (heldout_before > 0 ? 100.0 * (heldout_after / heldout_before - 1.0) : 0.0) << " %";
  }
  if (!misfit_passed) {
    why << sep() << "still above the noise level:";
    for (const std::string& s : still_flagged) why << " " << s;
    why << " (" << 100.0 * excess_explained << " % of the misfit above the noise removed)";
  }
  if (!plausible) why << sep() << "implausible: " << plausibility_note;
  if (!identifiable) why << sep() << "not identifiable: " << identifiability_note;
  if (!step_passed) {
    why << sep() << "the improvement does not hold at half the step: LR there " << lr_at_finer_step
        << " <= critical " << critical_value;
  }
  return why.str();
}

void ApplyDecisionRule(const DecisionOptions& options, const Candidate& candidate,
                       CandidateTest* test) {
  test->nuisance = candidate.nuisance;
  test->critical_value = ChiBarSquareCriticalValue(candidate.num_added, candidate.num_boundary,
                                                   options.alpha / candidate.num_variants);
  test->lr_passed = test->refit_error.empty() && test->lr > test->critical_value;
  // Without held-out frames there is nothing to validate on: the gate cannot pass.
  test->heldout_passed =
      test->heldout_before > 0.0 &&
      test->heldout_after <= (1.0 - options.min_heldout_improvement) * test->heldout_before;
  const double excess = test->cost_before - test->floor_cost;
  test->excess_explained = excess > 0.0 ? (test->cost_before - test->cost_after) / excess : 0.0;
  test->returned_to_noise = test->refit_error.empty() && test->still_flagged.empty();
  test->misfit_passed =
      test->returned_to_noise ||
      (test->refit_error.empty() && test->excess_explained >= options.min_excess_explained);
  test->step_passed = !test->step_checked || test->lr_at_finer_step > test->critical_value;
  test->accepted = test->refit_error.empty() && test->lr_passed && test->heldout_passed &&
                   test->misfit_passed && test->plausible && test->identifiable &&
                   test->step_passed;
}

void ApplyNuisanceCheck(const DecisionOptions& options, const Candidate& nuisance,
                        CandidateTest* conditional) {
  conditional->nuisance_critical_value = ChiBarSquareCriticalValue(
      nuisance.num_added, nuisance.num_boundary, options.alpha / nuisance.num_variants);
  conditional->nuisance_needed =
      conditional->refit_error.empty() &&
      conditional->nuisance_lr > conditional->nuisance_critical_value &&
      conditional->physics_heldout > 0.0 &&
      conditional->heldout_after <=
          (1.0 - options.min_heldout_improvement) * conditional->physics_heldout;
}

namespace {

// The conditional test of physics `physics` given nuisance `nuisance`, -1 when none was run.
int FindConditional(const std::vector<CandidateTest>& tests, Extension physics,
                    Extension nuisance) {
  for (size_t i = 0; i < tests.size(); ++i)
    if (tests[i].conditional && tests[i].extension == physics && tests[i].given == nuisance)
      return static_cast<int>(i);
  return -1;
}

}  // namespace

std::string Decide(bool flagged, const std::vector<CandidateTest>& tests, int* winner) {
  *winner = -1;
  if (!flagged) return "none";
  // Step 2: per physics extension the test it stands on, if any.
  std::vector<int> standing;
  for (const Candidate& physics : CandidateLibrary()) {
    if (physics.nuisance) continue;
    int alone = -1;  // accepted against the base
    for (size_t i = 0; i < tests.size(); ++i)
      if (!tests[i].conditional && tests[i].extension == physics.extension && tests[i].accepted)
        alone = static_cast<int>(i);
    int chosen = alone;
    bool stands = true;
    for (const Candidate& nuisance : CandidateLibrary()) {
      if (!nuisance.nuisance) continue;
      int accepted_nuisance = -1;
      for (size_t i = 0; i < tests.size(); ++i)
        if (!tests[i].conditional && tests[i].extension == nuisance.extension && tests[i].accepted)
          accepted_nuisance = static_cast<int>(i);
      const int c = FindConditional(tests, physics.extension, nuisance.extension);
      if (c < 0) {
        // No joint fit: only the likelihood ratios against the base can be compared.
        if (accepted_nuisance >= 0)
          stands = stands && alone >= 0 && tests[alone].lr > tests[accepted_nuisance].lr;
        continue;
      }
      const CandidateTest& given = tests[c];
      const bool imitated = alone >= 0 && given.lr_passed && !given.nuisance_needed;
      if (given.accepted) {
        // The joint model: the nuisance's parameters stay in whenever it is fitted (they are
        // nuisance parameters; leaving them out would bias the physics' value).
        chosen = c;
      } else if (!imitated && accepted_nuisance >= 0) {
        stands = false;  // the nuisance explains the mismatch; the physics adds nothing decisive
      }
    }
    if (stands && chosen >= 0) standing.push_back(chosen);
  }
  for (int i : standing)
    if (*winner < 0 || tests[i].lr > tests[*winner].lr) *winner = i;
  if (*winner >= 0) return ToString(tests[*winner].extension);
  for (size_t i = 0; i < tests.size(); ++i)
    if (!tests[i].conditional && tests[i].nuisance && tests[i].accepted &&
        (*winner < 0 || tests[i].lr > tests[*winner].lr))
      *winner = static_cast<int>(i);
  return *winner >= 0 ? "none" : "unexplained";
}

}  // namespace softid::diagnosis
