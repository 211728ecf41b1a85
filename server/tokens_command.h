// `softid-server tokens create|list|revoke`: the operator's hands on the API tokens, working on
// the store's database directly (also while a server runs on it): the data directory's SQLite
// database, or the PostgreSQL database of --store.
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

// Runs the parsed subcommand on <data_dir>/softid.db, or on the PostgreSQL database `store_url`
// names when it is not empty (--store); returns the exit status (0 ok, 2 bad input, 1 other
// failure) after printing the result or the error.
int RunTokensCommand(const TokensCommand& flags, const std::string& data_dir,
                     const std::string& store_url);

}  // namespace softid::server
