// Invariant checks in three tiers (after Drake's drake_assert.h / drake_throw.h):
//  - SOFTID_DEMAND(cond): always on; a violated internal invariant is a bug, so abort.
//  - SOFTID_ASSERT(cond): like DEMAND but only in debug builds, for costly checks in hot loops.
//  - SOFTID_THROW_UNLESS(cond, message): always on; bad arguments to a core constructor or setter
//    throw std::invalid_argument naming the condition and the message.
// Expected failures (parse, I/O) return Status / Result instead; see status.h.
#pragma once

#include <stdexcept>
#include <string>

namespace softid::internal {
[[noreturn]] void AbortWithMessage(const char* condition, const char* file, int line);
[[noreturn]] void ThrowInvalidArgument(const char* condition, const std::string& message,
                                       const char* file, int line);
}  // namespace softid::internal

#define SOFTID_DEMAND(cond) \
  ((cond) ? (void)0 : ::softid::internal::AbortWithMessage(#cond, __FILE__, __LINE__))

#ifdef NDEBUG
#define SOFTID_ASSERT(cond) ((void)0)
#else
#define SOFTID_ASSERT(cond) SOFTID_DEMAND(cond)
#endif

#define SOFTID_THROW_UNLESS(cond, message) \
  ((cond) ? (void)0                        \
          : ::softid::internal::ThrowInvalidArgument(#cond, (message), __FILE__, __LINE__))
