// Incremental SHA-256 (FIPS 180-4) over libcrypto's EVP interface, as lowercase hex: the names of
// content-addressed blobs and the checksums in capture manifests.
#pragma once

#include <memory>
#include <string>
#include <string_view>

namespace softid::server::store {

class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(Sha256&&) noexcept;
  Sha256& operator=(Sha256&&) noexcept;
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;

  void Update(std::string_view bytes);
  // The 64-character lowercase hex digest of everything passed to Update. Afterwards the hasher
  // starts over as if newly constructed.
  std::string FinishHex();

  // One-shot digest of `bytes`.
  static std::string Hex(std::string_view bytes);
  // True for exactly 64 lowercase hex digits: the only spelling the store accepts, so that one
  // blob never has two names.
  static bool IsValidHex(std::string_view hex);

 private:
  struct Context;
  std::unique_ptr<Context> context_;
};

}  // namespace softid::server::store
