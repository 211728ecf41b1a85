// API tokens against a real store: issued secrets are never stored, and only a known, unrevoked,
// unexpired token authenticates, as its station.
#include "server/api_tokens.h"

#include <gtest/gtest.h>

#include <memory>

#include "server/store/sha256.h"
#include "server/store/sqlite_job_store.h"
#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

class ApiTokensTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Result<std::unique_ptr<store::SqliteJobStore>> opened =
        store::SqliteJobStore::Open(dir_.path() / "softid.db");
    ASSERT_TRUE(opened.ok()) << opened.status().ToString();
    store_ = std::move(*opened);
  }
  ServiceStatus Refusal(const Authenticator& auth, std::optional<std::string_view> header) {
    return auth.Authenticate(header).status();
  }

  store::testing::TempDir dir_;
  std::unique_ptr<store::SqliteJobStore> store_;
};

TEST_F(ApiTokensTest, IssuedTokenAuthenticatesAsItsStationAndOnlyItsHashIsStored) {
  Result<IssuedToken> issued = IssueToken(*store_, "lab-3", /*admin=*/false, std::nullopt);
  ASSERT_TRUE(issued.ok()) << issued.status().ToString();
  EXPECT_EQ(issued->secret.rfind("softid_", 0), 0u);
  EXPECT_EQ(issued->secret.size(), 7u + 64u);
  EXPECT_EQ(issued->token.secret_sha256, store::Sha256::Hex(issued->secret));
  Result<std::vector<store::ApiToken>> listed = store_->ListTokens();
  ASSERT_TRUE(listed.ok());
  ASSERT_EQ(listed->size(), 1u);
  EXPECT_EQ((*listed)[0], issued->token);

  const Authenticator auth(store_.get(), AuthMode::kToken);
  const std::string header = "Bearer " + issued->secret;
  ServiceResult<Caller> caller = auth.Authenticate(header);
  ASSERT_TRUE(caller.ok()) << caller.status().ToString();
  EXPECT_EQ(caller->station, "lab-3");
  EXPECT_FALSE(caller->admin);

  // Distinct secrets for the same station.
  Result<IssuedToken> second = IssueToken(*store_, "lab-3", /*admin=*/true, std::nullopt);
  ASSERT_TRUE(second.ok());
  EXPECT_NE(second->secret, issued->secret);
  EXPECT_TRUE(auth.Authenticate("Bearer " + second->secret)->admin);
}

TEST_F(ApiTokensTest, MissingUnknownRevokedAndExpiredTokensAreRefused) {
  const Authenticator auth(store_.get(), AuthMode::kToken);
  EXPECT_EQ(Refusal(auth, std::nullopt).code(), ServiceCode::kUnauthenticated);
  EXPECT_EQ(Refusal(auth, "").code(), ServiceCode::kUnauthenticated);
  EXPECT_EQ(Refusal(auth, "Basic abc").code(), ServiceCode::kUnauthenticated);
  EXPECT_EQ(Refusal(auth, "Bearer softid_" + std::string(64, '0')).code(),
            ServiceCode::kUnauthenticated);

  Result<IssuedToken> revoked = IssueToken(*store_, "lab-1", false, std::nullopt);
  ASSERT_TRUE(revoked.ok());
  ASSERT_TRUE(auth.Authenticate("Bearer " + revoked->secret).ok());
  ASSERT_TRUE(store_->RevokeToken(revoked->token.id).ok());
  ASSERT_TRUE(store_->RevokeToken(revoked->token.id).ok());  // idempotent
  const ServiceStatus after = Refusal(auth, "Bearer " + revoked->secret);
  EXPECT_EQ(after.code(), ServiceCode::kUnauthenticated);
  EXPECT_NE(after.message().find("was revoked"), std::string::npos) << after.message();
  EXPECT_EQ(store_->RevokeToken("tok-0123456789abcdef").code(), StatusCode::kNotFound);

  // Expired: made directly in the store with an expiry in the past.
  const std::string secret = "softid_" + std::string(64, 'e');
  ASSERT_TRUE(store_
                  ->CreateToken("lab-2", false,
                                store::ToTimestamp(std::chrono::system_clock::now() -
                                                   std::chrono::seconds(1)),
                                store::Sha256::Hex(secret))
                  .ok());
  const ServiceStatus expired = Refusal(auth, "Bearer " + secret);
  EXPECT_EQ(expired.code(), ServiceCode::kUnauthenticated);
  EXPECT_NE(expired.message().find("has expired"), std::string::npos) << expired.message();

  // Without authentication every caller is the operator.
  const Authenticator open(store_.get(), AuthMode::kNone);
  ServiceResult<Caller> operator_caller = open.Authenticate(std::nullopt);
  ASSERT_TRUE(operator_caller.ok());
  EXPECT_TRUE(operator_caller->admin);
}

TEST_F(ApiTokensTest, StationNamesAreChecked) {
  for (const char* bad : {"", "a b", "lab/3", "ütf", "x\n"}) {
    EXPECT_EQ(IssueToken(*store_, bad, false, std::nullopt).status().code(),
              StatusCode::kInvalidArgument)
        << bad;
  }
  EXPECT_FALSE(IssueToken(*store_, std::string(65, 'a'), false, std::nullopt).ok());
  EXPECT_TRUE(IssueToken(*store_, "Lab_3.north-2", false, std::nullopt).ok());
}

}  // namespace
}  // namespace softid::server
