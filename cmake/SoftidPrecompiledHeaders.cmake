# Precompiled headers: the third-party headers that nearly every file includes (the standard
# library, Eigen, nlohmann-json, spdlog, GoogleTest, CLI11) are parsed once per group of targets
# instead of once per file. Each group compiles its header once in a small anchor target and the
# targets that share the group's compile flags reuse it. docs/benchmarks.md has the build times
# with and without. The fuzz build turns it off: its files are compiled with differing flags.
option(SOFTID_PRECOMPILE_HEADERS "Precompile the third-party headers every file includes" ON)

set(SOFTID_PCH_STANDARD <algorithm> <array> <atomic> <chrono> <cmath> <cstdint> <filesystem>
    <functional> <limits> <map> <memory> <optional> <string> <utility> <vector>)
set(SOFTID_PCH_THIRD_PARTY <Eigen/Core> <Eigen/Geometry> <fmt/format.h> <nlohmann/json.hpp>
    <spdlog/spdlog.h>)

# An anchor: an object library of one empty file whose only product is the group's header.
# LIBS: what the group's targets link (the header's include paths and definitions); HEADERS: those
# beyond the standard library's; DEFINITIONS: the group's targets' own.
function(softid_add_pch_group anchor)
  cmake_parse_arguments(ARG "" "" "LIBS;HEADERS;DEFINITIONS" ${ARGN})
  if(NOT SOFTID_PRECOMPILE_HEADERS)
    return()
  endif()
  set(source ${CMAKE_CURRENT_BINARY_DIR}/${anchor}.cc)
  file(CONFIGURE OUTPUT ${source} CONTENT "// The precompiled header's anchor.\n")
  add_library(${anchor} OBJECT ${source})
  target_link_libraries(${anchor} PRIVATE ${ARG_LIBS})
  target_compile_definitions(${anchor} PRIVATE ${ARG_DEFINITIONS})
  target_precompile_headers(${anchor} PRIVATE ${SOFTID_PCH_STANDARD} ${ARG_HEADERS})
endfunction()

# `target` reuses `anchor`'s precompiled header; its compile flags must match the anchor's.
function(softid_use_pch_group target anchor)
  if(SOFTID_PRECOMPILE_HEADERS)
    target_precompile_headers(${target} REUSE_FROM ${anchor})
  endif()
endfunction()

# A precompiled header of `target`'s own (for a target whose flags match no group's).
function(softid_precompile_headers target)
  if(SOFTID_PRECOMPILE_HEADERS)
    target_precompile_headers(${target} PRIVATE ${SOFTID_PCH_STANDARD} ${ARGN})
  endif()
endfunction()
