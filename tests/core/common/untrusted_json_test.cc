#include "core/common/untrusted_json.h"

#include <gtest/gtest.h>

#include <string>
#include <thread>

#include "core/common/json_fields.h"

namespace softid::json {
namespace {

std::string Nested(int depth) {
  return std::string(depth, '[') + std::string(depth, ']');
}

TEST(UntrustedJsonTest, ParsesOrdinaryJson) {
  const Result<nlohmann::json> value =
      ParseUntrustedJson(R"({"fit": ["youngs_modulus"], "cells": 12})", "config_json");
  ASSERT_TRUE(value.ok()) << value.status().ToString();
  EXPECT_EQ((*value)["cells"], 12);
  EXPECT_EQ((*value)["fit"][0], "youngs_modulus");
}

// 100,000 nested arrays (200 KB) used to overflow the stack of a gRPC thread when the parsed
// value was copied or printed. Run on a thread with a small stack, as gRPC's are.
TEST(UntrustedJsonTest, DeepNestingIsRefusedWithoutRecursion) {
  Status status;
  std::thread parser([&] { status = ParseUntrustedJson(Nested(100000), "config_json").status(); });
  parser.join();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(), "config_json: nested deeper than 32 levels of arrays and objects");
}

TEST(UntrustedJsonTest, DepthLimitIsExact) {
  UntrustedJsonLimits limits;
  limits.max_depth = 3;
  EXPECT_TRUE(ParseUntrustedJson(Nested(3), "x", limits).ok());
  EXPECT_FALSE(ParseUntrustedJson(Nested(4), "x", limits).ok());
  EXPECT_TRUE(ParseUntrustedJson(R"({"a": {"b": [1, 2]}})", "x", limits).ok());
  EXPECT_FALSE(ParseUntrustedJson(R"({"a": {"b": [[1], 2]}})", "x", limits).ok());
  EXPECT_TRUE(ParseUntrustedJson("7", "x", limits).ok());
}

TEST(UntrustedJsonTest, SizeLimitNamesFieldAndLimit) {
  UntrustedJsonLimits limits;
  limits.max_bytes = 10;
  const Status status = ParseUntrustedJson(R"({"cells": 12345})", "config_json", limits).status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(status.message(), "config_json: 16 bytes: at most 10 are accepted");
}

TEST(UntrustedJsonTest, SyntaxErrorNamesPositionAndField) {
  const Status status =
      ParseUntrustedJson(R"({"cameras": [{"fx": NaN}]})", "capture_json").status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("capture_json: invalid JSON at byte"), std::string::npos)
      << status.message();
  EXPECT_NE(status.message().find("(in cameras[0].fx)"), std::string::npos) << status.message();
  EXPECT_NE(status.message().find("NaN and Infinity are not JSON numbers"), std::string::npos)
      << status.message();

  const Status second = ParseUntrustedJson(R"({"a": [1, 2, Infinity]})", "x").status();
  EXPECT_NE(second.message().find("(in a[2])"), std::string::npos) << second.message();
  EXPECT_FALSE(ParseUntrustedJson("", "x").ok());
  EXPECT_FALSE(ParseUntrustedJson("{} extra", "x").ok());
}

TEST(UntrustedJsonTest, InvalidLimitsAreNamed) {
  UntrustedJsonLimits limits;
  limits.max_depth = 0;
  EXPECT_NE(ParseUntrustedJson("1", "x", limits).status().message().find("max_depth = 0"),
            std::string::npos);
}

// Error messages quote values shortened to 80 bytes, never inside a multi-byte character, and
// show invalid UTF-8 as U+FFFD instead of throwing.
TEST(JsonBriefTest, ShortenedValuesStayValidUtf8) {
  for (int pad = 0; pad < 4; ++pad) {
    std::string value = std::string(pad, 'a');
    for (int i = 0; i < 40; ++i) value += "\xc3\xa9";  // é
    const std::string brief = Brief(value);
    EXPECT_LE(brief.size(), 80u);
    ASSERT_EQ(brief.substr(brief.size() - 3), "...");
    const std::string kept = brief.substr(0, brief.size() - 3);
    // A JSON string of the kept bytes parses: no character was cut.
    EXPECT_TRUE(ParseUntrustedJson(kept + "\"", "x").ok()) << brief;
  }
  EXPECT_NO_THROW(Brief(std::string("bad \xff byte")));
  EXPECT_NE(Brief(std::string("bad \xff byte")).find("\xef\xbf\xbd"), std::string::npos);
}

}  // namespace
}  // namespace softid::json
