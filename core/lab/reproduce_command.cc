// softid-lab reproduce: regenerate the paper's Table 1 and the multi-parameter benchmarks of issue
// 3 with our simulator (benchmarks defined in reproduce_benchmarks.h): synthesise each row's
// capture (reused when an identical one exists), fit it from the benchmark's random starts, score
// every start against the truth, print per row the mean error of converged runs and the
// convergence rate next to the paper's figures, and write one result JSON per row plus a summary.
#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "core/capture/capture.h"
#include "core/inverse/fit.h"
#include "core/inverse/identifiability.h"
#include "core/lab/commands.h"
#include "core/lab/reproduce_benchmarks.h"
#include "core/lab/result_report.h"
#include "core/scenes/scene.h"
#include "core/scenes/synthesize.h"

namespace softid::lab {
namespace {

using reproduce::Benchmark;
using reproduce::Metric;
using reproduce::Quantity;
using reproduce::Row;
using Clock = std::chrono::steady_clock;

constexpr const char* kStampFile = "reproduce-capture.json";

struct ReproduceFlags {
  std::string benchmark;
  int starts = 0;  // 0: the benchmark's
  std::vector<std::string> rows;
  int threads = 0;
  std::string out = "reproduce-out";
  std::string work;  // captures; default OUT/captures
  bool quick = false;
  int cells = 0;     // 0: the benchmark's
  int substeps = 0;  // 0: the benchmark's
  int max_iterations = 0;
  int refine_iterations = -1;  // -1: the benchmark's
  std::string frame_loss;      // empty: the job default
  std::uint64_t seed = 1;
  // 1-based start numbers to run (default: all). Every start is still drawn from the seed, and the
  // cores per start are those of the full row, so a start run alone follows the same path.
  std::vector<int> only_starts;
};

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct QuantitySummary {
  const Quantity* quantity = nullptr;
  double mean_error = std::numeric_limits<double>::quiet_NaN();  // converged runs, metric unit
  double max_error = std::numeric_limits<double>::quiet_NaN();
  bool met = false;
};

struct RowSummary {
  const Row* row = nullptr;
  int starts = 0, converged = 0, failed = 0;
  std::vector<QuantitySummary> quantities;
  bool pass = false;
  double seconds = 0.0;
  double start_seconds = -1.0;  // the slowest start's wall time, with a time target
  std::string result_file;
  nlohmann::json identifiability_verdict;  // null without the analysis
  std::vector<std::string> verdict_lines;
};

// The synthesis options of a row; the stamp records them so an identical capture is reused.
scenes::SynthesisOptions SynthesisFor(const Benchmark& b, const Row& row, double duration) {
  scenes::SynthesisOptions options;
  options.run.simulation.cells_along_longest_side = b.cells;
  options.run.substeps_per_frame = b.substeps;
  options.run.fps = b.fps;
  if (duration > 0.0) options.run.duration = duration;
  options.cameras.count = row.cameras;
  options.cameras.width = row.width;
  options.cameras.height = row.height;
  options.noise = b.noise;
  options.depth_scale = b.depth_scale;
  options.write_mass = !b.fit_mass;
  return options;
}

nlohmann::json Stamp(const Benchmark& b, const scenes::SynthesisOptions& o) {
  return {{"scene", b.scene},
          {"cells", o.run.simulation.cells_along_longest_side},
          {"substeps", o.run.substeps_per_frame},
          {"fps", o.run.fps},
          {"duration", o.run.duration ? *o.run.duration : 0.0},
          {"cameras", o.cameras.count},
          {"width", o.cameras.width},
          {"height", o.cameras.height},
          {"noise",
           {o.noise.sigma_constant, o.noise.sigma_quadratic, o.noise.dropout_probability,
            o.noise.seed}},
          {"depth_scale", o.depth_scale},
          {"write_mass", o.write_mass}};
}

// The row's capture folder, synthesised unless an identical one is there.
Result<std::filesystem::path> EnsureCapture(const Benchmark& b, const Row& row, double duration,
                                            const std::filesystem::path& work,
                                            const scenes::Scene& scene) {
  const scenes::SynthesisOptions options = SynthesisFor(b, row, duration);
  const nlohmann::json stamp = Stamp(b, options);
  const std::filesystem::path dir =
      work / b.scene /
      fmt::format("c{}-{}x{}-{}cells-{}sub-{:.2f}s{}{}", row.cameras, row.width, row.height,
                  b.cells, b.substeps, duration > 0.0 ? duration : scene.duration,
                  b.fps == 60.0 ? std::string() : fmt::format("-{:g}fps", b.fps),
                  b.fit_mass ? "-nomass" : "");
  if (std::filesystem::exists(dir / capture::kCaptureFileName)) {
    std::ifstream in(dir / kStampFile);
    const nlohmann::json existing = nlohmann::json::parse(in, nullptr, false);
    if (!existing.is_discarded() && existing == stamp) {
      spdlog::info("reproduce: reusing capture {}", dir.string());
      return dir;
    }
    spdlog::info("reproduce: {} was made with other settings; synthesising again", dir.string());
  }
  std::error_code ignored;
  std::filesystem::remove_all(dir, ignored);
  const auto start = Clock::now();
  SOFTID_ASSIGN_OR_RETURN(scenes::SynthesisSummary summary,
                          scenes::Synthesize(scene, options, dir));
  SOFTID_RETURN_IF_ERROR(WriteJsonFile(dir / kStampFile, stamp));
  spdlog::info(
      "reproduce: synthesised {} ({} frames, {} elements, {:.0f} object pixels per frame and "
      "camera) in {:.1f} s",
      dir.string(), summary.run.num_frames, summary.num_elements, summary.mean_valid_pixels,
      SecondsSince(start));
  return dir;
}

// The identifiability verdict for the benchmark's focus variables, in words and as JSON.
void Verdict(const Benchmark& b, const inverse::IdentifiabilityReport& report, RowSummary* out) {
  nlohmann::json verdict = nlohmann::json::object();
  for (const std::string& name : b.identifiability_focus) {
    const inverse::VariableIdentifiability* v = report.Find(name);
    if (v == nullptr) continue;
    std::string flags;
    for (inverse::IdentifiabilityFlag f : v->flags)
      flags += (flags.empty() ? "" : ", ") + std::string(inverse::ToString(f));
    verdict[name] = {{"identifiable", v->identifiable()},
                     {"relative_uncertainty",
                      v->relative_uncertainty >= 0.0 && std::isfinite(v->relative_uncertainty)
                          ? nlohmann::json(v->relative_uncertainty)
                          : nlohmann::json(nullptr)},
                     {"flags", nlohmann::json::array()}};
    for (inverse::IdentifiabilityFlag f : v->flags) verdict[name]["flags"].push_back(ToString(f));
    out->verdict_lines.push_back(
        fmt::format("{}: {} (formal 1-sigma {:.3g} %{}{})", name,
                    v->identifiable() ? "identifiable" : "NOT separately identifiable",
                    100.0 * v->relative_uncertainty, flags.empty() ? "" : "; ", flags));
  }
  // Pairwise correlations and valleys among the focus variables.
  for (size_t a = 0; a < b.identifiability_focus.size(); ++a) {
    for (size_t c = a + 1; c < b.identifiability_focus.size(); ++c) {
      int i = -1, j = -1;
      for (size_t k = 0; k < report.variables.size(); ++k) {
        if (report.variables[k].name == b.identifiability_focus[a]) i = static_cast<int>(k);
        if (report.variables[k].name == b.identifiability_focus[c]) j = static_cast<int>(k);
      }
      if (i < 0 || j < 0) continue;
      const double rho = report.correlation(i, j);
      out->verdict_lines.push_back(fmt::format(
          "correlation({}, {}) = {}", report.variables[i].name, report.variables[j].name,
          std::isfinite(rho) ? fmt::format("{:+.3f}", rho)
                             : std::string("undefined (one of them is unbounded)")));
      verdict["correlations"][report.variables[i].name + "," + report.variables[j].name] =
          std::isfinite(rho) ? nlohmann::json(rho) : nlohmann::json(nullptr);
    }
  }
  for (const inverse::DegenerateCombination& c : report.degenerate_combinations) {
    std::string loadings;
    for (const auto& [name, w] : c.loadings)
      loadings += fmt::format("{}{} {:+.2f}", loadings.empty() ? "" : ", ", name, w);
    out->verdict_lines.push_back(fmt::format(
        "valley (scaled eigenvalue {:.3g}): the data fix only a combination; loadings {}",
        c.scaled_eigenvalue, loadings));
  }
  verdict["degenerate_combinations"] = report.degenerate_combinations.size();
  out->identifiability_verdict = verdict;
}

// One row's run: its inputs, and what its stages find and fill in, in the order they do.
struct RowRun {
  RowRun(const Benchmark& b, const Row& row, const ReproduceFlags& flags, int starts, int threads,
         double duration, const std::filesystem::path& out)
      : b(b),
        row(row),
        flags(flags),
        starts(starts),
        threads(threads),
        duration(duration),
        out(out) {}

  const Benchmark& b;
  const Row& row;
  const ReproduceFlags& flags;
  const int starts;  // drawn from the seed
  const int threads;
  const double duration;
  const std::filesystem::path& out;
  const Clock::time_point begin = Clock::now();
  scenes::Scene scene;
  fem::PhysicalParameters truth;
  std::filesystem::path dir;  // the capture's
  capture::Capture capture;
  std::vector<nlohmann::json> initial;  // every start drawn
  std::vector<int> run;                 // the starts to run, indices into `initial`
  std::filesystem::path config_dir;     // each run start's job config
  int max_iterations = 0, refine_iterations = 0;
  int cores_per_start = 1;
  inverse::FitResult combined;
  // Per run start, its fit without the start (grid, time step, frame loss: its "auto" choices).
  std::vector<std::optional<inverse::FitResult>> records;
  std::vector<inverse::JobConfig> configs;  // per run start
  nlohmann::json start_scores = nlohmann::json::array();
  std::vector<std::vector<double>> errors;  // per quantity, of the converged starts
  RowSummary summary;

  int num_run() const { return static_cast<int>(run.size()); }
};

// The row's scene and its capture, synthesised unless an identical one is there.
Status LoadRowCapture(RowRun& r, const std::filesystem::path& work) {
  SOFTID_ASSIGN_OR_RETURN(r.scene, scenes::MakeBuiltinScene(r.b.scene));
  if (r.duration > 0.0) r.scene.duration = r.duration;
  r.truth = r.scene.parameters;
  SOFTID_ASSIGN_OR_RETURN(r.dir, EnsureCapture(r.b, r.row, r.duration, work, r.scene));
  SOFTID_ASSIGN_OR_RETURN(r.capture, capture::ReadCapture(r.dir, {.decode_frames = false}));
  return Status::Ok();
}

// The starts: drawn, chosen, and where their job configs go (each one reruns alone with
// `softid-lab fit CAPTURE --config FILE`).
Status PlanStarts(RowRun& r) {
  const ReproduceFlags& flags = r.flags;
  r.max_iterations = flags.max_iterations > 0 ? flags.max_iterations : r.b.max_iterations;
  r.refine_iterations =
      flags.refine_iterations >= 0 ? flags.refine_iterations : r.b.refine_iterations;
  // The same starts for every row of a benchmark (one seed), so rows differ only in their data.
  std::mt19937_64 rng(flags.seed);
  for (int s = 0; s < r.starts; ++s) r.initial.push_back(reproduce::DrawStart(r.b, r.truth, rng));
  if (flags.only_starts.empty()) {
    for (int s = 0; s < r.starts; ++s) r.run.push_back(s);
  } else {
    for (int number : flags.only_starts) r.run.push_back(number - 1);
  }
  r.config_dir = r.out / fmt::format("{}-{}-starts", r.b.name, r.row.id);
  std::error_code ec;
  std::filesystem::create_directories(r.config_dir, ec);
  if (ec) return Status::Internal(fmt::format("{}: {}", r.config_dir.string(), ec.message()));
  // The cores the parallel starts leave idle go to each start's simulation.
  r.cores_per_start =
      std::max(1, static_cast<int>(std::thread::hardware_concurrency()) / std::max(1, r.threads));
  return Status::Ok();
}

// Fits run start k into combined.starts[k] (under `mutex`, which also guards `have_base`) and logs
// its errors; fails when its job config cannot be made or written.
Status FitStart(RowRun& r, int k, std::mutex& mutex, bool* have_base) {
  const Benchmark& b = r.b;
  const int s = r.run[k];
  Result<inverse::JobConfig> config =
      reproduce::MakeStartConfig(b, r.row, r.truth, r.initial[s], r.capture.mass_kg.has_value(),
                                 {.max_iterations = r.max_iterations,
                                  .refine_iterations = r.refine_iterations,
                                  .cores = r.cores_per_start,
                                  .frame_loss = r.flags.frame_loss});
  Status written = config.ok()
                       ? WriteJsonFile(r.config_dir / fmt::format("start-{:02d}.json", s + 1),
                                       inverse::ToJson(*config))
                       : config.status();
  if (!written.ok()) return written;
  r.configs[k] = *config;
  Result<inverse::FitResult> fit = inverse::Fit(r.capture, *config);
  std::lock_guard lock(mutex);
  inverse::StartResult& start = r.combined.starts[k];
  if (fit.ok()) {
    start = fit->starts[0];
    if (!*have_base) r.combined.base = fit->base;
    *have_base = true;
    r.records[k] = std::move(*fit);
    r.records[k]->starts.clear();
  } else {
    start.failed = true;
    start.termination = fit.status().message();
    Result<fem::PhysicalParameters> p =
        inverse::ApplyToParameters(*config, fem::PhysicalParameters{});
    if (p.ok()) start.initial = start.final = *p;
  }
  start.index = s;
  std::string errors;
  for (const Quantity& q : b.quantities) {
    errors += fmt::format(
        " {} {:.3g}{}", q.label,
        reproduce::MetricDisplayScale(q.metric) * reproduce::ScoreError(q, start.final, r.truth),
        reproduce::MetricUnit(q.metric));
  }
  spdlog::info("{} {} start {}/{}: {}{}; cost {:.3e} m^2, {} iterations, {:.0f} s", b.name,
               r.row.id, s + 1, r.starts, start.failed ? "FAILED " : "", errors, start.final_cost,
               start.iterations, start.seconds);
  return Status::Ok();
}

// The combined result reports how its best start was fitted (its grid, time step and frame loss:
// each start makes its own "auto" choices), with every start's result.
void TakeFitRecord(const inverse::FitResult& record, RowRun* r) {
  inverse::FitResult combined = record;
  combined.fitted = std::move(r->combined.fitted);
  combined.base = std::move(r->combined.base);
  combined.starts = std::move(r->combined.starts);
  combined.best = r->combined.best;
  r->combined = std::move(combined);
}

// Fits the run starts, `threads` at a time, into `combined`, whose best is the cheapest.
Status FitStarts(RowRun& r) {
  const int num_run = r.num_run();
  inverse::FitResult& combined = r.combined;
  combined.fitted = r.b.fit;
  combined.starts.resize(num_run);
  r.records.resize(num_run);
  r.configs.resize(num_run);
  bool have_base = false;
  std::atomic<int> next{0};
  std::mutex mutex;
  Status error;
  auto worker = [&]() {
    for (int k = next++; k < num_run; k = next++) {
      if (Status fitted = FitStart(r, k, mutex, &have_base); !fitted.ok()) {
        std::lock_guard lock(mutex);
        error = fitted;
        return;
      }
    }
  };
  {
    std::vector<std::jthread> pool;
    for (int t = 1; t < std::min(r.threads, num_run); ++t) pool.emplace_back(worker);
    worker();
  }
  SOFTID_RETURN_IF_ERROR(error);
  for (int s = 0; s < num_run; ++s) {
    const inverse::StartResult& start = combined.starts[s];
    if (start.failed || start.evaluations == 0) continue;
    if (combined.best < 0 || start.final_cost < combined.starts[combined.best].final_cost)
      combined.best = s;
  }
  if (combined.best >= 0 && r.records[combined.best]) TakeFitRecord(*r.records[combined.best], &r);
  combined.total_seconds = SecondsSince(r.begin);
  return Status::Ok();
}

// Scores per start and per quantity; convergence over the judged quantities.
void ScoreStarts(RowRun& r) {
  const std::vector<Quantity>& quantities = r.b.quantities;
  RowSummary& summary = r.summary;
  summary.starts = r.num_run();
  r.errors.resize(quantities.size());
  for (int k = 0; k < r.num_run(); ++k) {
    const inverse::StartResult& start = r.combined.starts[k];
    bool converged = !start.failed;
    nlohmann::json scores = nlohmann::json::object();
    std::vector<double> e(quantities.size());
    for (size_t q = 0; q < quantities.size(); ++q) {
      const Quantity& quantity = quantities[q];
      e[q] = reproduce::ScoreError(quantity, start.final, r.truth);
      scores[quantity.name] = std::isfinite(e[q]) ? nlohmann::json(e[q]) : nlohmann::json(nullptr);
      if (quantity.judged && !(e[q] < reproduce::ConvergenceLimit(quantity.metric)))
        converged = false;
    }
    summary.failed += start.failed;
    summary.converged += converged;
    if (converged) {
      for (size_t q = 0; q < e.size(); ++q) r.errors[q].push_back(e[q]);
    }
    r.start_scores.push_back(
        {{"index", start.index}, {"converged", converged}, {"errors", scores}});
  }
  summary.pass = summary.converged == r.num_run();
}

// With a time target: the slowest start and its work (a job's wall time is that of its starts
// run in parallel).
void JudgeStartTime(RowRun& r) {
  const double target = r.b.start_seconds_target;
  if (!(target > 0.0)) return;
  const inverse::StartResult* slowest = nullptr;
  for (const inverse::StartResult& start : r.combined.starts) {
    if (slowest == nullptr || start.seconds > slowest->seconds) slowest = &start;
  }
  if (slowest == nullptr) return;
  RowSummary& summary = r.summary;
  summary.start_seconds = slowest->seconds;
  const bool met = slowest->seconds <= target;
  summary.pass = summary.pass && met;
  summary.verdict_lines.push_back(fmt::format(
      "wall time per start {:.0f} s ({:.1f} min; target {:.0f} s: {}) on {} core(s): {} "
      "iterations, {} evaluations, {} steps, {:.1f} ms per step (forward {:.0f} s, adjoint "
      "{:.0f} s)",
      slowest->seconds, slowest->seconds / 60.0, target, met ? "met" : "NOT met", r.cores_per_start,
      slowest->iterations, slowest->evaluations, slowest->steps,
      1e3 * slowest->seconds / std::max<long long>(1, slowest->steps), slowest->forward_seconds,
      slowest->backward_seconds));
}

// Per quantity the mean and worst error of the converged starts against its target.
void SummariseQuantities(RowRun& r) {
  for (size_t q = 0; q < r.b.quantities.size(); ++q) {
    QuantitySummary qs;
    qs.quantity = &r.b.quantities[q];
    if (!r.errors[q].empty()) {
      double sum = 0.0, worst = 0.0;
      for (double e : r.errors[q]) sum += e, worst = std::max(worst, e);
      qs.mean_error = sum / static_cast<double>(r.errors[q].size());
      qs.max_error = worst;
    }
    qs.met = qs.mean_error <= qs.quantity->target;
    if (qs.quantity->judged && !qs.met) r.summary.pass = false;
    r.summary.quantities.push_back(qs);
  }
}

// The identifiability of the focus variables at the best start, into `result` and the verdict.
void AnalyseRowIdentifiability(RowRun& r, nlohmann::json* result) {
  const inverse::FitResult& combined = r.combined;
  if (r.b.identifiability_focus.empty() || combined.best < 0) return;
  inverse::IdentifiabilityOptions options;
  options.threads = r.threads;
  const auto analysis_start = Clock::now();
  Result<inverse::IdentifiabilityReport> report =
      inverse::AnalyzeIdentifiability(r.capture, r.configs[combined.best], combined, options);
  if (report.ok()) {
    (*result)["identifiability"] = inverse::ToJson(*report);
    Verdict(r.b, *report, &r.summary);
    spdlog::info("{} {}: identifiability analysis in {:.0f} s", r.b.name, r.row.id,
                 SecondsSince(analysis_start));
  } else {
    r.summary.verdict_lines.push_back("identifiability analysis failed: " +
                                      report.status().message());
    r.summary.identifiability_verdict = {{"error", report.status().message()}};
  }
}

nlohmann::json QuantitiesJson(const std::vector<QuantitySummary>& summaries) {
  nlohmann::json quantities = nlohmann::json::array();
  for (const QuantitySummary& qs : summaries) {
    quantities.push_back(
        {{"name", qs.quantity->name},
         {"label", qs.quantity->label},
         {"unit", reproduce::MetricUnit(qs.quantity->metric)},
         {"scale", reproduce::MetricDisplayScale(qs.quantity->metric)},
         {"judged", qs.quantity->judged},
         {"target", qs.quantity->target},
         {"mean_error_converged",
          std::isfinite(qs.mean_error) ? nlohmann::json(qs.mean_error) : nlohmann::json(nullptr)},
         {"max_error_converged",
          std::isfinite(qs.max_error) ? nlohmann::json(qs.max_error) : nlohmann::json(nullptr)},
         {"met", qs.met}});
  }
  return quantities;
}

// The row's part of its result JSON: its setup, scores and verdict.
nlohmann::json RowJson(const RowRun& r) {
  const Benchmark& b = r.b;
  const Row& row = r.row;
  const RowSummary& summary = r.summary;
  nlohmann::json row_json = {
      {"benchmark", b.name},
      {"row", row.id},
      {"label", row.label},
      {"capture", r.dir.string()},
      {"cameras", row.cameras},
      {"width", row.width},
      {"height", row.height},
      {"gradient", inverse::ToString(row.gradient)},
      {"cells", b.cells},
      {"substeps", b.substeps},
      {"duration", r.scene.duration},
      {"starts", r.num_run()},
      {"start_configs", r.config_dir.string()},
      {"converged", summary.converged},
      {"failed", summary.failed},
      {"convergence_rate", static_cast<double>(summary.converged) / std::max(1, r.num_run())},
      {"quantities", QuantitiesJson(summary.quantities)},
      {"start_scores", r.start_scores},
      {"pass", summary.pass},
      {"seconds", summary.seconds},
      {"fps", b.fps},
      {"truth", fem::ToJson(r.truth)},
  };
  if (b.start_seconds_target > 0.0) {
    row_json["start_seconds"] = summary.start_seconds;
    row_json["start_seconds_target"] = b.start_seconds_target;
  }
  if (row.paper) {
    row_json["paper"] = {{"error_percent", row.paper->error_percent},
                         {"converged_percent", row.paper->converged_percent},
                         {"entry", row.paper->note}};
  }
  if (!summary.identifiability_verdict.is_null())
    row_json["identifiability_verdict"] = summary.identifiability_verdict;
  return row_json;
}

// Fits every start of one row, scores them against the truth and writes the row's result JSON.
Result<RowSummary> RunRow(const Benchmark& b, const Row& row, const ReproduceFlags& flags,
                          int starts, int threads, double duration,
                          const std::filesystem::path& work, const std::filesystem::path& out) {
  RowRun r(b, row, flags, starts, threads, duration, out);
  r.summary.row = &row;
  SOFTID_RETURN_IF_ERROR(LoadRowCapture(r, work));
  SOFTID_RETURN_IF_ERROR(PlanStarts(r));
  SOFTID_RETURN_IF_ERROR(FitStarts(r));
  ScoreStarts(r);
  JudgeStartTime(r);
  SummariseQuantities(r);
  nlohmann::json result =
      r.combined.best >= 0 ? inverse::ToJson(r.combined) : nlohmann::json::object();
  AnalyseRowIdentifiability(r, &result);
  r.summary.seconds = SecondsSince(r.begin);
  result["reproduce"] = RowJson(r);
  r.summary.result_file = (out / fmt::format("{}-{}.json", b.name, row.id)).string();
  SOFTID_RETURN_IF_ERROR(WriteJsonFile(r.summary.result_file, result));
  return std::move(r.summary);
}

void PrintRows(const Benchmark& b, const std::vector<RowSummary>& rows) {
  std::printf("\n%-10s %-36s %-7s %-5s %-13s %-12s %-10s %-6s %-22s %s\n", "row", "setup", "conv.",
              "", "quantity", "mean err", "target", "met", "paper (err, conv.)", "time");
  for (const RowSummary& r : rows) {
    for (size_t q = 0; q < r.quantities.size(); ++q) {
      const QuantitySummary& qs = r.quantities[q];
      const double scale = reproduce::MetricDisplayScale(qs.quantity->metric);
      const char* unit = reproduce::MetricUnit(qs.quantity->metric);
      const std::string conv = q == 0 ? fmt::format("{}/{}", r.converged, r.starts) : std::string();
      const std::string rate =
          q == 0 ? fmt::format("{:.0f}%", 100.0 * r.converged / std::max(1, r.starts))
                 : std::string();
      const std::string mean = std::isfinite(qs.mean_error)
                                   ? fmt::format("{:.3g} {}", scale * qs.mean_error, unit)
                                   : std::string("-");
      const std::string target =
          qs.quantity->judged ? fmt::format("<= {:.3g} {}", scale * qs.quantity->target, unit)
                              : std::string("(info)");
      const std::string met = qs.quantity->judged ? (qs.met ? "yes" : "NO") : "";
      const std::string paper = q == 0 && r.row->paper
                                    ? fmt::format("{:.1f} %, {:.0f} %", r.row->paper->error_percent,
                                                  r.row->paper->converged_percent)
                                    : std::string();
      const std::string time = q == 0 ? fmt::format("{:.0f} s", r.seconds) : std::string();
      std::printf("%-10s %-36s %-7s %-5s %-13s %-12s %-10s %-6s %-22s %s\n",
                  q == 0 ? r.row->id.c_str() : "", q == 0 ? r.row->label.c_str() : "", conv.c_str(),
                  rate.c_str(), qs.quantity->label.c_str(), mean.c_str(), target.c_str(),
                  met.c_str(), paper.c_str(), time.c_str());
    }
    for (const std::string& line : r.verdict_lines) std::printf("%-10s   %s\n", "", line.c_str());
  }
  std::printf(
      "converged = every judged quantity within %.0f %% (relative), 5 deg, 10 mm; mean "
      "errors over converged runs; %s\n",
      100.0 * reproduce::ConvergenceLimit(Metric::kRelative), b.description.c_str());
}

// The rows --rows names, or every row (every quick row with --quick); InvalidArgument naming an
// unknown row and the known ones.
Result<std::vector<const Row*>> SelectRows(const Benchmark& b, const ReproduceFlags& flags) {
  std::vector<const Row*> rows;
  if (flags.rows.empty()) {
    for (const Row& row : b.rows) {
      if (!flags.quick || row.in_quick) rows.push_back(&row);
    }
    return rows;
  }
  for (const std::string& id : flags.rows) {
    auto it = std::find_if(b.rows.begin(), b.rows.end(), [&](const Row& r) { return r.id == id; });
    if (it == b.rows.end()) {
      std::string known;
      for (const Row& r : b.rows) known += (known.empty() ? "" : ", ") + r.id;
      return Status::InvalidArgument(
          fmt::format("--rows: \"{}\" is not a row of {} (rows: {})", id, b.name, known));
    }
    rows.push_back(&*it);
  }
  return rows;
}

// A row of the summary file: the row's "reproduce" object from its result file, without the
// per-start scores, with the result file named.
nlohmann::json SummaryRowJson(const RowSummary& summary) {
  std::ifstream in(summary.result_file);
  const nlohmann::json written = nlohmann::json::parse(in, nullptr, false);
  nlohmann::json row_json = written.is_discarded() ? nlohmann::json::object()
                                                   : written.value("reproduce", nlohmann::json());
  row_json.erase("start_scores");
  row_json["result_file"] = summary.result_file;
  return row_json;
}

// The run the flags ask for: the benchmark with --cells and --substeps applied, its starts per
// row, clip length, threads and rows, and the folders.
struct ReproducePlan {
  Benchmark b;
  int starts = 0;
  double duration = 0.0;
  int threads = 1;
  std::vector<const Row*> rows;  // into b.rows
  std::filesystem::path out, work;
};

// Fills `plan` (in place: its rows point into plan->b) and creates the output folder; kExitOk, or
// the exit code after logging what is wrong.
int PlanReproduce(const ReproduceFlags& flags, ReproducePlan* plan) {
  Result<Benchmark> made = reproduce::MakeBenchmark(flags.benchmark);
  if (!made.ok()) {
    spdlog::error("{}", made.status().message());
    return kExitInvalidInput;
  }
  plan->b = *made;
  Benchmark& b = plan->b;
  if (flags.cells > 0) b.cells = flags.cells;
  if (flags.substeps > 0) b.substeps = flags.substeps;
  const int starts = flags.starts > 0 ? flags.starts : (flags.quick ? b.quick_starts : b.starts);
  plan->starts = starts;
  plan->duration = flags.quick && b.quick_duration > 0.0 ? b.quick_duration : b.duration;
  int threads =
      flags.threads > 0 ? flags.threads : static_cast<int>(std::thread::hardware_concurrency());
  plan->threads = std::clamp(threads, 1, std::max(1, starts));
  for (int number : flags.only_starts) {
    if (number < 1 || number > starts) {
      spdlog::error("--only-starts: {} is not a start of this run (1..{})", number, starts);
      return kExitInvalidInput;
    }
  }
  Result<std::vector<const Row*>> selected = SelectRows(b, flags);
  if (!selected.ok()) {
    spdlog::error("{}", selected.status().message());
    return kExitInvalidInput;
  }
  plan->rows = *selected;
  plan->out = flags.out;
  plan->work = flags.work.empty() ? plan->out / "captures" : std::filesystem::path(flags.work);
  std::error_code ec;
  std::filesystem::create_directories(plan->out, ec);
  if (ec) {
    spdlog::error("--out = {}: {}", plan->out.string(), ec.message());
    return kExitFailure;
  }
  return kExitOk;
}

// What the rows run so far give the summary.
struct RowsDone {
  std::vector<RowSummary> summaries;
  nlohmann::json summary_rows = nlohmann::json::array();
  bool pass = true;
};

// Runs the rows in turn, printing each one's table as it ends; kExitOk, or the exit code after
// logging the row that failed.
int RunRows(const ReproducePlan& plan, const ReproduceFlags& flags, RowsDone* done) {
  const Benchmark& b = plan.b;
  for (const Row* row : plan.rows) {
    Result<RowSummary> summary =
        RunRow(b, *row, flags, plan.starts, plan.threads, plan.duration, plan.work, plan.out);
    if (!summary.ok()) {
      spdlog::error("{} {}: {}", b.name, row->id, summary.status().message());
      return summary.status().code() == StatusCode::kInvalidArgument ? kExitInvalidInput
                                                                     : kExitFailure;
    }
    done->summaries.push_back(*summary);
    done->pass = done->pass && summary->pass;
    PrintRows(b, {done->summaries.back()});
    std::fflush(stdout);
    done->summary_rows.push_back(SummaryRowJson(*summary));
  }
  return kExitOk;
}

// The table of every row, and the summary file.
int WriteReproduceSummary(const ReproducePlan& plan, const ReproduceFlags& flags,
                          const RowsDone& done) {
  const Benchmark& b = plan.b;
  std::printf("\n== reproduce %s: %s ==", b.name.c_str(), b.description.c_str());
  PrintRows(b, done.summaries);
  const nlohmann::json summary = {{"format", "softid-reproduce/1"}, {"benchmark", b.name},
                                  {"description", b.description},   {"quick", flags.quick},
                                  {"starts", plan.starts},          {"seed", flags.seed},
                                  {"rows", done.summary_rows},      {"pass", done.pass}};
  const std::filesystem::path summary_file = plan.out / fmt::format("{}-summary.json", b.name);
  if (Status written = WriteJsonFile(summary_file, summary); !written.ok()) {
    spdlog::error("{}", written.message());
    return kExitFailure;
  }
  std::printf("%s: every row %s its target; summary written to %s\n", b.name.c_str(),
              done.pass ? "meets" : "does NOT meet", summary_file.string().c_str());
  return kExitOk;
}

int RunReproduce(const ReproduceFlags& flags) {
  ReproducePlan plan;
  if (const int exit_code = PlanReproduce(flags, &plan); exit_code != kExitOk) return exit_code;
  const Benchmark& b = plan.b;
  spdlog::info(
      "reproduce {}: {} row(s), {} start(s) each, {} thread(s), grid {} cells, {} "
      "substeps{}",
      b.name, plan.rows.size(), plan.starts, plan.threads, b.cells, b.substeps,
      flags.quick ? ", quick" : "");
  RowsDone done;
  if (const int exit_code = RunRows(plan, flags, &done); exit_code != kExitOk) return exit_code;
  return WriteReproduceSummary(plan, flags, done);
}

}  // namespace

Command RegisterReproduce(CLI::App* app) {
  app->footer(
      "Examples:\n"
      "  softid-lab reproduce table1 --quick\n"
      "  softid-lab reproduce table1 --rows c1-50\n"
      "  softid-lab reproduce pillow-ramp");
  auto flags = std::make_shared<ReproduceFlags>();
  std::string names;
  for (const std::string& n : reproduce::BenchmarkNames()) names += (names.empty() ? "" : "|") + n;
  app->add_option("benchmark", flags->benchmark, names)->required();
  app->add_option("--starts", flags->starts, "random starts per row (default: the benchmark's)");
  app->add_option("--rows", flags->rows, "row ids to run (default: all; with --quick the first)")
      ->delimiter(',');
  app->add_option("--threads", flags->threads, "parallel starts (0 = all cores)")
      ->capture_default_str();
  app->add_option("--out", flags->out, "folder for the result JSON of every row and the summary")
      ->capture_default_str();
  app->add_option("--work", flags->work,
                  "folder for the synthesised captures (default OUT/captures)");
  app->add_flag("--quick", flags->quick,
                "reduced run: fewer starts, a shorter clip, only the main row");
  app->add_option("--cells", flags->cells, "grid cells along the longest side (default 16)");
  app->add_option("--substeps", flags->substeps, "steps per frame (default 2)");
  app->add_option("--max-iterations", flags->max_iterations, "optimiser iterations per start");
  app->add_option("--refine-iterations", flags->refine_iterations,
                  "Levenberg-Marquardt iterations per start after L-BFGS (default: the "
                  "benchmark's, 40 for ball-bounce and pillow-ramp, 0 otherwise)")
      ->check(CLI::NonNegativeNumber);
  app->add_option("--frame-loss", flags->frame_loss,
                  "how the frames' costs add up: squared|cauchy (default: the job default, "
                  "docs/job-config.md)")
      ->check(CLI::IsMember({"squared", "cauchy"}));
  app->add_option("--seed", flags->seed, "seed of the random starts")->capture_default_str();
  app->add_option("--only-starts", flags->only_starts,
                  "run only these starts (1-based, comma-separated), each exactly as in the full "
                  "row")
      ->delimiter(',');
  return [flags] { return RunReproduce(*flags); };
}

}  // namespace softid::lab
