#include "server/store/resource_id.h"

#include <gtest/gtest.h>

#include <set>

namespace softid::server::store {
namespace {

// New ids have the prefix and 16 hex digits, pass the check, and do not repeat.
TEST(ResourceId, NewIdsAreWellFormedAndDistinct) {
  std::set<std::string> ids;
  for (int i = 0; i < 1000; ++i) {
    const std::string id = NewResourceId(kJobIdPrefix);
    ASSERT_EQ(id.size(), 20u);
    EXPECT_TRUE(CheckResourceId(id, kJobIdPrefix, "job id").ok()) << id;
    ids.insert(id);
  }
  EXPECT_EQ(ids.size(), 1000u);
}

// A malformed id is reported as such, naming the field and the expected form.
TEST(ResourceId, RejectsMalformedIds) {
  const Status wrong_prefix = CheckResourceId("cap-0123456789abcdef", kJobIdPrefix, "job id");
  EXPECT_EQ(wrong_prefix.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(wrong_prefix.message(),
            "job id = 'cap-0123456789abcdef': must be 'job-' and 16 lowercase hex digits");
  EXPECT_FALSE(CheckResourceId("job-0123456789ABCDEF", kJobIdPrefix, "job id").ok());
  EXPECT_FALSE(CheckResourceId("job-0123", kJobIdPrefix, "job id").ok());
  EXPECT_FALSE(CheckResourceId("", kJobIdPrefix, "job id").ok());
}

}  // namespace
}  // namespace softid::server::store
