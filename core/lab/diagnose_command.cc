// softid-lab diagnose: fit the base model and look for left-out physics (core/diagnosis).
#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>
#include <variant>

#include "core/capture/capture.h"
#include "core/diagnosis/diagnose.h"
#include "core/diagnosis/report.h"
#include "core/inverse/job_config.h"
#include "core/lab/commands.h"
#include "core/lab/diagnosis_runner.h"
#include "core/lab/fit_inputs.h"
#include "core/lab/result_report.h"

namespace softid::lab {
namespace {

struct DiagnoseFlags {
  std::string capture;
  std::string config;
  std::string out = "diagnosis.json";
  std::string plots;  // default: <out dir>/diagnosis_plots
  int max_refits = 2;
  double max_seconds = diagnosis::DiagnoseOptions().max_seconds;
  bool no_identifiability = false;
  int compare_cells = diagnosis::DiagnoseOptions().comparison_cells;
  int compare_substeps = diagnosis::DiagnoseOptions().comparison_substeps;
};

int RunDiagnose(const DiagnoseFlags& flags) {
  std::variant<FitInputs, int> loaded = LoadFitInputs(flags.capture, flags.config);
  if (const int* exit_code = std::get_if<int>(&loaded)) return *exit_code;
  const FitInputs& inputs = std::get<FitInputs>(loaded);
  const inverse::JobConfig& config = inputs.config;
  diagnosis::DiagnoseOptions options = DiagnoseOptionsForLab(config);
  options.decision.max_refits = flags.max_refits;
  options.max_seconds = flags.max_seconds;
  options.identifiability = !flags.no_identifiability;
  options.comparison_cells = flags.compare_cells;
  options.comparison_substeps = flags.compare_substeps;
  const std::filesystem::path out(flags.out);
  options.plot_directory =
      flags.plots.empty() ? (out.has_parent_path() ? out.parent_path() : ".") / "diagnosis_plots"
                          : std::filesystem::path(flags.plots);
  Result<diagnosis::DiagnosisReport> report = diagnosis::Diagnose(inputs.capture, config, options);
  if (!report.ok()) {
    spdlog::error("{}", report.status().message());
    return report.status().code() == StatusCode::kInvalidArgument ? kExitInvalidInput
                                                                  : kExitFailure;
  }
  const Status written = WriteJsonFile(out, diagnosis::ToJson(*report));
  if (!written.ok()) {
    spdlog::error("{}", written.message());
    return kExitFailure;
  }
  std::printf("%s", diagnosis::ToText(*report).c_str());
  std::printf("diagnosis written to %s\n", flags.out.c_str());
  return kExitOk;
}

}  // namespace

Command RegisterDiagnose(CLI::App* app) {
  app->footer(
      "Example:\n"
      "  softid-lab diagnose capture/ --config job.json -o out/diagnosis.json   # plots in "
      "out/diagnosis_plots");
  auto flags = std::make_shared<DiagnoseFlags>();
  app->add_option("capture", flags->capture, "capture folder (with capture.json)")->required();
  app->add_option("-c,--config", flags->config, "job config JSON: its fit set is the base model");
  app->add_option("-o,--out", flags->out, "diagnosis JSON to write")->capture_default_str();
  app->add_option("--plots", flags->plots, "folder for the PNG plots (default: next to --out)");
  app->add_option("--max-refits", flags->max_refits, "candidates refitted after screening")
      ->capture_default_str()
      ->check(CLI::Range(1, 10));
  app->add_option("--max-seconds", flags->max_seconds,
                  "time budget [s]: the final refit on the job's grid and time step stops at its "
                  "first iteration past it (0 = none)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app->add_option("--compare-cells", flags->compare_cells,
                  "grid the models are compared on, at most (cells along the longest side; 0 = "
                  "the job's own)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app->add_option("--compare-substeps", flags->compare_substeps,
                  "time step the models are compared on, at most (substeps per frame; 0 = the "
                  "job's own)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  app->add_flag("--no-identifiability", flags->no_identifiability,
                "skip the identifiability analysis of the final model");
  return [flags] { return RunDiagnose(*flags); };
}

}  // namespace softid::lab
