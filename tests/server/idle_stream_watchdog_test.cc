#include "server/idle_stream_watchdog.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

namespace softid::server {
namespace {

using std::chrono::milliseconds;

// Waits until `flag` is set or `limit` passes; returns the flag.
bool WaitFor(const std::atomic<bool>& flag, milliseconds limit) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  while (!flag.load() && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(milliseconds(5));
  }
  return flag.load();
}

TEST(IdleStreamWatchdog, AStreamWaitingLongerThanTheTimeoutIsCancelledOnce) {
  IdleStreamWatchdog watchdog(milliseconds(50), milliseconds(5));
  std::atomic<int> cancels{0};
  std::atomic<bool> cancelled{false};
  const auto watch = watchdog.Start([&] {
    ++cancels;
    cancelled.store(true);
  });
  EXPECT_TRUE(WaitFor(cancelled, milliseconds(5000)));
  std::this_thread::sleep_for(milliseconds(100));
  EXPECT_EQ(cancels.load(), 1);
}

// The server's own work between reads (writing a chunk, storing the capture) is not idleness,
// however long it takes; the clock starts again with the next wait.
TEST(IdleStreamWatchdog, TimeOutsideWaitsNeverCounts) {
  IdleStreamWatchdog watchdog(milliseconds(50), milliseconds(5));
  std::atomic<bool> cancelled{false};
  const auto watch = watchdog.Start([&] { cancelled.store(true); });
  watch->EndWait();
  std::this_thread::sleep_for(milliseconds(300));  // six timeouts of work
  EXPECT_FALSE(cancelled.load());
  watch->BeginWait();
  EXPECT_TRUE(WaitFor(cancelled, milliseconds(5000)));
}

TEST(IdleStreamWatchdog, OnlyTheIdleStreamIsCancelled) {
  IdleStreamWatchdog watchdog(milliseconds(50), milliseconds(5));
  std::atomic<bool> idle_cancelled{false}, busy_cancelled{false};
  const auto idle = watchdog.Start([&] { idle_cancelled.store(true); });
  const auto busy = watchdog.Start([&] { busy_cancelled.store(true); });
  busy->EndWait();
  EXPECT_TRUE(WaitFor(idle_cancelled, milliseconds(5000)));
  EXPECT_FALSE(busy_cancelled.load());
}

}  // namespace
}  // namespace softid::server
