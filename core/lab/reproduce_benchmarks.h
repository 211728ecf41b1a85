// The benchmarks of `softid-lab reproduce`: the paper's Table 1 (Weiss et al. CVPR 2020,
// falling torus, Young's modulus only) and three multi-parameter experiments, as data: which scene,
// which cameras per row, what is fitted from which random starts, how a recovered value is scored,
// the accuracy targets and the paper's figures to print next to ours.
//
// Protocol shared by all benchmarks (so rows are comparable with the paper's):
//  - the capture is synthesised by our simulator (core/scenes) at the grid and time step the fit
//    uses (same cells, same substeps): the benchmark measures the identification, not the
//    discretisation error between two resolutions;
//  - the parameters not fitted are fixed at their true values;
//  - a run "converged" when every judged quantity is within its convergence limit (the paper's
//    rule for Table 1: relative error < 10 %); a row reports, per quantity, the mean error over
//    the converged runs and the fraction of runs that converged;
//  - a row meets its target when every run converged and every judged quantity's mean error is
//    within its target.
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "core/capture/depth_noise.h"
#include "core/common/status.h"
#include "core/fem/physical_parameters.h"
#include "core/inverse/job_config.h"

namespace softid::lab::reproduce {

// How a recovered value is compared with the truth.
enum class Metric {
  kRelative,            // |p - p*| / |p*| of a scalar [-]
  kVectorRelative,      // |v - v*| / |v*| [-]
  kRatioRelative,       // relative error of youngs_modulus / density [-] (what E-rho scaling keeps)
  kNormalAngleDegrees,  // angle between ground normals [deg]
  kOffsetMillimetres,   // |d - d*| of the ground offset [mm]
};

// The quantities a benchmark scores: a parameter name ("youngs_modulus", "gravity", "density"
// printed as "mass"), "ground_plane.normal", "ground_plane.offset" or "youngs_modulus/density".
struct Quantity {
  std::string name;
  std::string label;  // printed
  Metric metric = Metric::kRelative;
  double target = 0.01;  // in the metric's unit: 0.01 = 1 %, degrees, mm
  // Judged quantities decide convergence and the verdict; the others are printed for information
  // (e.g. E and beta of the bouncing ball, which only their combination may determine).
  bool judged = true;
};

// A convergence limit per metric: the paper's 10 % for relative errors; for the plane, limits of
// the same looseness (5 degrees, 10 mm: several times the targets).
double ConvergenceLimit(Metric metric);
// The error of `value` against `truth` in the metric's unit.
double ScoreError(const Quantity& quantity, const fem::PhysicalParameters& value,
                  const fem::PhysicalParameters& truth);
// "%" for relative metrics (errors are printed * 100), "deg", "mm".
const char* MetricUnit(Metric metric);
double MetricDisplayScale(Metric metric);  // 100 for relative metrics, 1 otherwise

struct PaperFigure {
  double error_percent = 0.0;
  double converged_percent = 0.0;
  std::string note;  // which entry of Table 1
};

struct Row {
  std::string id;
  std::string label;
  int cameras = 1;
  int width = 50, height = 50;  // [px]
  inverse::GradientMethod gradient = inverse::GradientMethod::kAdjoint;
  std::optional<PaperFigure> paper;
  bool in_quick = false;  // part of --quick when no --rows are given
};

struct Benchmark {
  std::string name;   // table1, ball-bounce, pillow-ramp, bar-hanging
  std::string scene;  // built-in scene
  std::string description;
  std::vector<Row> rows;
  std::vector<std::string> fit;  // fitted parameter names
  std::vector<Quantity> quantities;
  int starts = 20;              // random starts per row
  int quick_starts = 3;         // with --quick
  int cells = 16;               // grid of the generator and the fit
  int substeps = 2;             // steps per frame, generator and fit
  double fps = 60.0;            // frames per second of the capture [1/s]
  double duration = 0.0;        // [s]; 0 = the scene's own
  double quick_duration = 0.0;  // [s] with --quick; 0 = as duration
  int max_iterations = 50;
  // Levenberg-Marquardt iterations after L-BFGS per start (SolverOptions::refine_iterations): the
  // coupled multi-parameter fits need them to leave the valleys L-BFGS creeps along.
  int refine_iterations = 0;
  capture::DepthNoiseOptions noise;
  double depth_scale = 1e-3;  // [m] per PNG unit
  // The capture leaves mass_kg out, so that density (the mass) can be fitted.
  bool fit_mass = false;
  // Run the identifiability analysis at the best start and print its verdict for these variables.
  std::vector<std::string> identifiability_focus;
  // Wall-time target of one start [s] (0: none): the row then also reports the slowest start's
  // wall time against it. Starts that run alone get every core (SolverOptions::threads).
  double start_seconds_target = 0.0;
};

// The benchmark named `name`; InvalidArgument listing the known names otherwise.
Result<Benchmark> MakeBenchmark(const std::string& name);
std::vector<std::string> BenchmarkNames();

// The initial values of start `index` (public JSON form per fitted name, for JobConfig::initial),
// drawn from `rng`: positive scalars log-uniformly over [0.1, 10] x truth (the paper's Table 1
// range); gravity with its magnitude scaled by U[0.7, 1.3] and its direction tilted by up to 20
// degrees; the ground plane tilted by up to 10 degrees, its offset moved by up to +-2 cm.
nlohmann::json DrawStart(const Benchmark& benchmark, const fem::PhysicalParameters& truth,
                         std::mt19937_64& rng);

// What a run sets for each of its starts, beside the benchmark's own settings.
struct StartSettings {
  int max_iterations = 0;     // optimiser iterations
  int refine_iterations = 0;  // Levenberg-Marquardt iterations after L-BFGS
  int cores = 1;              // threads of the start's simulation
  std::string frame_loss;     // the job config's cost.frame_loss; empty: the job default
};

// The job config of one start: `fit`, the start values, every other parameter fixed at the truth
// (density only when the capture has no mass), the benchmark's grid and time step, one start.
Result<inverse::JobConfig> MakeStartConfig(const Benchmark& benchmark, const Row& row,
                                           const fem::PhysicalParameters& truth,
                                           const nlohmann::json& initial, bool capture_has_mass,
                                           const StartSettings& settings);

}  // namespace softid::lab::reproduce
