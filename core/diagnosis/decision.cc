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
  if (!returned_to_noise) {
    why << sep() << "still above the noise level:";
    for (const std::string& s : still_flagged) why << " " << s;
  }
  if (!plausible) why << sep() << "implausible: " << plausibility_note;
  if (!identifiable) why << sep() << "not identifiable: " << identifiability_note;
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
  test->returned_to_noise = test->refit_error.empty() && test->still_flagged.empty();
  test->accepted = test->refit_error.empty() && test->lr_passed && test->heldout_passed &&
                   test->returned_to_noise && test->plausible && test->identifiable;
}

std::string Decide(bool flagged, const std::vector<CandidateTest>& tests, int* winner) {
  *winner = -1;
  if (!flagged) return "none";
  for (size_t i = 0; i < tests.size(); ++i) {
    if (!tests[i].accepted) continue;
    if (*winner < 0 || tests[i].lr > tests[*winner].lr) *winner = static_cast<int>(i);
  }
  if (*winner < 0) return "unexplained";
  if (tests[*winner].nuisance) return "none";
  return ToString(tests[*winner].extension);
}

}  // namespace softid::diagnosis
