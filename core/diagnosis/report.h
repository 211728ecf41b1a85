// The diagnosis report as JSON (diagnosis.json, format "softid-diagnosis/1") and as text.
//
// diagnosis.json:
//   {"format": "softid-diagnosis/1",
//    "decision": "friction" | "heterogeneous_stiffness" | "air_drag" | "contact" | "none" |
//                "unexplained",
//    "findings": [{"physics": "friction", "parameters": {"friction_coefficient": 0.29},
//                  "uncertainty": {"friction_coefficient": 0.01}, "cost_before": .., "cost_after":
//                  .., "heldout_before": .., "heldout_after": .., "base_cost": ..,
//                  "base_heldout": .., "given": null | {"given": "initial_spin", "nuisance_lr",
//                  "nuisance_critical_value", "nuisance_needed", "physics_cost",
//                  "physics_heldout"}, "onset_frame": 4, "phases": ["sliding"], "regions":
//                  ["patch 2 (-x bottom)"], "test": {..}}],
//    (a finding "given" a nuisance was tested against the nuisance's refit: cost_before and
//     heldout_before are that model's; decision.h step 2)
//    "nuisances": [{"nuisance": "initial_spin", "parameters": {..}, "accepted_alone": ..,
//                   "explains_mismatch": .., "needed_given_physics": .. (when physics was found
//                   given it), "parameters_in_final_model": {..} (when the final model holds it),
//                   ..}],
//    "mismatch": {"flagged": .., "onset_frame": .., "worst_frame": .., "phases": [..],
//                 "patches": [..], "frames": [{"frame", "time", "heldout", "phase", "before",
//                 "after"}]},
//    "noise_floor": {"sigma": .., "method": .., "frame0_misfit": .., "quantile_misfit": ..},
//    "screening": [..], "candidates": [..],      // every screened / refitted candidate (with
//                                                // "given", "nuisance_parameters", "starts")
//    "base_fit": {result.json}, "final_fit": {result.json}, "identifiability": {..} | null,
//    "plots": [..], "seconds": ..}
// Costs are in m^2 (mean Tukey loss over the frames' points), misfits normalised by the floor.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "core/diagnosis/diagnose.h"

namespace softid::diagnosis {

inline constexpr const char* kDiagnosisFormat = "softid-diagnosis/1";

nlohmann::json ToJson(const DiagnosisReport& report);
// A few paragraphs for people: decision, where and when, what was missing and its value with
// uncertainty, costs before and after on fitted and held-out frames, and why others were rejected.
std::string ToText(const DiagnosisReport& report);

}  // namespace softid::diagnosis
