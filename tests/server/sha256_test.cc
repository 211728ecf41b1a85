#include "server/store/sha256.h"

#include <gtest/gtest.h>

#include <string>

namespace softid::server::store {
namespace {

// FIPS 180-4 / NIST test vectors.
TEST(Sha256, KnownVectors) {
  EXPECT_EQ(Sha256::Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(Sha256::Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(Sha256::Hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
}

// Hashing in pieces gives the one-shot digest, and the hasher restarts after FinishHex.
TEST(Sha256, IncrementalMatchesOneShot) {
  std::string data(1 << 20, '\0');
  for (size_t i = 0; i < data.size(); ++i) data[i] = static_cast<char>((i * 131) & 0xff);
  Sha256 hasher;
  for (size_t start = 0; start < data.size(); start += 7777) {
    hasher.Update(std::string_view(data).substr(start, 7777));
  }
  EXPECT_EQ(hasher.FinishHex(), Sha256::Hex(data));
  hasher.Update("abc");
  EXPECT_EQ(hasher.FinishHex(), Sha256::Hex("abc"));
}

// Only 64 lowercase hex digits name a blob.
TEST(Sha256, IsValidHex) {
  EXPECT_TRUE(Sha256::IsValidHex(Sha256::Hex("x")));
  EXPECT_FALSE(Sha256::IsValidHex(""));
  EXPECT_FALSE(Sha256::IsValidHex(std::string(63, 'a')));
  EXPECT_FALSE(Sha256::IsValidHex(std::string(64, 'A')));
  EXPECT_FALSE(Sha256::IsValidHex(std::string(63, 'a') + "g"));
}

}  // namespace
}  // namespace softid::server::store
