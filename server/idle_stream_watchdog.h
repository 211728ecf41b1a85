// Ends client streams that stopped sending. gRPC's synchronous API blocks a thread in Read()
// for as long as a client keeps a stream open; 200 idle uploads held 217 threads and their
// staging folders indefinitely. Each watched stream is touched on every message it receives; a
// background thread cancels any stream idle for longer than the timeout (its Read() then returns
// false, the handler returns and its staged files are removed).
#pragma once

#include <chrono>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <thread>

namespace softid::server {

class IdleStreamWatchdog {
 public:
  using Clock = std::chrono::steady_clock;

  // A registered stream; unregisters on destruction. Touch() after every message received.
  class Watch {
   public:
    ~Watch();
    Watch(const Watch&) = delete;
    Watch& operator=(const Watch&) = delete;
    void Touch();

   private:
    friend class IdleStreamWatchdog;
    Watch(IdleStreamWatchdog* owner, uint64_t id) : owner_(owner), id_(id) {}
    IdleStreamWatchdog* owner_;
    uint64_t id_;
  };

  // `idle_timeout` > 0: how long a stream may go without a message; checked every `poll`.
  IdleStreamWatchdog(std::chrono::milliseconds idle_timeout, std::chrono::milliseconds poll);
  ~IdleStreamWatchdog();  // stops the thread; outstanding Watches must be gone
  IdleStreamWatchdog(const IdleStreamWatchdog&) = delete;
  IdleStreamWatchdog& operator=(const IdleStreamWatchdog&) = delete;

  // Starts watching a stream; `cancel` is called once (from the watchdog's thread) if it idles
  // out, and must be safe to call while the stream's handler runs (ServerContext::TryCancel is).
  std::unique_ptr<Watch> Start(std::function<void()> cancel);

  std::chrono::milliseconds idle_timeout() const { return idle_timeout_; }

 private:
  struct Entry {
    Clock::time_point last_activity;
    std::function<void()> cancel;
    bool cancelled = false;
  };
  void Loop();

  const std::chrono::milliseconds idle_timeout_;
  const std::chrono::milliseconds poll_;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  uint64_t next_id_ = 0;
  std::map<uint64_t, Entry> entries_;
  std::thread thread_;  // last: started after the members it uses
};

}  // namespace softid::server
