# All third-party dependencies come from Debian packages (installed by `tools/m2s setup`).
find_package(Threads REQUIRED)
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(Ceres 2.0 REQUIRED)
find_package(assimp REQUIRED)
# OpenCV: only the modules used are installed (Debian's CMake config comes with the full
# libopencv-dev, which pulls in contrib, dnn and Qt), so find them directly.
find_path(OpenCV_INCLUDE_DIR opencv2/core.hpp PATH_SUFFIXES opencv4 REQUIRED)
set(OpenCV_LIBS)
foreach(_m core imgproc calib3d imgcodecs features2d)
  find_library(OpenCV_${_m}_LIBRARY opencv_${_m} REQUIRED)
  if(NOT TARGET opencv::${_m})
    add_library(opencv::${_m} UNKNOWN IMPORTED)
    set_target_properties(opencv::${_m} PROPERTIES IMPORTED_LOCATION ${OpenCV_${_m}_LIBRARY}
                                                   INTERFACE_INCLUDE_DIRECTORIES ${OpenCV_INCLUDE_DIR})
  endif()
  list(APPEND OpenCV_LIBS opencv::${_m})
endforeach()
find_package(nlohmann_json 3 REQUIRED)
find_package(CLI11 REQUIRED)

# LCM: Debian ships no CMake config; find the library, headers and lcm-gen directly.
find_path(LCM_INCLUDE_DIR lcm/lcm-cpp.hpp REQUIRED)
find_library(LCM_LIBRARY lcm REQUIRED)
find_program(LCM_GEN_EXECUTABLE lcm-gen REQUIRED)
if(NOT TARGET lcm::lcm)
  add_library(lcm::lcm UNKNOWN IMPORTED)
  set_target_properties(lcm::lcm PROPERTIES IMPORTED_LOCATION ${LCM_LIBRARY}
                                            INTERFACE_INCLUDE_DIRECTORIES ${LCM_INCLUDE_DIR})
endif()

# libsodium (bus authentication): Debian ships a pkg-config file, no CMake config.
find_path(SODIUM_INCLUDE_DIR sodium.h REQUIRED)
find_library(SODIUM_LIBRARY sodium REQUIRED)
if(NOT TARGET sodium::sodium)
  add_library(sodium::sodium UNKNOWN IMPORTED)
  set_target_properties(sodium::sodium PROPERTIES IMPORTED_LOCATION ${SODIUM_LIBRARY}
                                                  INTERFACE_INCLUDE_DIRECTORIES ${SODIUM_INCLUDE_DIR})
endif()

# EGL + OpenGL ES 3.x (Mesa llvmpipe headless, or the vendor driver).
find_path(EGL_INCLUDE_DIR EGL/egl.h REQUIRED)
find_library(EGL_LIBRARY EGL REQUIRED)
find_path(GLES3_INCLUDE_DIR GLES3/gl31.h REQUIRED)
find_library(GLES_LIBRARY GLESv2 REQUIRED)
if(NOT TARGET m2s_egl)
  add_library(m2s_egl INTERFACE)
  target_include_directories(m2s_egl INTERFACE ${EGL_INCLUDE_DIR} ${GLES3_INCLUDE_DIR})
  target_link_libraries(m2s_egl INTERFACE ${EGL_LIBRARY} ${GLES_LIBRARY})
  add_library(m2s::egl ALIAS m2s_egl)
endif()

if(M2S_BUILD_XR)
  find_package(OpenXR CONFIG)
  if(NOT OpenXR_FOUND)
    message(WARNING "OpenXR loader not found: the XR client and simulated runtime are not built")
    set(M2S_BUILD_XR OFF)
  endif()
endif()

if(M2S_BUILD_TESTS)
  find_package(GTest REQUIRED)
  include(GoogleTest)
endif()
if(M2S_BUILD_BENCHMARKS)
  find_package(benchmark REQUIRED)
endif()
