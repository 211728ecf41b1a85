#include "server/lease_heartbeat.h"

#include <utility>

namespace softid::server {

LeaseHeartbeat::LeaseHeartbeat(LeaseCalls calls, std::chrono::milliseconds interval,
                               std::atomic<bool>& stop)
    : calls_(std::move(calls)), thread_([this, interval, &stop] { Loop(interval, stop); }) {}

LeaseHeartbeat::~LeaseHeartbeat() {
  {
    std::lock_guard lock(mutex_);
    done_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void LeaseHeartbeat::Loop(std::chrono::milliseconds interval, std::atomic<bool>& stop) {
  std::unique_lock lock(mutex_);
  while (!wake_.wait_for(lock, interval, [this] { return done_; })) {
    if (Status renewed = calls_.renew(); !renewed.ok()) {
      if (calls_.on_lost) calls_.on_lost(renewed);
      lost_.store(true);
      stop.store(true);
      return;
    }
    if (calls_.stop_requested && calls_.stop_requested()) {
      stop_requested_.store(true);
      stop.store(true);
    }
  }
}

}  // namespace softid::server
