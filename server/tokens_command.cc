#include "server/tokens_command.h"

#include <fmt/chrono.h>

#include <cstdio>
#include <ctime>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>

#include "server/api_tokens.h"
#include "server/store/open_store.h"

namespace softid::server {
namespace {

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitInvalidInput = 2;

int Fail(const Status& status) {
  std::fprintf(stderr, "softid-server tokens: %s\n", status.message().c_str());
  return status.code() == StatusCode::kInvalidArgument || status.code() == StatusCode::kNotFound
             ? kExitInvalidInput
             : kExitFailure;
}

std::string Iso(const std::optional<store::Timestamp>& t) {
  if (!t.has_value()) return "";
  const std::time_t seconds = std::chrono::system_clock::to_time_t(
      std::chrono::time_point_cast<std::chrono::system_clock::duration>(*t));
  return fmt::format("{:%Y-%m-%dT%H:%M:%SZ}", fmt::gmtime(seconds));
}

nlohmann::json TokenJson(const store::ApiToken& token) {
  return {{"id", token.id},
          {"station", token.station},
          {"admin", token.admin},
          {"created", Iso(token.created_at)},
          {"expires", Iso(token.expires_at)},
          {"revoked", Iso(token.revoked_at)}};
}

}  // namespace

void AddTokensCommand(CLI::App& app, TokensCommand* flags) {
  flags->command = app.add_subcommand("tokens", "create, list and revoke per-station API tokens");
  flags->command->require_subcommand(1);
  flags->command->add_flag("--json", flags->json, "machine-readable output");
  flags->create = flags->command->add_subcommand(
      "create",
      "issue a token for a station and print it once (example: tokens create "
      "--station lab-3 --expires-in-days 365)");
  flags->create->add_option("--station", flags->station, "the station's name ([A-Za-z0-9._-])")
      ->required();
  flags->create->add_flag("--admin", flags->admin, "may see and manage every station's jobs");
  flags->create
      ->add_option("--expires-in-days", flags->expires_in_days,
                   "refuse the token after this many days (default: never)")
      ->check(CLI::NonNegativeNumber);
  flags->list = flags->command->add_subcommand("list", "list tokens (never their secrets)");
  flags->revoke = flags->command->add_subcommand("revoke", "revoke a token by its id (tok-...)");
  flags->revoke->add_option("id", flags->token_id, "the token's id")->required();
  // --data (and the other server flags) may follow the subcommand: tokens create --data DIR ...
  for (CLI::App* sub : {flags->command, flags->create, flags->list, flags->revoke}) {
    sub->fallthrough();
  }
}

int RunTokensCommand(const TokensCommand& flags, const std::string& data_dir,
                     const std::string& store_url) {
  // With --store the tokens live in that database, and --data is not needed.
  if (store_url.empty()) {
    if (data_dir.empty()) return Fail(Status::InvalidArgument("--data is required"));
    std::error_code error;
    std::filesystem::create_directories(data_dir, error);
    if (error) return Fail(Status::IoError("--data " + data_dir + ": " + error.message()));
  }
  Result<store::OpenedStore> opened = store::OpenStore(store_url, data_dir);
  if (!opened.ok()) return Fail(opened.status());
  store::TokenStore* store = opened->tokens;
  if (flags.create->parsed()) {
    std::optional<std::chrono::seconds> lifetime;
    if (flags.expires_in_days > 0) {
      lifetime = std::chrono::seconds(static_cast<int64_t>(flags.expires_in_days * 86400.0));
    }
    Result<IssuedToken> issued = IssueToken(*store, flags.station, flags.admin, lifetime);
    if (!issued.ok()) return Fail(issued.status());
    if (flags.json) {
      nlohmann::json out = TokenJson(issued->token);
      out["token"] = issued->secret;
      std::cout << out.dump() << "\n";
    } else {
      std::cout << issued->secret << "\n";
      std::fprintf(
          stderr,
          "token %s for station %s%s%s: give it to the station (SOFTID_TOKEN); it is "
          "not shown again\n",
          issued->token.id.c_str(), issued->token.station.c_str(),
          issued->token.admin ? " (admin)" : "",
          issued->token.expires_at ? (", expires " + Iso(issued->token.expires_at)).c_str() : "");
    }
    return kExitOk;
  }
  if (flags.list->parsed()) {
    Result<std::vector<store::ApiToken>> tokens = store->ListTokens();
    if (!tokens.ok()) return Fail(tokens.status());
    nlohmann::json all = nlohmann::json::array();
    for (const store::ApiToken& token : *tokens) all.push_back(TokenJson(token));
    if (flags.json) {
      std::cout << all.dump() << "\n";
    } else {
      for (const nlohmann::json& t : all) {
        std::cout << t["id"].get<std::string>() << "  " << t["station"].get<std::string>()
                  << (t["admin"].get<bool>() ? "  admin" : "") << "  created "
                  << t["created"].get<std::string>();
        if (!t["expires"].get<std::string>().empty()) std::cout << "  expires " << t["expires"];
        if (!t["revoked"].get<std::string>().empty()) std::cout << "  REVOKED " << t["revoked"];
        std::cout << "\n";
      }
    }
    return kExitOk;
  }
  if (Status revoked = store->RevokeToken(flags.token_id); !revoked.ok()) return Fail(revoked);
  if (!flags.json) std::cout << "token " << flags.token_id << " revoked\n";
  return kExitOk;
}

}  // namespace softid::server
