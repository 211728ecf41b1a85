# Debian's SuiteSparse 5.x ships no CMake package: find CHOLMOD and its BLAS by hand.
find_path(CHOLMOD_INCLUDE_DIR cholmod.h PATH_SUFFIXES suitesparse)
find_library(CHOLMOD_LIBRARY cholmod)
find_library(SUITESPARSE_CONFIG_LIBRARY suitesparseconfig)
find_package(BLAS REQUIRED)
find_package(LAPACK REQUIRED)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(Cholmod REQUIRED_VARS CHOLMOD_LIBRARY CHOLMOD_INCLUDE_DIR)
if(Cholmod_FOUND AND NOT TARGET Cholmod::cholmod)
  add_library(Cholmod::cholmod INTERFACE IMPORTED)
  set_target_properties(Cholmod::cholmod PROPERTIES
    INTERFACE_INCLUDE_DIRECTORIES "${CHOLMOD_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "${CHOLMOD_LIBRARY};${SUITESPARSE_CONFIG_LIBRARY};${LAPACK_LIBRARIES};${BLAS_LIBRARIES}")
endif()
