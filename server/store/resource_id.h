// Resource ids: a kind prefix and 16 random hex digits ("job-3f9c0a1b2c3d4e5f"). Random rather than
// sequential so ids leak nothing about volume and stay unique across nodes without coordination.
// With 64 bits the chance of any collision among 10^8 ids is about n^2 / 2^65 = 3e-4, and a
// collision fails the insert (PRIMARY KEY) instead of mixing two jobs up.
#pragma once

#include <string>
#include <string_view>

#include "core/common/status.h"

namespace softid::server::store {

inline constexpr std::string_view kCaptureIdPrefix = "cap-";
inline constexpr std::string_view kJobIdPrefix = "job-";

// A fresh id "<prefix><16 lowercase hex digits>" from the operating system's random source.
std::string NewResourceId(std::string_view prefix);

// InvalidArgument unless `id` is "<prefix><16 lowercase hex digits>"; `what` names the field in the
// message ("job id"). Checked at the store's edge so that a malformed id is reported as malformed
// input, not as an unknown resource.
Status CheckResourceId(std::string_view id, std::string_view prefix, std::string_view what);

// Longest idempotency key a client may send (the proto documents it).
inline constexpr size_t kMaxRequestIdLength = 128;

// InvalidArgument naming "request_id" unless it is at most kMaxRequestIdLength bytes without
// control characters (an empty request_id means none and is valid).
Status CheckRequestId(std::string_view request_id);

}  // namespace softid::server::store
