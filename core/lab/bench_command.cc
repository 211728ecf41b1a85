// softid-lab bench: milliseconds per simulation step against the number of active cells, and the
// fitted scaling exponent. The torus-drop scene is timed over its first 0.3 s, which includes the
// impact (contact, refactorisation) as well as free flight.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <memory>

#include "core/fem/hex_mesh.h"
#include "core/fem/simulator.h"
#include "core/geometry/signed_distance_field.h"
#include "core/lab/commands.h"
#include "core/scenes/scene.h"
#include "core/scenes/scene_runner.h"

namespace softid::lab {
namespace {

// CPU seconds of the whole process (all threads): unlike wall time it barely moves when other
// work shares the machine, so runs stay comparable on a busy host.
double ProcessCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

struct BenchFlags {
  std::vector<int> target_cells = {1000, 3000, 10000, 30000};
  double seconds = 0.3;
  int substeps = 4;
  double fps = 60.0;
  bool adjoint = true;
  // One simulation on every core, as a single-start job runs; --threads 1 gives the per-core
  // figure of a machine filled with parallel starts.
  int threads = 0;
  // Runs per size: the host's speed varies by up to 1.5x from minute to minute, so single runs
  // are poor evidence. The table shows the best run and the median.
  int repeat = 1;
};

double Median(std::vector<double> values) {
  std::sort(values.begin(), values.end());
  if (values.empty()) return -1.0;
  const size_t half = values.size() / 2;
  return values.size() % 2 == 1 ? values[half] : 0.5 * (values[half - 1] + values[half]);
}

struct ForwardAdjointTiming {
  double ms = -1.0;              // wall [ms/step], forward and adjoint
  double cpu_ms = -1.0;          // process CPU [ms/step], forward and adjoint
  double adjoint_cpu_ms = -1.0;  // process CPU [ms/step], adjoint pass alone
};

// Milliseconds per step of a forward run that stores its states followed by the adjoint pass
// back through them (the fit's unit of work), with a cost gradient entering at every frame.
ForwardAdjointTiming ForwardAdjointMs(const scenes::Scene& scene, int resolution,
                                      const BenchFlags& flags) {
  ForwardAdjointTiming timing;
  fem::SimulationOptions options;
  options.cells_along_longest_side = resolution;
  options.time_step = 1.0 / (flags.fps * flags.substeps);
  options.threads = flags.threads;
  fem::Simulator sim(scene.mesh, scene.parameters, options, scene.fixed_region);
  const int steps = static_cast<int>(std::lround(flags.seconds / options.time_step));
  const auto start = std::chrono::steady_clock::now();
  const double cpu_start = ProcessCpuSeconds();
  std::vector<fem::SimulationState> states = {sim.state()};
  for (int k = 0; k < steps; ++k) {
    if (sim.Step().diverged) return timing;
    states.push_back(sim.state());
  }
  const double cpu_backward = ProcessCpuSeconds();
  const int size = static_cast<int>(states[0].u.size());
  fem::StateAdjoint adjoint{Eigen::VectorXd::Zero(size), Eigen::VectorXd::Zero(size),
                            Eigen::VectorXd::Zero(size)};
  fem::ParameterGradient gradient;
  const Eigen::VectorXd frame_gradient = Eigen::VectorXd::Constant(size, 1e-3);
  for (int k = steps; k >= 1; --k) {
    if (k % flags.substeps == 0) adjoint.u += frame_gradient;
    if (!sim.BackpropagateStep(states[k - 1], states[k], &adjoint, &gradient).ok()) return timing;
  }
  sim.BackpropagateInitialState(states[0], adjoint, &gradient);
  const double cpu_end = ProcessCpuSeconds();
  timing.ms =
      1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() / steps;
  timing.cpu_ms = 1e3 * (cpu_end - cpu_start) / steps;
  timing.adjoint_cpu_ms = 1e3 * (cpu_end - cpu_backward) / steps;
  return timing;
}

int ActiveCells(const scenes::Scene& scene, int cells_along_longest_side) {
  geometry::SignedDistanceOptions options;
  options.cells_along_longest_side = cells_along_longest_side;
  options.padding_cells = 1;
  auto sdf = geometry::ComputeSignedDistanceField(scene.mesh, options);
  if (!sdf.ok()) return 0;
  return fem::BuildHexMesh(*sdf, fem::SimulationOptions().min_cell_volume_fraction).NumElements();
}

// Resolution whose active-cell count is closest to `target` (cells scale like n^3).
int ResolutionFor(const scenes::Scene& scene, int target) {
  int n = 16;
  for (int it = 0; it < 3; ++it) {
    const int cells = ActiveCells(scene, n);
    if (cells <= 0) break;
    const int next =
        std::max(2, static_cast<int>(std::lround(n * std::cbrt(double(target) / cells))));
    if (next == n) break;
    n = next;
  }
  return n;
}

void PrintBenchHeader(const BenchFlags& flags) {
  std::printf(
      "softid-lab bench: torus-drop, first %.2f s, %d substeps at %.0f fps (dt = %.3g s); thr: "
      "threads of the simulation, par: share of the factor solved in parallel; timings: best of %d "
      "run(s), and their median\n",
      flags.seconds, flags.substeps, flags.fps, 1.0 / (flags.fps * flags.substeps), flags.repeat);
  std::printf("%10s %8s %8s %4s %6s %10s %10s %8s %10s %10s %10s %8s %12s %8s %12s %12s\n", "cells",
              "nodes", "res", "thr", "par", "setup_s", "ms/step", "median", "cpu_ms/st",
              "newton/st", "gmres/st", "refacts", "fwd+adj ms", "median", "fwd+adj cpu", "adj cpu");
}

// The `repeat` runs of one size: what the scene runner reports of the last, and every run's
// timings.
struct SizeRuns {
  int resolution = 0;
  int cells = 0, nodes = 0, threads = 1;
  double parallel_share = 0.0, setup = 0.0;
  Result<scenes::RunSummary> summary = Status::Internal("not run");
  std::vector<double> ms_runs, cpu_ms_runs, adjoint_ms_runs, adjoint_cpu_runs, backward_cpu_runs;
};

// Runs the scene `flags.repeat` times at the resolution nearest `target` cells, each run followed
// by the forward+adjoint timing; false after printing why a run failed.
bool TimeSize(const scenes::Scene& scene, int target, const BenchFlags& flags, SizeRuns* runs) {
  const int n = ResolutionFor(scene, target);
  runs->resolution = n;
  scenes::RunOptions run;
  run.simulation.cells_along_longest_side = n;
  run.simulation.threads = flags.threads;
  run.fps = flags.fps;
  run.substeps_per_frame = flags.substeps;
  run.duration = flags.seconds;
  for (int r = 0; r < flags.repeat; ++r) {
    const auto start = std::chrono::steady_clock::now();
    double cpu_at_setup = 0.0;
    runs->summary = scenes::RunScene(scene, run, [&](int frame, const fem::Simulator& sim) {
      runs->parallel_share = sim.solver_parallel_share();
      if (frame == 0) {
        runs->cells = sim.hex_mesh().NumElements();
        runs->nodes = sim.hex_mesh().NumNodes();
        runs->threads = sim.num_threads();
        runs->setup =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        cpu_at_setup = ProcessCpuSeconds();
      }
    });
    const Result<scenes::RunSummary>& summary = runs->summary;
    if (!summary.ok() || summary->diverged) {
      std::printf("%10d  run failed: %s\n", target,
                  summary.ok() ? "diverged" : summary.status().message().c_str());
      return false;
    }
    const double steps = std::max(1, summary->num_steps);
    runs->ms_runs.push_back(1e3 * summary->seconds / steps);
    runs->cpu_ms_runs.push_back(1e3 * (ProcessCpuSeconds() - cpu_at_setup) / steps);
    if (flags.adjoint) {
      const ForwardAdjointTiming timing = ForwardAdjointMs(scene, n, flags);
      runs->adjoint_ms_runs.push_back(timing.ms);
      runs->adjoint_cpu_runs.push_back(timing.cpu_ms);
      runs->backward_cpu_runs.push_back(timing.adjoint_cpu_ms);
    }
  }
  return true;
}

// What the closing lines need of the sizes run: the log-log points of the scaling fit and the
// timings at ~3000 cells (-1 until that size has run).
struct BenchTotals {
  std::vector<double> log_cells, log_ms;
  double ms_at_3000 = -1.0, adjoint_ms_at_3000 = -1.0, adjoint_cpu_ms_at_3000 = -1.0;
  double median_ms_at_3000 = -1.0, median_adjoint_ms_at_3000 = -1.0;
};

// One row of the table: the best of the runs and their median; adds the size to `totals`.
void ReportSize(const SizeRuns& runs, int target, const BenchFlags& flags, BenchTotals* totals) {
  const Result<scenes::RunSummary>& summary = runs.summary;
  const double steps = std::max(1, summary->num_steps);
  const double ms = *std::min_element(runs.ms_runs.begin(), runs.ms_runs.end());
  const double cpu_ms = *std::min_element(runs.cpu_ms_runs.begin(), runs.cpu_ms_runs.end());
  ForwardAdjointTiming adjoint{0.0, 0.0, 0.0};
  double adjoint_median_ms = 0.0;
  if (flags.adjoint) {
    adjoint.ms = *std::min_element(runs.adjoint_ms_runs.begin(), runs.adjoint_ms_runs.end());
    adjoint.cpu_ms = *std::min_element(runs.adjoint_cpu_runs.begin(), runs.adjoint_cpu_runs.end());
    adjoint.adjoint_cpu_ms =
        *std::min_element(runs.backward_cpu_runs.begin(), runs.backward_cpu_runs.end());
    adjoint_median_ms = Median(runs.adjoint_ms_runs);
  }
  const double adjoint_ms = adjoint.ms;
  std::printf("%10d %8d %8d %4d %6.2f %10.2f %10.2f %8.2f %10.2f %10.2f %10.1f %8d", runs.cells,
              runs.nodes, runs.resolution, runs.threads, runs.parallel_share, runs.setup, ms,
              Median(runs.ms_runs), cpu_ms, summary->newton_iterations / steps,
              summary->linear_iterations / steps, summary->refactorizations);
  if (flags.adjoint) {
    std::printf(" %12.2f %8.2f %12.2f %12.2f\n", adjoint_ms, adjoint_median_ms, adjoint.cpu_ms,
                adjoint.adjoint_cpu_ms);
  } else {
    std::printf(" %12s %8s %12s %12s\n", "-", "-", "-", "-");  // not timed (--no-adjoint)
  }
  if (target == 3000) totals->adjoint_cpu_ms_at_3000 = adjoint.cpu_ms;
  if (target == 3000) totals->adjoint_ms_at_3000 = adjoint_ms;
  std::fflush(stdout);
  totals->log_cells.push_back(std::log(runs.cells));
  totals->log_ms.push_back(std::log(ms));
  if (target == 3000) {
    totals->ms_at_3000 = ms;
    totals->median_ms_at_3000 = Median(runs.ms_runs);
    totals->median_adjoint_ms_at_3000 = adjoint_median_ms;
  }
}

void PrintScalingExponent(const std::vector<double>& log_cells, const std::vector<double>& log_ms) {
  if (log_cells.size() < 2) return;
  // Least-squares slope of log(ms/step) against log(cells).
  const double n = static_cast<double>(log_cells.size());
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (size_t i = 0; i < log_cells.size(); ++i) {
    sx += log_cells[i];
    sy += log_ms[i];
    sxx += log_cells[i] * log_cells[i];
    sxy += log_cells[i] * log_ms[i];
  }
  std::printf("scaling exponent (ms/step ~ cells^p): p = %.2f\n",
              (n * sxy - sx * sy) / (n * sxx - sx * sx));
}

// The forward+adjoint step at ~3000 cells against its target, and the teddy-sized job it
// projects.
void PrintJobProjection(const BenchTotals& totals, const BenchFlags& flags) {
  const double adjoint_ms_at_3000 = totals.adjoint_ms_at_3000;
  const double adjoint_cpu_ms_at_3000 = totals.adjoint_cpu_ms_at_3000;
  std::printf(
      "at ~3000 cells: %.2f ms per forward+adjoint step = %.2fx the 40 ms target, median %.2f "
      "(paper: ~600 ms on an RTX 2070)\n",
      adjoint_ms_at_3000, adjoint_ms_at_3000 / 40.0, totals.median_adjoint_ms_at_3000);
  // A teddy-sized job: 80 frames, 50 L-BFGS iterations. The paper counts 80 time steps per
  // evaluation and one evaluation per iteration (~40 min at ~0.6 s per step); a softid job steps
  // each 60 fps frame `substeps` times (step doubling picks 4 on torus-drop) and its Wolfe line
  // search needs ~1.3 evaluations (forward + adjoint) per iteration.
  constexpr int kFrames = 80, kIterations = 50;
  constexpr double kEvaluationsPerIteration = 1.3;
  const double paper_minutes = adjoint_ms_at_3000 * 1e-3 * kFrames * kIterations / 60.0;
  const double minutes = adjoint_ms_at_3000 * 1e-3 * kFrames * flags.substeps * kIterations *
                         kEvaluationsPerIteration / 60.0;
  std::printf(
      "teddy-sized job (3000 cells, %d frames, %d iterations): counted as the paper does (80 "
      "steps of this size, one evaluation per iteration) %.1f min; as a softid job runs it (%d "
      "substeps, ~%.1f evaluations per iteration) %.1f min per start = %.1fx the 3 min target "
      "(paper: ~40 min)\n",
      kFrames, kIterations, paper_minutes, flags.substeps, kEvaluationsPerIteration, minutes,
      minutes / 3.0);
  // The same from CPU time, which a busy host inflates far less than wall time.
  const double cpu_minutes = minutes * adjoint_cpu_ms_at_3000 / adjoint_ms_at_3000;
  std::printf("  from CPU time: %.2f ms per forward+adjoint step, projected %.1f min per start\n",
              adjoint_cpu_ms_at_3000, cpu_minutes);
  std::printf(
      "  a projection: `softid-lab reproduce teddy-job` runs such a job (80 frames of one step, "
      "4 parameters, 50 iterations) and times it\n");
}

int RunBench(const BenchFlags& flags) {
  auto scene = scenes::MakeBuiltinScene("torus-drop");
  if (!scene.ok()) return kExitFailure;
  PrintBenchHeader(flags);
  BenchTotals totals;
  for (int target : flags.target_cells) {
    SizeRuns runs;
    if (!TimeSize(*scene, target, flags, &runs)) return kExitFailure;
    ReportSize(runs, target, flags, &totals);
  }
  PrintScalingExponent(totals.log_cells, totals.log_ms);
  if (totals.ms_at_3000 > 0.0) {
    std::printf(
        "at ~3000 cells: %.2f ms/step = %.2fx the 15 ms target, median %.2f (paper: ~300 ms on a "
        "GPU)\n",
        totals.ms_at_3000, totals.ms_at_3000 / 15.0, totals.median_ms_at_3000);
  }
  if (totals.adjoint_ms_at_3000 > 0.0) PrintJobProjection(totals, flags);
  return kExitOk;
}

}  // namespace

Command RegisterBench(CLI::App* app) {
  app->footer(
      "Examples:\n"
      "  softid-lab bench --cells 3000 --repeat 3\n"
      "  softid-lab bench --cells 10000 --threads 1   # the per-core figure");
  auto flags = std::make_shared<BenchFlags>();
  app->add_option("--cells", flags->target_cells, "target active-cell counts")
      ->capture_default_str();
  app->add_option("--seconds", flags->seconds, "simulated time per size [s]")
      ->capture_default_str();
  app->add_option("--substeps", flags->substeps, "steps per frame")->capture_default_str();
  app->add_flag("!--no-adjoint", flags->adjoint, "skip the forward+adjoint timing");
  app->add_option("--repeat", flags->repeat, "runs per size; the best and the median are shown")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app->add_option("--threads", flags->threads,
                  "threads of one simulation: assembly, triangular solves, products (0: one per "
                  "core; 1: the per-core figure of a machine full of parallel starts)")
      ->capture_default_str();
  return [flags] { return RunBench(*flags); };
}

}  // namespace softid::lab
