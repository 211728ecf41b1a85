#include "core/common/cpu_support.h"

#include <gtest/gtest.h>

#include <string>

namespace softid {
namespace {

// The build records the -march level CMake resolved (an empty one would mean the check never
// knows what to look for), and the machine that built and runs the tests runs that level.
TEST(CpuSupport, BuildLevelIsRecordedAndThisHostRunsIt) {
#if defined(__x86_64__)
  const std::string level = BuildCpuLevel();
  EXPECT_FALSE(level.empty());
#if defined(__AVX2__)
  EXPECT_NE(level, "x86-64") << "the code was compiled with AVX2 but the level says baseline";
#endif
#endif
  const Status status = CheckCpuSupportsBuild();
  EXPECT_TRUE(status.ok()) << status.ToString();
  EXPECT_TRUE(CpuSupportsBuild());
}

}  // namespace
}  // namespace softid
