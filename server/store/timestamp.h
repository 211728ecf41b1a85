// Store timestamps: UTC wall-clock time at microsecond resolution, the resolution kept in the
// database (INTEGER microseconds since the Unix epoch), so a value read back compares equal to the
// value written.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>

namespace softid::server::store {

using Timestamp = std::chrono::sys_time<std::chrono::microseconds>;

// Where the store reads the time; injected so tests can step it (lease expiry, ordering).
using Clock = std::function<std::chrono::system_clock::time_point()>;

inline Timestamp ToTimestamp(std::chrono::system_clock::time_point t) {
  return std::chrono::floor<std::chrono::microseconds>(t);
}
inline int64_t ToUnixMicros(Timestamp t) {
  return t.time_since_epoch().count();
}
inline Timestamp FromUnixMicros(int64_t us) {
  return Timestamp(std::chrono::microseconds(us));
}

}  // namespace softid::server::store
