// softid-lab prove-diagnosis: the concealed-effect benchmark of the diagnosis. Each case
// synthesises a capture with an effect on (core/scenes/diagnosis_scenes.h) on a finer grid and a
// smaller time step than the fit, with realistic depth noise, then diagnoses it with the effect
// off, and compares the decision with the truth. Prints a confusion table (true effect vs
// decision) and per case the recovered value and the held-out cost before and after.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include "core/capture/capture.h"
#include "core/common/json_fields.h"
#include "core/diagnosis/diagnose.h"
#include "core/diagnosis/report.h"
#include "core/inverse/job_config.h"
#include "core/lab/commands.h"
#include "core/lab/diagnosis_runner.h"
#include "core/lab/result_report.h"
#include "core/scenes/diagnosis_scenes.h"
#include "core/scenes/synthesize.h"

namespace softid::lab {
namespace {

struct ProveFlags {
  std::string out = "/tmp/softid-prove-diagnosis";
  std::vector<std::string> cases = {"friction", "heterogeneous_stiffness", "air_drag", "control",
                                    "initial_spin"};
  int seeds = 20;  // controls
  bool quick = false;
  int jobs = 1;
  int fit_cells = 10;
  // Steps per frame of the fit (the generator takes twice as many). At 2 the fit's time-step
  // error biased the values (friction 0.5 -> 0.41, halves 2x -> 2.8); at 4 they are within their
  // tolerances.
  int fit_substeps = 4;
  int generator_cells = 15;
  int max_iterations = 30;
  int max_refits = 2;
  bool keep = false;
  // Reuse the outcome of every case already finished in --out with the same settings (a long
  // benchmark run can stop and go on later).
  bool resume = false;
  // Run only the cases whose name contains one of these (e.g. "-2-" for the 2x stiffness case);
  // empty = all.
  std::vector<std::string> only;
};

struct Case {
  std::string name;  // unique, e.g. "friction-0.3"
  std::string scene;
  scenes::ConcealedEffect effect = scenes::ConcealedEffect::kNone;
  double strength = 0.0;
  int seed = 0;
};

struct Outcome {
  Case c;
  std::string decision = "error";
  std::string error;
  double recovered = std::nan("");  // mu, stiffness ratio or drag
  double heldout_before = 0.0, heldout_after = 0.0;
  double seconds = 0.0;
  std::string nuisances;
};

// The settings a finished case's outcome depends on (besides the code): a resumed run reuses an
// outcome only when they match.
nlohmann::json OutcomeSettings(const ProveFlags& flags) {
  return {{"fit_cells", flags.fit_cells},
          {"fit_substeps", flags.fit_substeps},
          {"generator_cells", flags.generator_cells},
          {"generator_substeps", 2 * flags.fit_substeps},
          {"max_iterations", flags.max_iterations},
          {"max_refits", flags.max_refits}};
}

constexpr const char* kOutcomeFormat = "softid-prove-outcome/1";

nlohmann::json OutcomeJson(const Outcome& o, const ProveFlags& flags) {
  return {{"format", kOutcomeFormat},
          {"case", o.c.name},
          {"settings", OutcomeSettings(flags)},
          {"decision", o.decision},
          {"error", o.error},
          {"recovered",
           std::isnan(o.recovered) ? nlohmann::json(nullptr) : nlohmann::json(o.recovered)},
          {"heldout_before", o.heldout_before},
          {"heldout_after", o.heldout_after},
          {"seconds", o.seconds},
          {"nuisances", o.nuisances}};
}

// The outcome a previous run left in the case's folder, if it is for this case and these
// settings and did not end in an error.
std::optional<Outcome> FinishedOutcome(const Case& c, const ProveFlags& flags,
                                       const std::filesystem::path& file) {
  if (!std::filesystem::exists(file)) return std::nullopt;
  try {
    const nlohmann::json j = nlohmann::json::parse(std::ifstream(file));
    if (j.value("format", "") != kOutcomeFormat || j.value("case", "") != c.name ||
        j.at("settings") != OutcomeSettings(flags) || !j.value("error", "").empty())
      return std::nullopt;
    Outcome o;
    o.c = c;
    o.decision = j.at("decision").get<std::string>();
    o.recovered = j.at("recovered").is_null() ? std::nan("") : j.at("recovered").get<double>();
    o.heldout_before = j.at("heldout_before").get<double>();
    o.heldout_after = j.at("heldout_after").get<double>();
    o.seconds = j.at("seconds").get<double>();
    o.nuisances = j.at("nuisances").get<std::string>();
    return o;
  } catch (const std::exception& e) {
    spdlog::warn("{}: unreadable ({}); the case runs again", file.string(), e.what());
    return std::nullopt;
  }
}

// What the experimenter fits in each scene (the base model): what the motion shows, nothing of
// the concealed effect. Starts are off the truth.
inverse::JobConfig BaseConfig(const std::string& scene, const ProveFlags& flags) {
  inverse::JobConfig config;
  if (scene == "light-throw") {
    config.fit = {"initial_velocity"};
    inverse::InitialValue v;
    v.value = nlohmann::json::array({1.8, 0.0, 2.6});
    config.initial["initial_velocity"] = v;
    // In free flight the stiffness hardly matters: a plausible guess.
    config.fixed = {{"youngs_modulus", 3e4}, {"stiffness_damping", 0.01}, {"poisson_ratio", 0.3}};
  } else {
    config.fit = {"youngs_modulus", "stiffness_damping"};
    inverse::InitialValue e, beta;
    e.value = scene == "ramp-block" ? 1e4 : 1.5e3;  // half the truth
    beta.value = 0.005;
    config.initial["youngs_modulus"] = e;
    config.initial["stiffness_damping"] = beta;
    config.fixed = {{"poisson_ratio", 0.3}};
  }
  config.solver.cells = flags.fit_cells;
  config.solver.substeps = flags.fit_substeps;
  config.heldout_every = 4;
  config.solver.starts = 1;
  config.solver.threads = 1;
  config.solver.max_iterations = flags.max_iterations;
  return config;
}

// The ground plane is known (calibrated) in every scene: fixed at the truth.
void FixGround(const scenes::Scene& scene, inverse::JobConfig* config) {
  config->fixed["ground"] =
      scene.parameters.ground ? fem::ToJson(*scene.parameters.ground) : nlohmann::json(nullptr);
}

std::vector<Case> MakeCases(const ProveFlags& flags) {
  std::vector<Case> out;
  auto want = [&](const std::string& name) {
    return std::find(flags.cases.begin(), flags.cases.end(), name) != flags.cases.end();
  };
  auto add = [&](const std::string& scene, scenes::ConcealedEffect effect, double strength,
                 int seed) {
    Case c;
    c.scene = scene;
    c.effect = effect;
    c.strength = strength;
    c.seed = seed;
    std::ostringstream name;
    name << scenes::ToString(effect) << "-" << scene << "-" << strength << "-s" << seed;
    c.name = name.str();
    out.push_back(c);
  };
  using scenes::ConcealedEffect;
  // One case of every kind first (a broken scene shows early), then the other strengths.
  if (want("friction")) add("ramp-block", ConcealedEffect::kFriction, 0.3, 1);
  if (want("heterogeneous_stiffness"))
    add("halves-drop", ConcealedEffect::kHeterogeneousStiffness, 4.0, 1);
  if (want("air_drag")) add("light-throw", ConcealedEffect::kAirDrag, 0.6, 1);
  if (want("initial_spin")) add("light-throw", ConcealedEffect::kInitialSpin, 4.0, 1);
  if (want("friction") && !flags.quick) {
    add("ramp-block", ConcealedEffect::kFriction, 0.1, 1);
    add("ramp-block", ConcealedEffect::kFriction, 0.5, 1);
  }
  if (want("heterogeneous_stiffness") && !flags.quick)
    add("halves-drop", ConcealedEffect::kHeterogeneousStiffness, 2.0, 1);
  if (want("control")) {
    const std::vector<std::string> names = scenes::DiagnosisSceneNames();
    for (int s = 0; s < flags.seeds; ++s)
      add(names[s % names.size()], ConcealedEffect::kNone, 0.0, 100 + s);
  }
  if (!flags.only.empty()) {
    std::erase_if(out, [&](const Case& c) {
      return std::none_of(flags.only.begin(), flags.only.end(), [&](const std::string& part) {
        return c.name.find(part) != std::string::npos;
      });
    });
  }
  return out;
}

// The case's scene with its effect on.
Result<scenes::ConcealedScene> MakeCaseScene(const Case& c) {
  // Controls vary the material by seed (+-20 %) so that they are not one motion with new noise.
  const double variation =
      c.effect == scenes::ConcealedEffect::kNone ? 0.2 * std::sin(12.9898 * c.seed) : 0.0;
  return scenes::MakeDiagnosisScene(c.scene, c.effect, c.strength, variation);
}

// Synthesises the case's capture into `dir` (emptied first) on the generator's grid and time
// step, with the seed's depth noise, and reads it back.
Result<capture::Capture> SynthesizeCaseCapture(const Case& c, const scenes::ConcealedScene& scene,
                                               const ProveFlags& flags,
                                               const std::filesystem::path& dir) {
  std::filesystem::remove_all(dir);
  scenes::SynthesisOptions synth;
  synth.run.simulation.cells_along_longest_side = flags.generator_cells;
  // Half the fit's time step, as the fit must not share the generator's discretisation.
  synth.run.substeps_per_frame = 2 * flags.fit_substeps;
  synth.cameras = scene.cameras;
  synth.noise = capture::StructuredLightNoise(static_cast<uint64_t>(c.seed));
  synth.depth_scale = capture::kStructuredLightDepthScale;
  Result<scenes::SynthesisSummary> written = scenes::Synthesize(scene.scene, synth, dir);
  if (!written.ok()) return written.status();
  return capture::ReadCapture(dir);
}

// Diagnoses the capture with the base model (the effect off), plots into `dir`.
Result<diagnosis::DiagnosisReport> DiagnoseCase(const Case& c, const scenes::ConcealedScene& scene,
                                                const capture::Capture& capture,
                                                const ProveFlags& flags,
                                                const std::filesystem::path& dir) {
  inverse::JobConfig config = BaseConfig(c.scene, flags);
  FixGround(scene.scene, &config);
  diagnosis::DiagnoseOptions options = DiagnoseOptionsForLab(config, "[" + c.name + "] ");
  options.decision.max_refits = flags.max_refits;
  // The models are compared on the fit's grid and time step (--fit-cells, --fit-substeps), which
  // the defaults (10, 4) make the diagnosis' own comparison discretisation.
  options.comparison_cells = 0;
  options.comparison_substeps = 0;
  options.plot_directory = dir / "diagnosis_plots";
  return diagnosis::Diagnose(capture, config, options);
}

// The decision, the held-out costs and the winner's recovered value into `o`.
void RecordDiagnosis(const diagnosis::DiagnosisReport& report, Outcome* o) {
  o->decision = report.decision;
  o->heldout_before = report.base_heldout;
  o->heldout_after = report.base_heldout;
  if (report.winner >= 0) {
    const diagnosis::TestedCandidate& w = report.tested[report.winner];
    o->heldout_after = w.test.heldout_after;
    const nlohmann::json& v = w.values;
    if (v.contains("friction_coefficient")) o->recovered = v["friction_coefficient"];
    if (v.contains("stiffness_ratio")) o->recovered = v["stiffness_ratio"];
    if (v.contains("drag_quadratic")) o->recovered = v["drag_quadratic"];
  }
  for (const auto& n : report.nuisances)
    o->nuisances += (o->nuisances.empty() ? "" : ",") + n["nuisance"].get<std::string>();
}

// Keep the report and plots, drop the depth images.
void DropDepthImages(const std::filesystem::path& dir) {
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    if (entry.is_directory() && entry.path().filename().string().rfind("cam", 0) == 0)
      std::filesystem::remove_all(entry.path());
}

Outcome RunCase(const Case& c, const ProveFlags& flags) {
  const std::filesystem::path dir = std::filesystem::path(flags.out) / c.name;
  if (flags.resume) {
    if (std::optional<Outcome> done = FinishedOutcome(c, flags, dir / "outcome.json")) {
      spdlog::info("[{}] finished earlier: decision {} (resumed)", c.name, done->decision);
      return *done;
    }
  }
  Outcome o;
  o.c = c;
  const auto begin = std::chrono::steady_clock::now();
  Result<scenes::ConcealedScene> scene = MakeCaseScene(c);
  if (!scene.ok()) {
    o.error = scene.status().message();
    return o;
  }
  Result<capture::Capture> capture = SynthesizeCaseCapture(c, *scene, flags, dir);
  if (!capture.ok()) {
    o.error = capture.status().message();
    return o;
  }
  Result<diagnosis::DiagnosisReport> report = DiagnoseCase(c, *scene, *capture, flags, dir);
  o.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
  if (!report.ok()) {
    o.error = report.status().message();
    return o;
  }
  (void)WriteJsonFile(dir / "diagnosis.json", diagnosis::ToJson(*report));
  RecordDiagnosis(*report, &o);
  if (!flags.keep) DropDepthImages(dir);
  // Written last: its presence means the case finished (what --resume looks for).
  (void)WriteJsonFile(dir / "outcome.json", OutcomeJson(o, flags));
  return o;
}

// False after logging the first --cases entry that names no kind of case.
bool KnownCaseKinds(const ProveFlags& flags) {
  for (const std::string& name : flags.cases) {
    if (name != "friction" && name != "heterogeneous_stiffness" && name != "air_drag" &&
        name != "control" && name != "initial_spin") {
      spdlog::error(
          "--cases = {}: unknown (known: friction, heterogeneous_stiffness, air_drag, "
          "control, initial_spin)",
          name);
      return false;
    }
  }
  return true;
}

// Runs every case, `flags.jobs` at a time, logging each outcome as it comes; in case order.
std::vector<Outcome> RunCases(const std::vector<Case>& cases, const ProveFlags& flags) {
  std::vector<Outcome> outcomes(cases.size());
  std::atomic<int> next{0};
  std::mutex log_mutex;
  auto worker = [&] {
    for (int i = next++; i < static_cast<int>(cases.size()); i = next++) {
      outcomes[i] = RunCase(cases[i], flags);
      std::lock_guard lock(log_mutex);
      const Outcome& o = outcomes[i];
      spdlog::info("case {}: decision {} ({:.0f} s){}", o.c.name, o.decision, o.seconds,
                   o.error.empty() ? "" : " error: " + o.error);
    }
  };
  {
    std::vector<std::jthread> pool;
    for (int t = 1; t < flags.jobs; ++t) pool.emplace_back(worker);
    worker();
  }
  return outcomes;
}

// Confusion table: true effect (rows) vs decision (columns).
void PrintConfusionTable(const std::vector<Outcome>& outcomes) {
  const std::vector<std::string> truths = {"friction", "heterogeneous_stiffness", "air_drag",
                                           "initial_spin", "none"};
  const std::vector<std::string> decisions = {
      "friction", "heterogeneous_stiffness", "air_drag", "contact", "none", "unexplained", "error"};
  std::map<std::string, std::map<std::string, int>> table;
  for (const Outcome& o : outcomes) table[scenes::ToString(o.c.effect)][o.decision]++;
  std::printf("\nconfusion table (rows: true effect, columns: decision)\n%-24s", "");
  for (const std::string& d : decisions) std::printf(" %12.12s", d.c_str());
  std::printf("\n");
  for (const std::string& t : truths) {
    if (table.count(t) == 0) continue;
    std::printf("%-24s", t.c_str());
    for (const std::string& d : decisions) std::printf(" %12d", table[t][d]);
    std::printf("\n");
  }
}

// The benchmark's scores over all cases.
struct ProveScores {
  int effect_cases = 0, effect_correct = 0, controls = 0, false_alarms = 0;
  int value_cases = 0, value_ok = 0, heldout_cases = 0, heldout_ok = 0;
};

// Scores one case: its decision, and when it found its physical effect, the held-out cost's
// drop (`down`, percent) and the recovered value.
void ScoreOutcome(const Outcome& o, double down, ProveScores* scores) {
  const std::string truth = scenes::ToString(o.c.effect);
  const bool physics = o.c.effect != scenes::ConcealedEffect::kNone &&
                       o.c.effect != scenes::ConcealedEffect::kInitialSpin;
  const bool correct = physics ? o.decision == truth : o.decision == "none";
  if (physics) {
    ++scores->effect_cases;
    scores->effect_correct += correct;
  } else {
    ++scores->controls;
    scores->false_alarms += !correct;
  }
  if (physics && o.decision == truth) {
    ++scores->heldout_cases;
    scores->heldout_ok += down >= 30.0;
    if (!std::isnan(o.recovered)) {
      ++scores->value_cases;
      if (o.c.effect == scenes::ConcealedEffect::kFriction)
        scores->value_ok += std::abs(o.recovered - o.c.strength) <= 0.05;
      else if (o.c.effect == scenes::ConcealedEffect::kHeterogeneousStiffness)
        scores->value_ok += std::abs(o.recovered / o.c.strength - 1.0) <= 0.25;
      else
        scores->value_ok += std::abs(o.recovered / o.c.strength - 1.0) <= 0.25;
    }
  }
}

// A case's entry in prove_diagnosis.json.
nlohmann::json CaseSummaryJson(const Outcome& o) {
  return {{"case", o.c.name},
          {"scene", o.c.scene},
          {"truth", scenes::ToString(o.c.effect)},
          {"strength", o.c.strength},
          {"decision", o.decision},
          {"recovered",
           std::isnan(o.recovered) ? nlohmann::json(nullptr) : nlohmann::json(o.recovered)},
          {"heldout_before", o.heldout_before},
          {"heldout_after", o.heldout_after},
          {"seconds", o.seconds},
          {"nuisances", o.nuisances},
          {"error", o.error}};
}

// A line per case, scoring each into `scores`; the cases' entries of the summary file.
nlohmann::json PrintCaseTable(const std::vector<Outcome>& outcomes, ProveScores* scores) {
  std::printf("\n%-48s %-24s %8s %9s %12s %12s %7s %7s  %s\n", "case", "decision", "true",
              "recovered", "heldout_bef", "heldout_aft", "down%", "s", "nuisances");
  nlohmann::json summary = nlohmann::json::array();
  for (const Outcome& o : outcomes) {
    const double down =
        o.heldout_before > 0 ? 100.0 * (1.0 - o.heldout_after / o.heldout_before) : 0.0;
    ScoreOutcome(o, down, scores);
    std::printf("%-48s %-24s %8.3g %9.3g %12.4g %12.4g %7.1f %7.0f  %s%s\n", o.c.name.c_str(),
                o.decision.c_str(), o.c.strength, o.recovered, o.heldout_before, o.heldout_after,
                down, o.seconds, o.nuisances.c_str(),
                o.error.empty() ? "" : (" " + o.error).c_str());
    summary.push_back(CaseSummaryJson(o));
  }
  return summary;
}

void PrintScores(const ProveScores& s) {
  std::printf("\neffect cases correct: %d/%d (target >= 90 %%)\n", s.effect_correct,
              s.effect_cases);
  std::printf("false alarms in controls (incl. spin): %d/%d (target <= 1 in 20)\n", s.false_alarms,
              s.controls);
  std::printf("recovered value within tolerance (mu +-0.05, ratio/drag +-25 %%): %d/%d\n",
              s.value_ok, s.value_cases);
  std::printf("held-out cost down >= 30 %% when found: %d/%d\n", s.heldout_ok, s.heldout_cases);
}

int RunProve(const ProveFlags& flags) {
  if (!KnownCaseKinds(flags)) return kExitInvalidInput;
  const std::vector<Case> cases = MakeCases(flags);
  spdlog::info("prove-diagnosis: {} case(s), {} at a time, work folder {}", cases.size(),
               flags.jobs, flags.out);
  const std::vector<Outcome> outcomes = RunCases(cases, flags);

  PrintConfusionTable(outcomes);
  ProveScores scores;
  const nlohmann::json summary = PrintCaseTable(outcomes, &scores);
  PrintScores(scores);
  (void)WriteJsonFile(std::filesystem::path(flags.out) / "prove_diagnosis.json",
                      {{"cases", summary},
                       {"effect_correct", scores.effect_correct},
                       {"effect_cases", scores.effect_cases},
                       {"false_alarms", scores.false_alarms},
                       {"controls", scores.controls}});
  return kExitOk;
}

}  // namespace

Command RegisterProveDiagnosis(CLI::App* app) {
  app->footer(
      "Example:\n"
      "  softid-lab prove-diagnosis --jobs 2 --out /tmp/prove [--resume]");
  auto flags = std::make_shared<ProveFlags>();
  app->add_option("--out", flags->out, "work folder (captures, reports, plots)")
      ->capture_default_str();
  app->add_option("--cases", flags->cases,
                  "friction, heterogeneous_stiffness, air_drag, control, initial_spin")
      ->delimiter(',')
      ->capture_default_str();
  app->add_option("--seeds", flags->seeds, "control seeds")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app->add_flag("--quick", flags->quick, "one strength per effect");
  app->add_option("--jobs", flags->jobs, "cases run at once")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app->add_option("--fit-cells", flags->fit_cells, "fit grid: cells along the longest side")
      ->capture_default_str();
  app->add_option("--fit-substeps", flags->fit_substeps, "fit: time steps per frame")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  app->add_option("--generator-cells", flags->generator_cells,
                  "generator grid (finer than the fit)")
      ->capture_default_str();
  app->add_option("--max-iterations", flags->max_iterations, "per fit")->capture_default_str();
  app->add_option("--max-refits", flags->max_refits, "candidates refitted per case")
      ->capture_default_str();
  app->add_option("--only", flags->only,
                  "run only the cases whose name contains one of these (comma-separated)")
      ->delimiter(',');
  app->add_flag("--keep", flags->keep, "keep the depth images of every case");
  app->add_flag("--resume", flags->resume,
                "reuse the outcome of every case already finished in --out with the same "
                "settings (run again: cases that ended in an error or never finished)");
  return [flags] { return RunProve(*flags); };
}

}  // namespace softid::lab
