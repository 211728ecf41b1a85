// Per-station API tokens: issued once (the secret is shown to the operator and never stored),
// sent by clients as "authorization: Bearer <token>" metadata, and checked on every call against
// the hashes in the store. A token may expire and can be revoked; either takes effect on the
// next call.
#pragma once

#include <chrono>
#include <optional>
#include <string>
#include <string_view>

#include "server/caller.h"
#include "server/service_status.h"
#include "server/store/api_token.h"

namespace softid::server {

// Whether calls must carry a token.
enum class AuthMode {
  kNone,   // every caller is the operator (Caller::Operator); for loopback and tests
  kToken,  // a valid token is required; the caller is its station
};
// "none" | "token".
const char* ToString(AuthMode mode);

// A token as issued: the record the store keeps and the secret handed to the station.
struct IssuedToken {
  store::ApiToken token;
  std::string secret;  // "softid_" + 64 hex digits; shown once
};

// Issues a token for `station` that expires after `lifetime` (nullopt: never).
Result<IssuedToken> IssueToken(store::TokenStore& tokens, const std::string& station, bool admin,
                               std::optional<std::chrono::seconds> lifetime);

class Authenticator {
 public:
  // `tokens` must outlive the authenticator (unused with AuthMode::kNone).
  Authenticator(store::TokenStore* tokens, AuthMode mode) : tokens_(tokens), mode_(mode) {}

  // The caller presenting `authorization` (the metadata value, nullopt when absent).
  // Unauthenticated, with a reason that names no other station, when the token is missing,
  // malformed, unknown, revoked or expired.
  ServiceResult<Caller> Authenticate(std::optional<std::string_view> authorization) const;

  AuthMode mode() const { return mode_; }

 private:
  store::TokenStore* tokens_;
  AuthMode mode_;
};

}  // namespace softid::server
