// Process-wide settings of the numerical libraries softid links, in one place:
//  - CHOLMOD's OpenMP regions run on the calling thread (this unit defines libgomp's entry point
//    GOMP_parallel for the whole process; see numeric_runtime.cc for why and what it saves);
//  - OpenBLAS runs single-threaded.
// softid parallelises across optimiser starts, jobs and its own thread teams
// (core/common/for_each_index.h, core/fem/thread_team.h) instead. Every program's main calls
// ConfigureNumericRuntime() first; LinearSolver calls it too, so a library user (a test) gets the
// same settings without knowing.
#pragma once

namespace softid::fem {

// Applies the settings above. Idempotent and thread-safe.
void ConfigureNumericRuntime();

}  // namespace softid::fem
