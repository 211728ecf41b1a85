#include "core/common/status.h"

#include <gtest/gtest.h>

#include "core/common/check.h"

namespace softid {
namespace {

Result<int> ParsePositive(int x) {
  if (x <= 0) return Status::InvalidArgument("x = " + std::to_string(x) + ": must be positive");
  return x;
}

Status UsesAssignOrReturn(int x, int* out) {
  SOFTID_ASSIGN_OR_RETURN(int value, ParsePositive(x));
  *out = value;
  return Status::Ok();
}

// A Result carries either the value or the error with its message.
TEST(Status, ResultHoldsValueOrError) {
  EXPECT_TRUE(ParsePositive(3).ok());
  EXPECT_EQ(*ParsePositive(3), 3);
  const Result<int> bad = ParsePositive(-2);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.status().ToString(), "INVALID_ARGUMENT: x = -2: must be positive");
}

// SOFTID_ASSIGN_OR_RETURN propagates the error and WithContext prefixes it.
TEST(Status, AssignOrReturnPropagates) {
  int out = 0;
  EXPECT_TRUE(UsesAssignOrReturn(5, &out).ok());
  EXPECT_EQ(out, 5);
  const Status s = UsesAssignOrReturn(0, &out).WithContext("job.json");
  EXPECT_EQ(s.message(), "job.json: x = 0: must be positive");
}

// SOFTID_THROW_UNLESS throws std::invalid_argument naming the message.
TEST(Check, ThrowUnlessNamesTheMessage) {
  try {
    SOFTID_THROW_UNLESS(1 + 1 == 3, "arithmetic is broken");
    FAIL() << "expected a throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("arithmetic is broken"), std::string::npos);
  }
}

}  // namespace
}  // namespace softid
