// Open3D parallelises each small ICP or RANSAC call with OpenMP; on a busy machine the threads'
// spin-waits cost more than the work (a registration took 2.4x longer on 2 loaded cores than
// with one thread). Within this guard the calling thread's OpenMP regions run on `threads`
// threads; OpenMP keeps that setting per thread, so other threads are unaffected.
#pragma once

#include <omp.h>

namespace softid::ingest {

class ScopedOpenMPThreads {
 public:
  explicit ScopedOpenMPThreads(int threads) : previous_(omp_get_max_threads()) {
    omp_set_num_threads(threads);
  }
  ~ScopedOpenMPThreads() { omp_set_num_threads(previous_); }
  ScopedOpenMPThreads(const ScopedOpenMPThreads&) = delete;
  ScopedOpenMPThreads& operator=(const ScopedOpenMPThreads&) = delete;

 private:
  int previous_;
};

}  // namespace softid::ingest
