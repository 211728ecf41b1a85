#include "core/diagnosis/report.h"

#include <cmath>
#include <sstream>

#include "core/common/json_fields.h"

namespace softid::diagnosis {
namespace {

nlohmann::json Number(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

nlohmann::json ToJson(const Localization& l) {
  nlohmann::json phases = nlohmann::json::array();
  for (const PhaseMisfit& p : l.phases) {
    phases.push_back({{"phase", ToString(p.phase)},
                      {"frames", p.frames},
                      {"first_frame", p.first_frame},
                      {"last_frame", p.last_frame},
                      {"misfit", p.normalised},
                      {"flagged", p.flagged}});
  }
  nlohmann::json patches = nlohmann::json::array();
  for (const PatchMisfit& p : l.patches) {
    patches.push_back({{"patch", p.patch},
                       {"label", p.label},
                       {"centre", json::FromVector3(p.centre)},
                       {"points", p.points},
                       {"misfit", p.normalised},
                       {"flagged", p.flagged}});
  }
  return {{"flagged", l.flagged},
          {"onset_frame", l.onset_frame},
          {"worst_frame", l.worst_frame},
          {"threshold", l.threshold},
          {"phases", phases},
          {"patches", patches}};
}

nlohmann::json ToJson(const CandidateTest& t) {
  return {{"lr", t.lr},
          {"critical_value", t.critical_value},
          {"n_eff", t.n_eff},
          {"tau_pixels", t.tau_pixels},
          {"tau_frames", t.tau_frames},
          {"lr_passed", t.lr_passed},
          {"heldout_passed", t.heldout_passed},
          {"returned_to_noise", t.returned_to_noise},
          {"step_free_cost_before", t.step_free_cost_before},
          {"step_free_cost_after", t.step_free_cost_after},
          {"excess_explained", t.excess_explained},
          {"misfit_passed", t.misfit_passed},
          {"still_flagged", t.still_flagged},
          {"plausible", t.plausible},
          {"plausibility_note", t.plausibility_note},
          {"identifiability_checked", t.identifiability_checked},
          {"identifiable", t.identifiable},
          {"identifiability_note", t.identifiability_note},
          {"step_checked", t.step_checked},
          {"cost_before_at_finer_step", t.cost_before_at_finer_step},
          {"cost_after_at_finer_step", t.cost_after_at_finer_step},
          {"lr_at_finer_step", t.lr_at_finer_step},
          {"step_passed", t.step_passed},
          {"accepted", t.accepted},
          {"reason", t.Reason()}};
}

// The conditional part of a test given a nuisance (decision.h, step 2), null otherwise.
nlohmann::json ConditionalJson(const CandidateTest& t) {
  if (!t.conditional) return nullptr;
  return {{"given", ToString(t.given)},
          {"physics_cost", t.physics_cost},
          {"physics_heldout", t.physics_heldout},
          {"nuisance_lr", t.nuisance_lr},
          {"nuisance_critical_value", t.nuisance_critical_value},
          {"nuisance_needed", t.nuisance_needed}};
}

std::string Fixed(double v, int digits = 3) {
  std::ostringstream s;
  s.precision(digits);
  s << v;
  return s.str();
}

std::string Join(const std::vector<std::string>& v) {
  std::string out;
  for (const std::string& s : v) out += (out.empty() ? "" : ", ") + s;
  return out.empty() ? "-" : out;
}

// The missing physics the diagnosis found, with where the base model missed.
// The finding's values are the final refit's on the job's discretisation when there was one
// ("compared_parameters": the refit's on the comparison's).
nlohmann::json FindingJson(const DiagnosisReport& r, const TestedCandidate& w) {
  const bool refitted = !r.final_values.is_null();
  return {{"physics", ToString(w.test.extension)},
          {"parameters", refitted ? r.final_values : w.values},
          {"compared_parameters", w.values},
          {"uncertainty", w.uncertainty},
          {"profile", w.profile},
          {"cost_before", w.test.cost_before},
          {"cost_after", w.test.cost_after},
          {"heldout_before", w.test.heldout_before},
          {"heldout_after", w.test.heldout_after},
          {"base_cost", r.base_cost},
          {"base_heldout", r.base_heldout},
          {"given", ConditionalJson(w.test)},
          {"onset_frame", r.before.onset_frame},
          {"phases", r.before.FlaggedPhaseNames()},
          {"regions", r.before.FlaggedPatchLabels()},
          {"test", ToJson(w.test)}};
}

// Per observed frame: its phase and misfit before and after the winning refit.
nlohmann::json FramesJson(const DiagnosisReport& r) {
  nlohmann::json frames = nlohmann::json::array();
  for (size_t k = 0; k < r.frames.size(); ++k) {
    frames.push_back({{"frame", r.frames[k]},
                      {"heldout", static_cast<bool>(r.heldout[k])},
                      {"phase", k < r.motion.size() ? ToString(r.motion[k].phase) : "?"},
                      {"time", k < r.motion.size() ? r.motion[k].time : 0.0},
                      {"before", r.before.frame_normalised.at(k)},
                      {"after", r.after.frame_normalised.at(k)}});
  }
  return frames;
}

nlohmann::json ScreenedJson(const ScreenedCandidate& s) {
  return {{"extension", ToString(s.extension)},
          {"axis",
           s.axis >= 0 ? nlohmann::json(std::string(1, "xyz"[s.axis])) : nlohmann::json(nullptr)},
          {"applicable", s.applicable},
          {"note", s.note},
          {"gradient", s.gradient},
          {"curvature", s.curvature},
          {"efficient_curvature", s.efficient_curvature},
          {"start_theta", s.theta},
          {"start_cost", Number(s.start_cost)},
          {"predicted_lr", s.predicted_lr},
          {"signature_share", s.signature_share},
          {"score", s.score}};
}

nlohmann::json CandidateJson(const TestedCandidate& t) {
  return {{"extension", ToString(t.test.extension)},
          {"nuisance", t.test.nuisance},
          {"parameters", t.values},
          {"uncertainty", t.uncertainty},
          {"profile", t.profile},
          {"cost_before", t.test.cost_before},
          {"cost_after", t.test.cost_after},
          {"heldout_before", t.test.heldout_before},
          {"heldout_after", t.test.heldout_after},
          {"refit_error", t.test.refit_error},
          {"null_refit", t.null_refit},
          {"given", ConditionalJson(t.test)},
          {"nuisance_parameters", t.nuisance_values},
          {"starts", t.starts},
          {"fit", t.fit},
          {"test", ToJson(t.test)},
          {"residual_after", ToJson(t.after)}};
}

// Where the base model misses: the onset, the worst frame and each phase's misfit.
void WriteMismatchText(const Localization& b, std::ostream& out) {
  if (!b.flagged) {
    out << "the base model fits to the noise level: no phase or patch above " << b.threshold
        << " x the floor (worst frame " << b.worst_frame << ")\n";
  } else {
    out << "mismatch: begins at frame " << b.onset_frame << ", worst at frame " << b.worst_frame
        << "; phases " << Join(b.FlaggedPhaseNames()) << "; patches "
        << Join(b.FlaggedPatchLabels()) << "\n";
    for (const PhaseMisfit& p : b.phases) {
      out << "  " << ToString(p.phase) << " (frames " << p.first_frame << "-" << p.last_frame
          << "): " << Fixed(p.normalised) << " x floor" << (p.flagged ? "  <-" : "") << "\n";
    }
  }
}

void WriteScreenedText(const ScreenedCandidate& s, std::ostream& out) {
  out << "  screened " << ToString(s.extension)
      << (s.axis >= 0 ? std::string(" (") + "xyz"[s.axis] + ")" : std::string()) << ": "
      << (s.applicable ? "score " + Fixed(s.score) + ", predicted LR " + Fixed(s.predicted_lr) +
                             ", signature " + Fixed(s.signature_share, 2)
                       : "not applicable")
      << (s.note.empty() ? "" : " (" + s.note + ")") << "\n";
}

// A refit with a candidate: its values, costs and test, and what a conditional nuisance added.
void WriteRefitText(const TestedCandidate& t, std::ostream& out) {
  out << "  refit " << ToString(t.test.extension)
      << (t.test.conditional ? std::string(" given ") + ToString(t.test.given) : std::string())
      << ": " << t.values.dump();
  if (!t.uncertainty.is_null()) out << " +- " << t.uncertainty.dump();
  if (t.profile.is_object() && t.profile.value("relative_uncertainty", -1.0) > 0.0)
    out << " (profile: +- " << Fixed(100.0 * t.profile["relative_uncertainty"].get<double>(), 2)
        << " %)";
  out << "\n    cost " << Fixed(t.test.cost_before) << " -> " << Fixed(t.test.cost_after)
      << " m^2, held-out " << Fixed(t.test.heldout_before) << " -> " << Fixed(t.test.heldout_after)
      << " m^2, LR " << Fixed(t.test.lr) << " (critical " << Fixed(t.test.critical_value) << ")"
      << (t.test.accepted ? ": accepted" : ": rejected: " + t.test.Reason());
  if (t.test.accepted && !t.test.returned_to_noise) {
    out << " (removes " << Fixed(100.0 * t.test.excess_explained)
        << " % of the misfit above the noise; still above it:";
    for (const std::string& s : t.test.still_flagged) out << " " << s;
    out << ")";
  }
  out << "\n";
  if (t.test.conditional) {
    out << "    " << ToString(t.test.given) << " given " << ToString(t.test.extension) << ": "
        << t.nuisance_values.dump() << ", cost " << Fixed(t.test.physics_cost) << " -> "
        << Fixed(t.test.cost_after) << " m^2, held-out " << Fixed(t.test.physics_heldout) << " -> "
        << Fixed(t.test.heldout_after) << " m^2, LR " << Fixed(t.test.nuisance_lr) << " (critical "
        << Fixed(t.test.nuisance_critical_value)
        << "): " << (t.test.nuisance_needed ? "still needed" : "adds nothing") << "\n";
  }
}

// "models compared on 10 cells, 4 substeps; final model refitted on 16 cells, 16 substeps (309 s)".
void WriteComparedAtText(const nlohmann::json& compared_at, std::ostream& out) {
  if (!compared_at.is_object()) return;
  out << "models compared on " << compared_at.value("cells", 0) << " cells, "
      << compared_at.value("substeps", 0) << " substeps per frame";
  if (compared_at.contains("predictable_last_frame")) {
    out << ", up to frame " << compared_at["predictable_last_frame"].get<int>()
        << " (after it halving the step no longer converges: no affordable step predicts the "
           "motion)";
  }
  if (compared_at.contains("final_refit")) {
    const nlohmann::json& refit = compared_at["final_refit"];
    if (refit.contains("error")) {
      out << "; the final refit on the job's discretisation failed: "
          << refit["error"].get<std::string>();
    } else if (refit.contains("skipped")) {
      out << "; not refitted on the job's discretisation (" << refit["skipped"].get<std::string>()
          << "): the final values are the compared optimum's";
    } else if (refit.contains("reused")) {
      out << "; final model: " << refit["reused"].get<std::string>() << " on "
          << refit.value("cells", 0) << " cells, " << refit.value("substeps", 0) << " substeps";
    } else {
      out << "; final model refitted on " << refit.value("cells", 0) << " cells, "
          << refit.value("substeps", 0) << " substeps (" << Fixed(refit.value("seconds", 0.0))
          << " s";
      if (refit.contains("stopped_at_time_limit_s")) {
        const int iterations = refit.value("iterations", 0);
        out << "; stopped after " << iterations << " iteration(s) at the diagnosis' time budget: "
            << (iterations == 0 ? "its values are the compared optimum's"
                                : "its values lie between the compared optimum and the job's");
      }
      out << ")";
    }
  }
  out << "\n";
}

}  // namespace

nlohmann::json ToJson(const DiagnosisReport& r) {
  nlohmann::json out;
  out["format"] = kDiagnosisFormat;
  out["decision"] = r.decision;
  out["findings"] = nlohmann::json::array();
  if (r.winner >= 0 && !r.tested[r.winner].test.nuisance) {
    out["findings"].push_back(FindingJson(r, r.tested[r.winner]));
  }
  out["nuisances"] = r.nuisances;
  out["mismatch"] = ToJson(r.before);
  out["mismatch"]["frames"] = FramesJson(r);
  out["residual_after"] = ToJson(r.after);
  out["noise_floor"] = {{"sigma", r.noise_floor.sigma},
                        {"method", r.noise_floor.method},
                        {"frame0_misfit", r.noise_floor.frame0_misfit},
                        {"quantile_misfit", r.noise_floor.quantile_misfit},
                        {"frame0_excess", r.noise_floor.frame0_excess}};
  out["base"] = {{"cost", r.base_cost}, {"heldout", r.base_heldout}, {"n_eff", r.n_eff}};
  out["screening"] = nlohmann::json::array();
  for (const ScreenedCandidate& s : r.screening) out["screening"].push_back(ScreenedJson(s));
  out["candidates"] = nlohmann::json::array();
  for (const TestedCandidate& t : r.tested) out["candidates"].push_back(CandidateJson(t));
  out["base_restarts"] = r.base_restarts;
  out["base_fit"] = r.base_fit;
  out["final_fit"] = r.final_fit;
  out["compared_at"] = r.compared_at;
  out["time_step_error"] = r.time_step_error ? ToJson(*r.time_step_error) : nlohmann::json();
  out["identifiability"] = r.identifiability;
  out["plots"] = r.plots;
  out["seconds"] = r.seconds;
  out["screening_seconds"] = r.screening_seconds;
  return out;
}

std::string ToText(const DiagnosisReport& r) {
  std::ostringstream out;
  out << "decision: " << r.decision << "\n";
  out << "noise floor: " << Fixed(1e3 * r.noise_floor.sigma) << " mm (" << r.noise_floor.method
      << "); base cost " << Fixed(r.base_cost) << " m^2, held-out " << Fixed(r.base_heldout)
      << " m^2, n_eff " << Fixed(r.n_eff) << "\n";
  WriteMismatchText(r.before, out);
  for (const ScreenedCandidate& s : r.screening) WriteScreenedText(s, out);
  for (size_t i = 0; i < r.tested.size(); ++i) WriteRefitText(r.tested[i], out);
  if (r.winner >= 0 && !r.tested[r.winner].test.nuisance) {
    const TestedCandidate& w = r.tested[r.winner];
    out << "missing physics: " << ToString(w.test.extension) << " "
        << (r.final_values.is_null() ? w.values : r.final_values).dump()
        << (w.test.conditional ? std::string(" (given ") + ToString(w.test.given) + ")"
                               : std::string())
        << "; held-out cost down " << Fixed(100.0 * (1.0 - w.test.heldout_after / r.base_heldout))
        << " % from the base\n";
  }
  for (const auto& n : r.nuisances) out << "nuisance: " << n.dump() << "\n";
  for (const auto& b : r.base_restarts) {
    out << "base fit restarted: cost " << b.value("cost_before", 0.0) << " -> "
        << b.value("cost_after", 0.0) << " m^2 (null model refitted from the "
        << b.value("via", std::string()) << " refit; first decision "
        << b.value("first_decision", std::string()) << ")\n";
  }
  WriteComparedAtText(r.compared_at, out);
  if (r.time_step_error) {
    out << "compared time step: " << r.time_step_error->finer_substeps
        << " substeps per frame move the residuals by " << Fixed(r.time_step_error->change_m * 1e3)
        << " mm RMS, " << Fixed(r.time_step_error->unabsorbed_m * 1e3)
        << " mm beyond what the base parameters absorb; that component is left out of each "
           "frame's misfit before the phases and patches are judged\n";
  }
  if (!r.plots.empty()) out << "plots: " << Join(r.plots) << "\n";
  return out.str();
}

}  // namespace softid::diagnosis
