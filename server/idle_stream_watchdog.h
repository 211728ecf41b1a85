// Ends client streams that stopped sending. gRPC's synchronous API blocks a thread in Read()
// for as long as a client keeps a stream open; 200 idle uploads held 217 threads and their
// staging folders indefinitely. A handler marks each wait for the client's next message; a
// background thread cancels any stream that has waited longer than the timeout (its Read() then
// returns false, the handler returns and its staged files are removed). Only waits count: the
// server's own work on a message (writing a chunk, storing the finished capture) can be slow on
// a loaded machine and is never the client's idleness.
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

  // A registered stream, waiting for the client from Start(); unregisters on destruction.
  class Watch {
   public:
    ~Watch();
    Watch(const Watch&) = delete;
    Watch& operator=(const Watch&) = delete;
    // Around every blocking read: the idle clock runs from BeginWait() until EndWait().
    void BeginWait();
    void EndWait();

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

  // Starts watching a stream, waiting from now; `cancel` is called once (from the watchdog's
  // thread) if it idles out, and must be safe to call while the stream's handler runs
  // (ServerContext::TryCancel is).
  std::unique_ptr<Watch> Start(std::function<void()> cancel);

  std::chrono::milliseconds idle_timeout() const { return idle_timeout_; }

 private:
  struct Entry {
    Clock::time_point wait_began;
    std::function<void()> cancel;
    bool waiting = true;
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
