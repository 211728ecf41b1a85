// softid-lab: the local laboratory tool (synthetic captures, simulation, benchmarks).
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>

#include "core/common/cpu_support.h"
#include "core/fem/numeric_runtime.h"
#include "core/lab/commands.h"

int main(int argc, char** argv) {
  // Links the start-up check that this CPU runs the build's instruction set.
  if (!softid::CpuSupportsBuild()) return 2;
  softid::fem::ConfigureNumericRuntime();  // CHOLMOD's OpenMP serialised, BLAS single-threaded
  auto logger = spdlog::stderr_color_mt("softid-lab");
  spdlog::set_default_logger(logger);
  spdlog::set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");

  CLI::App app{
      "softid-lab: simulate soft bodies, synthesise depth captures, fit parameters, benchmark"};
  app.require_subcommand(1);
  bool verbose = false;
  app.add_flag("-v,--verbose", verbose, "debug logging");
  std::vector<std::pair<CLI::App*, softid::lab::Command>> commands;
  auto add = [&](const char* name, const char* help, auto registrar) {
    CLI::App* sub = app.add_subcommand(name, help);
    commands.emplace_back(sub, registrar(sub));
  };
  add("synth", "simulate a scene and write a synthetic capture (+ truth.json)",
      softid::lab::RegisterSynth);
  add("simulate", "simulate a scene and write the deformed surface per frame (PLY)",
      softid::lab::RegisterSimulate);
  add("modes", "the body's lowest elastic eigenfrequencies as softid discretises it",
      softid::lab::RegisterModes);
  add("bench", "time simulation steps at several grid sizes", softid::lab::RegisterBench);
  add("ingest",
      "turn a raw recording into a capture (writes capture.json, ingest.json, ingest.png)",
      softid::lab::RegisterIngest);
  add("fit", "recover physical parameters from a capture (writes result.json)",
      softid::lab::RegisterFit);
  add("diagnose", "fit, then look for physics the model left out (writes diagnosis.json)",
      softid::lab::RegisterDiagnose);
  add("prove-diagnosis", "concealed-effect benchmark of the diagnosis (confusion table)",
      softid::lab::RegisterProveDiagnosis);
  add("prove-ingest", "raw recordings ingested and held against their truth (table)",
      softid::lab::RegisterProveIngest);
  add("reproduce", "benchmarks: table1 | ball-bounce | pillow-ramp | bar-hanging",
      softid::lab::RegisterReproduce);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : softid::lab::kExitInvalidInput;
  }
  if (verbose) spdlog::set_level(spdlog::level::debug);
  for (auto& [sub, command] : commands) {
    if (sub->parsed()) return command();
  }
  return softid::lab::kExitInvalidInput;
}
