#include "server/store/page_token.h"

#include <gtest/gtest.h>

namespace softid::server::store {
namespace {

// A token decodes to the cursor it was made from when used with the same filter.
TEST(PageToken, RoundTrips) {
  const PageCursor cursor{FromUnixMicros(1'763'712'000'123'456), "job-0123456789abcdef"};
  for (const std::string filter : {"", "state=QUEUED"}) {
    const std::string token = EncodePageToken(cursor, filter);
    EXPECT_EQ(
        token.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_"),
        std::string::npos)
        << "token must be URL-safe: " << token;
    const Result<PageCursor> decoded = DecodePageToken(token, filter);
    ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
    EXPECT_EQ(*decoded, cursor);
  }
}

// Tokens from elsewhere, truncated tokens and tokens for another filter are InvalidArgument.
TEST(PageToken, RejectsForeignTokens) {
  const std::string token = EncodePageToken({FromUnixMicros(5), "job-0123456789abcdef"}, "");
  for (const std::string& bad : {std::string("not a token!"), std::string("djE"),
                                 token.substr(0, token.size() / 2), std::string("AAAA")}) {
    const Result<PageCursor> decoded = DecodePageToken(bad, "");
    ASSERT_FALSE(decoded.ok()) << bad;
    EXPECT_EQ(decoded.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(decoded.status().message().find("page_token = '"), std::string::npos);
  }
  const Result<PageCursor> other_filter = DecodePageToken(token, "state=RUNNING");
  ASSERT_FALSE(other_filter.ok());
  EXPECT_NE(other_filter.status().message().find("was issued for filter '', not 'state=RUNNING'"),
            std::string::npos)
      << other_filter.status().message();
}

}  // namespace
}  // namespace softid::server::store
