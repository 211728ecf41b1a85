#include "core/common/cpu_support.h"

#include <cstdio>
#include <cstdlib>
#include <string>

#ifndef SOFTID_BUILD_CPU_LEVEL
#define SOFTID_BUILD_CPU_LEVEL ""
#endif

namespace softid {

const char* BuildCpuLevel() {
  return SOFTID_BUILD_CPU_LEVEL;
}

Status CheckCpuSupportsBuild() {
  const std::string level = BuildCpuLevel();
  bool supported = true;
#if defined(__x86_64__)
  __builtin_cpu_init();  // may run before the runtime's own initialisation
  if (level == "x86-64-v2") supported = __builtin_cpu_supports("x86-64-v2");
  if (level == "x86-64-v3") supported = __builtin_cpu_supports("x86-64-v3");
  if (level == "x86-64-v4") supported = __builtin_cpu_supports("x86-64-v4");
#endif
  if (supported) return Status::Ok();
  return Status::FailedPrecondition("this softid build needs an " + level +
                                    " CPU (built with -march=" + level +
                                    "), which this machine is not; rebuild with "
                                    "-DSOFTID_CPU_LEVEL=x86-64 to run here");
}

bool CpuSupportsBuild() {
  return CheckCpuSupportsBuild().ok();
}

namespace {

// Priority 101: before the default-priority initialisers of the rest of the program, which are
// compiled for the build's level.
__attribute__((constructor(101))) void StopOnUnsupportedCpu() {
  const Status status = CheckCpuSupportsBuild();
  if (status.ok()) return;
  std::fprintf(stderr, "error: %s\n", status.message().c_str());
  std::_Exit(2);
}

}  // namespace
}  // namespace softid
