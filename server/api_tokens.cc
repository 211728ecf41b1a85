#include "server/api_tokens.h"

#include <random>

#include "server/store/sha256.h"

namespace softid::server {
namespace {

constexpr std::string_view kSecretPrefix = "softid_";
constexpr std::string_view kBearer = "Bearer ";

// 32 bytes from the operating system's random source, as hex.
std::string RandomHex32() {
  std::random_device device;
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  for (int i = 0; i < 8; ++i) {
    uint32_t word = device();
    for (int b = 0; b < 8; ++b, word >>= 4) out.push_back(kHex[word & 0xf]);
  }
  return out;
}

}  // namespace

const char* ToString(AuthMode mode) {
  return mode == AuthMode::kToken ? "token" : "none";
}

Result<IssuedToken> IssueToken(store::TokenStore& tokens, const std::string& station, bool admin,
                               std::optional<std::chrono::seconds> lifetime) {
  IssuedToken issued;
  issued.secret = std::string(kSecretPrefix) + RandomHex32();
  std::optional<store::Timestamp> expires;
  if (lifetime.has_value()) {
    expires = store::ToTimestamp(std::chrono::system_clock::now() + *lifetime);
  }
  SOFTID_ASSIGN_OR_RETURN(
      issued.token, tokens.CreateToken(station, admin, expires, store::Sha256::Hex(issued.secret)));
  return issued;
}

ServiceResult<Caller> Authenticator::Authenticate(
    std::optional<std::string_view> authorization) const {
  if (mode_ == AuthMode::kNone) return Caller::Operator();
  const auto refuse = [](const std::string& why) {
    return ServiceStatus(ServiceCode::kUnauthenticated, why);
  };
  if (!authorization.has_value() || authorization->empty()) {
    return refuse(
        "this server requires an API token (authorization: Bearer <token>; the "
        "client reads SOFTID_TOKEN)");
  }
  if (authorization->rfind(kBearer, 0) != 0) {
    return refuse("authorization: expected \"Bearer <token>\"");
  }
  const std::string_view secret = authorization->substr(kBearer.size());
  if (secret.rfind(kSecretPrefix, 0) != 0) return refuse("the API token is not valid");
  Result<std::optional<store::ApiToken>> token = tokens_->FindToken(store::Sha256::Hex(secret));
  if (!token.ok()) return token.status();
  if (!token->has_value()) return refuse("the API token is not valid");
  const store::ApiToken& found = **token;
  const store::Timestamp now = store::ToTimestamp(std::chrono::system_clock::now());
  if (found.revoked_at.has_value()) return refuse("the API token " + found.id + " was revoked");
  if (found.expires_at.has_value() && *found.expires_at <= now) {
    return refuse("the API token " + found.id + " has expired");
  }
  return Caller{found.station, found.admin};
}

}  // namespace softid::server
