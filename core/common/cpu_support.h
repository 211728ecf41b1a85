// The build may use vector instructions beyond the x86-64 baseline (CMake SOFTID_CPU_LEVEL; by
// default x86-64-v3 when the build host has it). A program built so dies of an illegal instruction
// on a CPU without them, at whatever point first uses one. This check is compiled for the baseline
// and runs before the program's other static initialisers (and again when called), so such a
// program stops at once with a message naming the level and how to rebuild.
#pragma once

#include "core/common/status.h"

namespace softid {

// The -march level the build was compiled for ("x86-64-v3", "x86-64", "native", ...; empty off
// x86-64).
const char* BuildCpuLevel();

// Ok when this CPU runs what the build was compiled for; FailedPrecondition naming the level and
// the CMake flag to rebuild with otherwise. "native" and unknown levels are taken as supported.
Status CheckCpuSupportsBuild();

// For the programs' main(): referencing it links the start-up check into the program. Returns
// CheckCpuSupportsBuild().ok() (a failing CPU never gets here: the start-up check exits first).
bool CpuSupportsBuild();

}  // namespace softid
