#include "server/rate_limiter.h"

#include <gtest/gtest.h>

namespace softid::server {
namespace {

TEST(RateLimiter, BurstThenSustainedRatePerKey) {
  auto now = std::chrono::steady_clock::time_point();
  RateLimiter limiter(/*rate_per_second=*/2.0, /*burst=*/3.0, [&] { return now; });
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(limiter.Admit("a")) << i;
  EXPECT_FALSE(limiter.Admit("a"));
  EXPECT_TRUE(limiter.Admit("b"));        // its own bucket
  now += std::chrono::milliseconds(500);  // one token back at 2 per second
  EXPECT_TRUE(limiter.Admit("a"));
  EXPECT_FALSE(limiter.Admit("a"));
  now += std::chrono::seconds(100);  // refills up to the burst, not beyond
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(limiter.Admit("a")) << i;
  EXPECT_FALSE(limiter.Admit("a"));
}

TEST(RateLimiter, ZeroRateAdmitsEverything) {
  RateLimiter limiter(0.0, 1.0);
  for (int i = 0; i < 1000; ++i) ASSERT_TRUE(limiter.Admit("a"));
}

}  // namespace
}  // namespace softid::server
