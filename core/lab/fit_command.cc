// softid-lab fit: recover physical parameters from a capture (see core/inverse/fit.h); with
// "diagnose": true in the job config, the diagnosis of left-out physics follows (core/diagnosis).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <variant>

#include "core/capture/capture.h"
#include "core/diagnosis/diagnose.h"
#include "core/diagnosis/fit_report.h"
#include "core/diagnosis/report.h"
#include "core/inverse/fit.h"
#include "core/inverse/fit_uncertainty.h"
#include "core/inverse/grid_refinement.h"
#include "core/inverse/job_config.h"
#include "core/lab/commands.h"
#include "core/lab/diagnosis_runner.h"
#include "core/lab/fit_inputs.h"
#include "core/lab/result_report.h"

namespace softid::lab {
namespace {

struct FitFlags {
  std::string capture;
  std::string config;
  std::string out = "result.json";
  std::string report;  // default: <out's folder>/report
  bool no_report = false;
};

// The fit's pictures (core/diagnosis/fit_report.h) into the report folder, recorded in the
// result as "report". A report that cannot be drawn is a warning: the fitted values stand.
void AddFitReport(const FitFlags& flags, const capture::Capture& capture,
                  const inverse::JobConfig& config, const inverse::FitResult& fit,
                  nlohmann::json* json) {
  if (flags.no_report || fit.cancelled) return;
  const std::filesystem::path out(flags.out);
  const std::filesystem::path dir =
      !flags.report.empty() ? std::filesystem::path(flags.report)
                            : (out.has_parent_path() ? out.parent_path() : ".") / "report";
  Result<diagnosis::FitReport> report = diagnosis::WriteFitReport(capture, config, fit, dir);
  if (!report.ok()) {
    spdlog::warn("report: {}", report.status().message());
    (*json)["report"] = {{"error", report.status().message()}};
    return;
  }
  spdlog::info("report: {} pictures in {} ({:.1f} s)", report->files.size(), dir.string(),
               report->seconds);
  (*json)["report"] = diagnosis::ToJson(*report);
}

// The fit with what the config asks after it, and its result.json: each value's uncertainty
// (two forward and adjoint runs per fitted variable, logged next to the fit's own time) and,
// with "refine_grid", the refit on a finer grid where the grid moves a value.
struct AnalysedFit {
  inverse::FitResult fit;
  inverse::JobConfig config;  // what `fit` was computed with
  nlohmann::json json;
};

AnalysedFit AnalyseFit(const capture::Capture& capture, const inverse::JobConfig& config,
                       inverse::FitResult fit, const inverse::FitOptions& options) {
  if (!config.uncertainty || fit.cancelled) {
    nlohmann::json json = inverse::ToJson(fit);
    return {std::move(fit), config, std::move(json)};
  }
  Result<inverse::FitUncertainty> uncertainty =
      inverse::EstimateFitUncertainty(capture, config, fit);
  if (!uncertainty.ok()) {
    spdlog::warn("uncertainty: {}", uncertainty.status().message());
    nlohmann::json json = inverse::ToJson(fit, nullptr, uncertainty.status().message());
    return {std::move(fit), config, std::move(json)};
  }
  spdlog::info("uncertainty: {} evaluations in {:.1f} s ({:.0f} % of the fit's {:.1f} s)",
               uncertainty->report.evaluations, uncertainty->report.seconds,
               100.0 * uncertainty->report.seconds / std::max(1e-9, fit.total_seconds),
               fit.total_seconds);
  if (!config.refine_grid) {
    nlohmann::json json = inverse::ToJson(fit, &*uncertainty);
    return {std::move(fit), config, std::move(json)};
  }
  inverse::ControlledFit controlled = inverse::ControlGrid(capture, config, std::move(fit),
                                                           std::move(uncertainty).value(), options);
  nlohmann::json json =
      controlled.uncertainty
          ? inverse::ToJson(controlled.fit, &*controlled.uncertainty)
          : inverse::ToJson(controlled.fit, nullptr, controlled.uncertainty_error);
  json["grid_refinement"] = inverse::ToJson(controlled.refinement);
  return {std::move(controlled.fit), std::move(controlled.config), std::move(json)};
}

// One line per optimiser iteration.
void LogFitProgress(const inverse::FitProgress& p, const std::vector<std::string>& fitted) {
  // Continuation over the horizon: the cost is over the frames up to the stage's last one.
  const std::string stage =
      p.num_stages > 1
          ? fmt::format(" [frames 0-{}, stage {}/{}]", p.horizon_frame, p.stage + 1, p.num_stages)
          : "";
  // Newton misses make the cost depend on the iteration path: shown when there are any.
  const std::string misses =
      p.unconverged_steps > 0
          ? fmt::format(" | {} of {} steps unconverged", p.unconverged_steps, p.simulation_steps)
          : "";
  spdlog::info("start {}/{} it {:>3}/{} cost {:.4e}{} |g| {:.2e} {} | {:.0f} s, ~{:.0f} s left{}",
               p.start + 1, p.num_starts, p.iteration, p.max_iterations, p.cost, stage,
               p.gradient_norm, FormatParameters(p.parameters, fitted), p.elapsed_seconds,
               p.remaining_seconds, misses);
}

// "diagnose": true: look for left-out physics after the fit, report next to the result.
int DiagnoseAfterFit(const FitFlags& flags, const capture::Capture& capture,
                     const inverse::JobConfig& config, const inverse::FitResult& fit) {
  const std::filesystem::path out(flags.out);
  const std::filesystem::path dir = out.has_parent_path() ? out.parent_path() : ".";
  diagnosis::DiagnoseOptions diagnose_options = DiagnoseOptionsForLab(config);
  diagnose_options.plot_directory = dir / "diagnosis_plots";
  Result<diagnosis::DiagnosisReport> report =
      diagnosis::Diagnose(capture, config, diagnose_options, &fit);
  if (!report.ok()) {
    spdlog::error("diagnosis: {}", report.status().message());
    return kExitFailure;
  }
  const std::filesystem::path report_file = dir / "diagnosis.json";
  const Status report_written = WriteJsonFile(report_file, diagnosis::ToJson(*report));
  if (!report_written.ok()) {
    spdlog::error("{}", report_written.message());
    return kExitFailure;
  }
  std::printf("%s", diagnosis::ToText(*report).c_str());
  std::printf("diagnosis written to %s\n", report_file.string().c_str());
  return kExitOk;
}

int RunFit(const FitFlags& flags) {
  std::variant<FitInputs, int> loaded = LoadFitInputs(flags.capture, flags.config);
  if (const int* exit_code = std::get_if<int>(&loaded)) return *exit_code;
  const FitInputs& inputs = std::get<FitInputs>(loaded);
  const inverse::JobConfig& config = inputs.config;
  spdlog::info("fit: {} ({} frames, {} camera(s)); fitting {}; {} start(s), {} iterations max",
               flags.capture, inputs.capture.NumFrames(), inputs.capture.NumCameras(),
               fmt::join(config.fit, ", "), config.solver.starts, config.solver.max_iterations);

  inverse::FitOptions options;
  options.on_progress = [&](const inverse::FitProgress& p) { LogFitProgress(p, config.fit); };
  Result<inverse::FitResult> result = inverse::Fit(inputs.capture, config, options);
  if (!result.ok()) {
    spdlog::error("{}", result.status().message());
    return result.status().code() == StatusCode::kInvalidArgument ? kExitInvalidInput
                                                                  : kExitFailure;
  }
  AnalysedFit analysed = AnalyseFit(inputs.capture, config, std::move(result).value(), options);
  AddFitReport(flags, inputs.capture, analysed.config, analysed.fit, &analysed.json);
  const Status written = WriteJsonFile(flags.out, analysed.json);
  if (!written.ok()) {
    spdlog::error("{}", written.message());
    return kExitFailure;
  }
  PrintResultTable(analysed.json, std::filesystem::path(flags.capture) / "truth.json");
  std::printf("result written to %s\n", flags.out.c_str());
  if (!config.diagnose) return kExitOk;
  return DiagnoseAfterFit(flags, inputs.capture, analysed.config, analysed.fit);
}

}  // namespace

Command RegisterFit(CLI::App* app) {
  app->footer(
      "Examples:\n"
      "  softid-lab fit capture/ -o out/result.json                  # fits youngs_modulus; report "
      "in out/report\n"
      "  softid-lab fit capture/ --config job.json -o out/result.json --report pictures/");
  auto flags = std::make_shared<FitFlags>();
  app->add_option("capture", flags->capture, "capture folder (with capture.json)")->required();
  app->add_option("-c,--config", flags->config, "job config JSON (default: fit youngs_modulus)");
  app->add_option("-o,--out", flags->out, "result JSON to write")->capture_default_str();
  app->add_option("--report", flags->report,
                  "folder for the fit's pictures (default: report/ next to --out)");
  app->add_flag("--no-report", flags->no_report, "draw no pictures");
  return [flags] { return RunFit(*flags); };
}

}  // namespace softid::lab
