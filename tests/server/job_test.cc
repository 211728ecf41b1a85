#include "server/store/job.h"

#include <gtest/gtest.h>

#include "server/store/progress_event.h"

namespace softid::server::store {
namespace {

// Every state survives ToString -> JobStateFromString; only SUCCEEDED/FAILED/CANCELLED are final.
TEST(JobState, RoundTripsAndTerminality) {
  for (const JobState state : {JobState::kQueued, JobState::kRunning, JobState::kSucceeded,
                               JobState::kFailed, JobState::kCancelled}) {
    const Result<JobState> parsed = JobStateFromString(ToString(state));
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, state);
  }
  EXPECT_FALSE(IsTerminal(JobState::kQueued));
  EXPECT_FALSE(IsTerminal(JobState::kRunning));
  EXPECT_TRUE(IsTerminal(JobState::kSucceeded));
  EXPECT_TRUE(IsTerminal(JobState::kFailed));
  EXPECT_TRUE(IsTerminal(JobState::kCancelled));
}

// An unknown spelling is InvalidArgument listing the accepted ones.
TEST(JobState, RejectsUnknownSpelling) {
  const Result<JobState> parsed = JobStateFromString("queued");
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().message(),
            "job state = 'queued': must be one of QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED");
}

// Progress kinds use the database spellings "iteration" and "state".
TEST(ProgressKind, RoundTrips) {
  EXPECT_EQ(*ProgressKindFromString("iteration"), ProgressKind::kIteration);
  EXPECT_EQ(*ProgressKindFromString("state"), ProgressKind::kState);
  EXPECT_STREQ(ToString(ProgressKind::kState), "state");
  EXPECT_EQ(ProgressKindFromString("STATE").status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace softid::server::store
