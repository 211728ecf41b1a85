#include "core/lab/diagnosis_runner.h"

#include <spdlog/spdlog.h>

namespace softid::lab {

diagnosis::DiagnoseOptions DiagnoseOptionsForLab(const inverse::JobConfig& config,
                                                 const std::string& prefix) {
  diagnosis::DiagnoseOptions options;
  options.on_stage = [prefix](const std::string& stage) {
    spdlog::info("{}diagnosis: {}", prefix, stage);
  };
  const int max_iterations = config.solver.max_iterations;
  options.fit.on_progress = [prefix, max_iterations](const inverse::FitProgress& p) {
    spdlog::debug("{}  it {:>3}/{} cost {:.4e} |g| {:.2e} ({:.0f} s)", prefix, p.iteration,
                  max_iterations, p.cost, p.gradient_norm, p.elapsed_seconds);
  };
  return options;
}

}  // namespace softid::lab
