// softid-lab subcommands. Each registers its flags on a CLI11 subcommand and returns a callback
// producing the process exit code.
#pragma once

#include <CLI/CLI.hpp>
#include <functional>

namespace softid::lab {

using Command = std::function<int()>;

// Exit codes shared by the commands.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitInvalidInput = 2;

Command RegisterSynth(CLI::App* app);
Command RegisterSimulate(CLI::App* app);
Command RegisterModes(CLI::App* app);
Command RegisterBench(CLI::App* app);
Command RegisterIngest(CLI::App* app);
Command RegisterFit(CLI::App* app);
Command RegisterDiagnose(CLI::App* app);
Command RegisterProveDiagnosis(CLI::App* app);
Command RegisterProveIngest(CLI::App* app);
Command RegisterReproduce(CLI::App* app);

}  // namespace softid::lab
