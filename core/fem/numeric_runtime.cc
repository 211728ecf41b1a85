#include "core/fem/numeric_runtime.h"

#include <dlfcn.h>

#include <mutex>

// CHOLMOD's supernodal factorisation (Debian's SuiteSparse 5.12, built with OpenMP) opens an OpenMP
// parallel region per supernode (clearing its map, zeroing its block) with a thread count fixed at
// compile time, num_threads(CHOLMOD_OMP_NUM_THREADS = 4), which neither OMP_NUM_THREADS nor
// omp_set_num_threads() overrides; only the OMP_THREAD_LIMIT environment variable does, and only
// when set before the process starts. Thousands of 4-thread team starts per factorisation on 2
// cores spend most of it waking and parking threads: 230 ms vs 88 ms for the torus-drop matrix at
// 3100 cells, and 25 % of the whole simulation. This process-wide definition of libgomp's entry
// point for `#pragma omp parallel` takes precedence over libgomp's (the executable's dynamic
// symbol is bound first) and runs each region on the calling thread: a team of one, which is
// what OpenMP promises when a region runs serialised (omp_get_num_threads() = 1, loops run every
// iteration). Only CHOLMOD enters OpenMP in softid (our code is not built with -fopenmp); softid
// parallelises across optimiser starts and jobs instead.
extern "C" void GOMP_parallel(void (*function)(void*), void* data, unsigned /*num_threads*/,
                              unsigned /*flags*/) {
  function(data);
}

namespace softid::fem {
namespace {

// Our systems have at most a few 10^5 unknowns and softid parallelises across optimiser starts and
// jobs; a threaded BLAS (Debian's OpenBLAS pthread build) then spends most of its time spinning in
// sched_yield on small supernodes. Pin BLAS to one thread when the library offers the switch.
void UseSingleThreadedBlas() {
  using SetThreads = void (*)(int);
  if (auto set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"))) {
    set(1);
  }
}

}  // namespace

void ConfigureNumericRuntime() {
  static std::once_flag once;
  std::call_once(once, [] { UseSingleThreadedBlas(); });
}

}  // namespace softid::fem
