#include "server/periodic_task.h"

namespace softid::server {

PeriodicTask::PeriodicTask(std::chrono::milliseconds interval, std::function<void()> fn)
    : interval_(interval), fn_(std::move(fn)), thread_([this] {
        std::unique_lock lock(mutex_);
        do {
          lock.unlock();
          fn_();
          lock.lock();
        } while (!wake_.wait_for(lock, interval_, [this] { return stopping_; }));
      }) {}

PeriodicTask::~PeriodicTask() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

}  // namespace softid::server
