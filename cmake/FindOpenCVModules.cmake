# Finds the OpenCV modules softid uses (core, imgcodecs, imgproc, calib3d) from Debian's
# per-module -dev packages; the full libopencv-dev (which carries OpenCVConfig.cmake) pulls ~250
# packages we do not need. Defines OpenCV::core, OpenCV::imgcodecs, OpenCV::imgproc and
# OpenCV::calib3d (lens distortion).
find_path(OpenCVModules_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4)
set(_softid_opencv_vars OpenCVModules_INCLUDE_DIR)
foreach(module core imgcodecs imgproc calib3d)
  find_library(OpenCVModules_${module}_LIBRARY opencv_${module})
  list(APPEND _softid_opencv_vars OpenCVModules_${module}_LIBRARY)
endforeach()
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(OpenCVModules REQUIRED_VARS ${_softid_opencv_vars})
if(OpenCVModules_FOUND)
  foreach(module core imgcodecs imgproc calib3d)
    if(NOT TARGET OpenCV::${module})
      add_library(OpenCV::${module} UNKNOWN IMPORTED)
      set_target_properties(OpenCV::${module} PROPERTIES
        IMPORTED_LOCATION "${OpenCVModules_${module}_LIBRARY}"
        INTERFACE_INCLUDE_DIRECTORIES "${OpenCVModules_INCLUDE_DIR}")
    endif()
  endforeach()
endif()
