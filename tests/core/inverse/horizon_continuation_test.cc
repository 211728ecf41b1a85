#include "core/inverse/horizon_continuation.h"

#include <gtest/gtest.h>

#include <stdexcept>

namespace softid::inverse {
namespace {

std::vector<ObservedFrame> Frames(int count) {
  std::vector<ObservedFrame> frames(count);
  for (int k = 0; k < count; ++k) frames[k].frame = k;
  return frames;
}

// A drop: the simulation matches the recording (noise floor 1e-6 m^2) until frame 12, the impact.
std::vector<double> DropCosts(int count, int departure) {
  std::vector<double> costs(count, 1e-6);
  for (int k = departure; k < count; ++k) costs[k] = 5e-5;
  return costs;
}

TEST(HorizonStages, StartShortlyAfterTheDepartureAndDoubleUpToEveryFrame) {
  const std::vector<ObservedFrame> frames = Frames(61);
  const std::vector<int> stages = HorizonStages(frames, DropCosts(61, 12), 0.0);
  // 12 matching frames, then the departing one and 2 after it: 15; 12 + 6 = 18, 12 + 12 = 24,
  // 12 + 24 = 36; 12 + 48 = 60 > 0.8 * 61 is replaced by every frame.
  EXPECT_EQ(stages, (std::vector<int>{15, 18, 24, 36, 61}));
}

TEST(HorizonStages, OneStageWhenNothingDepartsOrTheDepartureIsLate) {
  const std::vector<ObservedFrame> frames = Frames(40);
  EXPECT_EQ(HorizonStages(frames, std::vector<double>(40, 3e-6), 0.0), std::vector<int>{40});
  // Departing below the negligible cost does not count (noise-free captures match at ~0).
  std::vector<double> tiny(40, 1e-14);
  tiny[20] = 1e-12;
  EXPECT_EQ(HorizonStages(frames, tiny, 1e-10), std::vector<int>{40});
  // The first stage would already hold most frames.
  EXPECT_EQ(HorizonStages(frames, DropCosts(40, 33), 0.0), std::vector<int>{40});
  // Twice the floor is not a departure yet.
  std::vector<double> close = DropCosts(40, 10);
  for (int k = 10; k < 40; ++k) close[k] = 1.9e-6;
  EXPECT_EQ(HorizonStages(frames, close, 0.0), std::vector<int>{40});
}

TEST(HorizonStages, CountsFittedFramesAndKeepsHeldOutOnesInsideThePrefix) {
  std::vector<ObservedFrame> frames = Frames(40);
  for (int k = 3; k < 40; k += 4) frames[k].heldout = true;  // every 4th frame
  std::vector<double> costs = DropCosts(40, 8);
  costs[3] = 1.0;  // a held-out frame never departs nor sets the floor
  const std::vector<int> stages = HorizonStages(frames, costs, 0.0);
  // Fitted frames: 0 1 2 4 5 6 8 9 10 12 13 14 16 17 18 20 ...; frame 8 (fitted #7) departs;
  // 6 + 3 = 9 fitted frames end at frame 10 (prefix 11), 6 + 6 = 12 at frame 14 (prefix 15),
  // 6 + 12 = 18 at frame 22 (prefix 23); 6 + 24 = 30 > 0.8 * 30 fitted frames.
  EXPECT_EQ(stages, (std::vector<int>{11, 15, 23, 40}));
}

TEST(HorizonStages, RejectsMismatchedCostsAndAllHeldOut) {
  std::vector<ObservedFrame> frames = Frames(5);
  EXPECT_THROW(HorizonStages(frames, std::vector<double>(4, 1.0), 0.0), std::invalid_argument);
  for (ObservedFrame& f : frames) f.heldout = true;
  EXPECT_THROW(HorizonStages(frames, std::vector<double>(5, 1.0), 0.0), std::invalid_argument);
}

}  // namespace
}  // namespace softid::inverse
