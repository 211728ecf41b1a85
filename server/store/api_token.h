// Per-station API tokens as the store keeps them: never the secret itself, only its SHA-256, so
// a copy of the database does not let anyone in. See server/api_tokens.h for issuing and
// checking them.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "server/store/timestamp.h"

namespace softid::server::store {

inline constexpr std::string_view kTokenIdPrefix = "tok-";

struct ApiToken {
  std::string id;             // "tok-<16 hex>": names the token in lists and revocations
  std::string station;        // the capture station it belongs to; owns what it creates
  bool admin = false;         // sees and manages every station's captures and jobs
  std::string secret_sha256;  // 64 lowercase hex digits
  Timestamp created_at{};
  std::optional<Timestamp> expires_at;  // refused from then on; nullopt: never expires
  std::optional<Timestamp> revoked_at;  // refused from then on

  bool operator==(const ApiToken&) const = default;
};

// Station names: 1-64 characters of [A-Za-z0-9._-]. InvalidArgument naming "station" otherwise.
Status ValidateStationName(std::string_view station);

// The token store's contract (implemented with the job store, in the same database).
class TokenStore {
 public:
  virtual ~TokenStore() = default;
  // A new token for `station` with the hash of its secret; InvalidArgument for a bad station
  // name or hash.
  virtual Result<ApiToken> CreateToken(const std::string& station, bool admin,
                                       std::optional<Timestamp> expires_at,
                                       const std::string& secret_sha256) = 0;
  // The token whose secret hashes to `secret_sha256`, or nullopt (revoked and expired ones are
  // returned too: the caller decides).
  virtual Result<std::optional<ApiToken>> FindToken(const std::string& secret_sha256) = 0;
  // Every token, oldest first.
  virtual Result<std::vector<ApiToken>> ListTokens() = 0;
  // Marks the token revoked (idempotent); NotFound for an unknown id.
  virtual Status RevokeToken(const std::string& token_id) = 0;
};

}  // namespace softid::server::store
