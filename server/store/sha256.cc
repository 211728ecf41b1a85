#include "server/store/sha256.h"

#include <openssl/evp.h>

#include "core/common/check.h"

namespace softid::server::store {

// Holds the EVP context; EVP failures only happen on allocation failure or a broken libcrypto, so
// they abort rather than travel as Status.
struct Sha256::Context {
  Context() : ctx(EVP_MD_CTX_new()) {
    SOFTID_DEMAND(ctx != nullptr);
    SOFTID_DEMAND(EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr) == 1);
  }
  ~Context() { EVP_MD_CTX_free(ctx); }
  EVP_MD_CTX* ctx;
};

Sha256::Sha256() : context_(std::make_unique<Context>()) {}
Sha256::~Sha256() = default;
Sha256::Sha256(Sha256&&) noexcept = default;
Sha256& Sha256::operator=(Sha256&&) noexcept = default;

void Sha256::Update(std::string_view bytes) {
  SOFTID_DEMAND(context_ != nullptr);  // not moved-from
  if (bytes.empty()) return;
  SOFTID_DEMAND(EVP_DigestUpdate(context_->ctx, bytes.data(), bytes.size()) == 1);
}

std::string Sha256::FinishHex() {
  SOFTID_DEMAND(context_ != nullptr);
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  SOFTID_DEMAND(EVP_DigestFinal_ex(context_->ctx, digest, &length) == 1);
  SOFTID_DEMAND(length == 32);
  SOFTID_DEMAND(EVP_DigestInit_ex(context_->ctx, EVP_sha256(), nullptr) == 1);
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string hex(2 * length, '0');
  for (unsigned int i = 0; i < length; ++i) {
    hex[2 * i] = kDigits[digest[i] >> 4];
    hex[2 * i + 1] = kDigits[digest[i] & 0xf];
  }
  return hex;
}

std::string Sha256::Hex(std::string_view bytes) {
  Sha256 hasher;
  hasher.Update(bytes);
  return hasher.FinishHex();
}

bool Sha256::IsValidHex(std::string_view hex) {
  if (hex.size() != 64) return false;
  for (const char c : hex) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  }
  return true;
}

}  // namespace softid::server::store
