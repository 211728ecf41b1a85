// fn(i) for every i in [0, n) on up to `workers` threads (the caller is one of them), each taking
// the next index; returns when all are done. For coarse independent tasks (one ICP, one frame):
// softid's processes serialise OpenMP regions (core/fem/linear_solver.cc), so parallel work at
// this grain uses threads of its own. fn must not throw.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

namespace softid {

// One worker per core the system reports (at least one).
inline int CoreCount() {
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

template <typename Fn>
void ForEachIndex(size_t n, int workers, const Fn& fn) {
  std::atomic<size_t> next{0};
  const auto work = [&] {
    for (size_t i = next++; i < n; i = next++) fn(i);
  };
  std::vector<std::thread> threads;
  const int extra = std::min<long long>(workers, static_cast<long long>(n)) - 1;
  for (int t = 0; t < extra; ++t) threads.emplace_back(work);
  work();
  for (std::thread& thread : threads) thread.join();
}

}  // namespace softid
