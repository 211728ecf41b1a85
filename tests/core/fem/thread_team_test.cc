// ThreadTeam: every member runs once per region, on threads of its own, and exceptions reach the
// caller.
#include "core/fem/thread_team.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <set>
#include <stdexcept>
#include <thread>

namespace softid::fem {
namespace {

TEST(ThreadTeam, EveryMemberRunsOncePerRegion) {
  ThreadTeam team(3);
  ASSERT_EQ(team.size(), 3);
  std::vector<int> runs(3, 0);
  constexpr int kRegions = 2000;
  for (int region = 0; region < kRegions; ++region) team.Run([&](int member) { ++runs[member]; });
  EXPECT_EQ(runs, std::vector<int>(3, kRegions));
}

TEST(ThreadTeam, MembersRunConcurrentlyOnTheirOwnThreads) {
  ThreadTeam team(2);
  std::atomic<int> arrived{0};
  std::thread::id ids[2];
  // Each member waits until both have arrived: this only finishes if they run concurrently.
  team.Run([&](int member) {
    ids[member] = std::this_thread::get_id();
    ++arrived;
    while (arrived.load() < 2) std::this_thread::yield();
  });
  EXPECT_EQ(ids[0], std::this_thread::get_id());
  EXPECT_NE(ids[1], ids[0]);
}

TEST(ThreadTeam, TeamOfOneRunsOnTheCaller) {
  ThreadTeam team(1);
  std::thread::id id;
  team.Run([&](int member) {
    EXPECT_EQ(member, 0);
    id = std::this_thread::get_id();
  });
  EXPECT_EQ(id, std::this_thread::get_id());
}

TEST(ThreadTeam, ExceptionReachesTheCallerAndTheTeamStaysUsable) {
  ThreadTeam team(2);
  EXPECT_THROW(team.Run([](int member) {
    if (member == 1) throw std::runtime_error("member 1 failed");
  }),
               std::runtime_error);
  int runs = 0;
  team.Run([&](int member) {
    if (member == 1) ++runs;
  });
  EXPECT_EQ(runs, 1);
}

// A background job runs beside the caller; meanwhile every member's task runs on the caller, and
// once the job has finished the members are back on their own threads.
TEST(ThreadTeam, BackgroundJobRunsBesideTheCaller) {
  ThreadTeam team(2);
  std::atomic<bool> release{false}, job_done{false};
  team.StartBackground([&] {
    while (!release.load()) std::this_thread::yield();  // finishes only if the caller goes on
    job_done = true;
  });
  EXPECT_TRUE(team.BackgroundRunning());
  std::thread::id ids[2];
  team.Run([&](int member) { ids[member] = std::this_thread::get_id(); });
  EXPECT_EQ(ids[0], std::this_thread::get_id());
  EXPECT_EQ(ids[1], std::this_thread::get_id());
  release = true;
  team.WaitForBackground();
  EXPECT_TRUE(job_done.load());
  EXPECT_FALSE(team.BackgroundRunning());
  team.Run([&](int member) { ids[member] = std::this_thread::get_id(); });
  EXPECT_NE(ids[1], std::this_thread::get_id());
}

TEST(ThreadTeam, RejectsAnEmptyTeam) {
  EXPECT_THROW(ThreadTeam(0), std::invalid_argument);
}

TEST(ThreadTeam, RejectsANegativeSpin) {
  EXPECT_THROW(ThreadTeam(2, std::chrono::microseconds(-1)), std::invalid_argument);
}

// Whether the members spin between regions or sleep at once, and whether the regions come back to
// back or after serial work longer than the spin (the workers then fall asleep), every member runs
// every region exactly once and sees the caller's writes from before the region.
TEST(ThreadTeam, EveryRegionRunsOnceWhetherMembersSpinOrSleep) {
  for (const int spin_us : {0, 50, 500}) {
    ThreadTeam team(2, std::chrono::microseconds(spin_us));
    std::vector<int> runs(2, 0);
    int published = 0;
    std::atomic<int> mismatches{0};
    for (int region = 0; region < 300; ++region) {
      published = region;
      if (region % 50 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
      team.Run([&](int member) {
        ++runs[member];
        if (published != region) ++mismatches;
      });
    }
    EXPECT_EQ(runs, std::vector<int>(2, 300)) << "spin " << spin_us << " us";
    EXPECT_EQ(mismatches.load(), 0) << "spin " << spin_us << " us";
  }
}

}  // namespace
}  // namespace softid::fem
