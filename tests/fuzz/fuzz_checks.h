// What the fuzz targets demand of a parser beyond not crashing: a rejected input comes back as a
// Status with code InvalidArgument and a message (parsers of untrusted input have no other way to
// fail), and an accepted one passes the target's own checks. A violation aborts, which libFuzzer
// reports like a crash, with the input that caused it.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>

#include "core/common/status.h"

namespace softid::fuzz {

// Aborts naming `what` (and `detail`, e.g. a status message) when `condition` is false. Unlike
// assert, on in every build type.
inline void Require(bool condition, const char* what, const std::string& detail = "") {
  if (condition) return;
  std::fprintf(stderr, "fuzz check failed: %s%s%s\n", what, detail.empty() ? "" : ": ",
               detail.c_str());
  std::abort();
}

// The rejection of an input by a parser: InvalidArgument with a message saying why.
inline void RequireRejection(const Status& status) {
  Require(status.code() == StatusCode::kInvalidArgument,
          "a parser failed with a code other than INVALID_ARGUMENT", status.ToString());
  Require(!status.message().empty(), "a parser rejected an input without a message");
}

}  // namespace softid::fuzz
