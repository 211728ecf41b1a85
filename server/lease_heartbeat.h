// Keeps a lease alive while long work runs: on a thread of its own, renews it at an interval and
// polls for a stop request, so that a long first evaluation (before any iteration reports)
// neither loses the lease nor ignores a cancel. A renewal that fails means the lease is lost:
// the work's stop flag is set and nothing more is renewed.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <thread>

#include "core/common/status.h"

namespace softid::server {

struct LeaseCalls {
  std::function<Status()> renew;  // renews the lease; an error means it is lost
  // True when the work should stop although the lease holds (a cancel request); may be empty.
  std::function<bool()> stop_requested;
  // Told why the lease was lost; may be empty.
  std::function<void(const Status&)> on_lost;
};

class LeaseHeartbeat {
 public:
  // Starts renewing every `interval`; sets `stop` when the lease is lost or a stop is requested.
  LeaseHeartbeat(LeaseCalls calls, std::chrono::milliseconds interval, std::atomic<bool>& stop);
  // Stops renewing (joins the thread).
  ~LeaseHeartbeat();
  LeaseHeartbeat(const LeaseHeartbeat&) = delete;
  LeaseHeartbeat& operator=(const LeaseHeartbeat&) = delete;

  bool lost() const { return lost_.load(); }
  bool stop_requested() const { return stop_requested_.load(); }
  // The work saw a stop request itself (e.g. between iterations).
  void set_stop_requested() { stop_requested_.store(true); }

 private:
  void Loop(std::chrono::milliseconds interval, std::atomic<bool>& stop);

  LeaseCalls calls_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool done_ = false;
  std::atomic<bool> lost_{false};
  std::atomic<bool> stop_requested_{false};
  std::thread thread_;  // last: started after the members it uses
};

}  // namespace softid::server
