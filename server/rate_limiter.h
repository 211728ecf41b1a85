// Requests per second per station, as token buckets: each station may burst up to `burst`
// requests and then `rate` per second. Keeps one client from starving the others' RPC threads.
#pragma once

#include <chrono>
#include <functional>
#include <map>
#include <mutex>
#include <string>

namespace softid::server {

class RateLimiter {
 public:
  using Clock = std::function<std::chrono::steady_clock::time_point()>;

  // `rate` <= 0 admits everything. `clock` defaults to steady_clock::now (tests step it).
  RateLimiter(double rate_per_second, double burst, Clock clock = {});

  // Takes one request from `key`'s bucket: false when it is empty.
  bool Admit(const std::string& key);

 private:
  struct Bucket {
    double tokens = 0.0;
    std::chrono::steady_clock::time_point refilled;
  };
  const double rate_, burst_;
  Clock clock_;
  std::mutex mutex_;
  std::map<std::string, Bucket> buckets_;
};

}  // namespace softid::server
