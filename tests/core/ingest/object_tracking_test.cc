// Which foreground regions are the object: regions stand in by their size and centre only.
#include "core/ingest/object_tracking.h"

#include <gtest/gtest.h>

namespace softid::ingest {
namespace {

ForegroundRegion Region(int pixels, const Eigen::Vector3d& centroid_C, int first_pixel) {
  ForegroundRegion region;
  for (int p = 0; p < pixels; ++p) region.pixels.push_back(first_pixel + p);
  region.centroid_C = centroid_C;
  return region;
}

// The camera 1 m above the world origin, looking down.
Eigen::Isometry3d CameraAbove() {
  Eigen::Isometry3d X_WC = Eigen::Isometry3d::Identity();
  X_WC.translation() = Eigen::Vector3d(0, 0, 1);
  X_WC.linear() = Eigen::Vector3d(1, -1, -1).asDiagonal();
  return X_WC;
}

// In the first frame the largest region is the object, with the regions about it (a ring's far
// side past a depth jump); a region farther than 1.5 object radii is something else.
TEST(ObjectTracker, FirstFrameTakesTheLargestRegionAndItsNeighbours) {
  ObjectTracker tracker(0.1);
  Foreground fg;
  fg.regions.push_back(Region(500, Eigen::Vector3d(0, 0, 0.9), 0));
  fg.regions.push_back(Region(80, Eigen::Vector3d(0.08, 0, 0.92), 1000));  // 8 cm away: a part
  fg.regions.push_back(Region(200, Eigen::Vector3d(0.5, 0, 0.9), 2000));   // 50 cm away
  const TrackedFrame first = tracker.Track(fg, CameraAbove(), 0.0);
  ASSERT_TRUE(first.found);
  EXPECT_EQ(first.regions, 2);
  EXPECT_EQ(first.rejected_regions, 1);
  EXPECT_EQ(first.pixels.size(), 580u);
}

// Afterwards the reach grows with the time since the object was last seen: 1.5 radii plus 10 m/s.
TEST(ObjectTracker, LaterFramesTakeRegionsWithinReachOfWhereTheObjectWas) {
  ObjectTracker tracker(0.1);
  Foreground fg;
  fg.regions.push_back(Region(500, Eigen::Vector3d(0, 0, 0.9), 0));
  ASSERT_TRUE(tracker.Track(fg, CameraAbove(), 0.0).found);
  Foreground moved;
  moved.regions.push_back(Region(300, Eigen::Vector3d(0.4, 0, 0.9), 0));  // 40 cm away
  EXPECT_FALSE(tracker.Track(moved, CameraAbove(), 0.01).found);          // reach 0.25 m
  const TrackedFrame later = tracker.Track(moved, CameraAbove(), 0.03);   // reach 0.45 m
  ASSERT_TRUE(later.found);
  EXPECT_NEAR(later.centre_W.x(), 0.4, 1e-12);
  EXPECT_NEAR(later.centre_W.z(), 0.1, 1e-12);
}

TEST(ObjectTracker, NoRegionsNothingFound) {
  ObjectTracker tracker(0.1);
  EXPECT_FALSE(tracker.Track(Foreground{}, CameraAbove(), 0.0).found);
}

}  // namespace
}  // namespace softid::ingest
