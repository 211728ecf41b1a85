// `softid-server tokens create|list|revoke`: the operator's hands on the API tokens, working on
// the data directory's database directly (also while a server runs on it).
#pragma once

#include <CLI/CLI.hpp>
#include <string>

namespace softid::server {

struct TokensCommand {
  CLI::App* command = nullptr;
  CLI::App* create = nullptr;
  CLI::App* list = nullptr;
  CLI::App* revoke = nullptr;
  std::string station;
  bool admin = false;
  double expires_in_days = 0.0;  // 0: never
  std::string token_id;
  bool json = false;
};

// Adds the `tokens` subcommand and its three subcommands to `app`.
void AddTokensCommand(CLI::App& app, TokensCommand* flags);

// Runs the parsed subcommand on <data_dir>/softid.db; returns the exit status (0 ok, 2 bad
// input, 1 other failure) after printing the result or the error.
int RunTokensCommand(const TokensCommand& flags, const std::string& data_dir);

}  // namespace softid::server
