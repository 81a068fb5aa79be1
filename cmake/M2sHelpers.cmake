# Compile options shared by every first-party target (linked PRIVATE, never global flags).
add_library(m2s_options INTERFACE)
add_library(m2s::options ALIAS m2s_options)
target_compile_features(m2s_options INTERFACE cxx_std_20)
target_compile_options(m2s_options INTERFACE
  $<$<CXX_COMPILER_ID:GNU,Clang>:-Wall -Wextra -Wpedantic -Wno-unused-parameter>
  $<$<BOOL:${M2S_WERROR}>:-Werror>)
if(M2S_SANITIZE)
  string(REPLACE ";" "," _m2s_san "${M2S_SANITIZE}")
  # -O1 (after the build type's -O3, so it wins): the sanitizers' usual level; it compiles
  # 2.5x faster than -O3 here, and the suite runs at a speed its bounds allow. Tests (targets
  # with the property M2S_FAST_COMPILE) and executables' mains (thin: the work is in the
  # libraries) get -O0, half the compile time again (m2s_fast_compile below).
  target_compile_options(m2s_options INTERFACE -fsanitize=${_m2s_san} -fno-omit-frame-pointer
    $<IF:$<BOOL:$<TARGET_PROPERTY:M2S_FAST_COMPILE>>,-O0,-O1>)
  # GCC 12's vptr check breaks LCM's callback dispatch (lcm-cpp-impl.hpp's static cb_func then
  # receives a bad user pointer; reproduced with a 20-line program on liblcm 1.3.1): off.
  # UBSan's null, alignment and object-size checks instrument every access through a pointer
  # or reference, which in Eigen's expression templates is most of the code: with ASan, they
  # make a source compile 1.5x as long (server/tracking/motion_uncertainty.cc: 78 s against
  # 51 s) for findings ASan reports anyway (a null dereference is a SEGV ASan reports with its
  # stack; object-size is a weaker bounds check than ASan's; x86-64 loads need no alignment).
  if("undefined" IN_LIST M2S_SANITIZE)
    target_compile_options(m2s_options INTERFACE -fno-sanitize=vptr,null,alignment,object-size)
  endif()
  target_link_options(m2s_options INTERFACE -fsanitize=${_m2s_san})
  # Under ASan, Eigen stops trusting glibc's malloc alignment and frees through its own
  # aligned allocator; objects shared with the (unsanitized) Ceres library would then be freed
  # by the wrong allocator. Keep Eigen's normal x86-64 behaviour.
  if("address" IN_LIST M2S_SANITIZE)
    target_compile_definitions(m2s_options INTERFACE EIGEN_MALLOC_ALREADY_ALIGNED=1)
  endif()
endif()

# In sanitized builds, compiles SOURCES at -O0 (a source's options come after its target's).
function(m2s_fast_compile)
  if(M2S_SANITIZE)
    set_source_files_properties(${ARGN} PROPERTIES COMPILE_OPTIONS -O0)
  endif()
endfunction()

# m2s_add_library(NAME ALIAS DIR [DEPS ...] [PRIVATE_DEPS ...])
# One library per folder: sources are DIR/src/**/*.cc, public headers DIR/include.
function(m2s_add_library name)
  cmake_parse_arguments(ARG "" "ALIAS;DIR" "DEPS;PRIVATE_DEPS" ${ARGN})
  file(GLOB_RECURSE _srcs CONFIGURE_DEPENDS ${ARG_DIR}/src/*.cc)
  add_library(${name} STATIC ${_srcs})
  add_library(${ARG_ALIAS} ALIAS ${name})
  target_include_directories(${name} PUBLIC ${ARG_DIR}/include PRIVATE ${ARG_DIR}/src)
  target_link_libraries(${name} PUBLIC ${ARG_DEPS} PRIVATE m2s::options ${ARG_PRIVATE_DEPS})
  target_compile_features(${name} PUBLIC cxx_std_20)
endfunction()

# m2s_add_executable(NAME SOURCES ... [DEPS ...]): lands in build/bin.
function(m2s_add_executable name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE m2s::options ${ARG_DEPS})
  m2s_fast_compile(${ARG_SOURCES})
endfunction()

# What every test target and the tests' precompiled header share: their flags must match for
# the header to be used (GCC ignores a precompiled header built with other flags).
function(m2s_test_compile_settings target)
  set_target_properties(${target} PROPERTIES M2S_FAST_COMPILE ON)
  target_link_libraries(${target} PRIVATE m2s::options GTest::gtest Eigen3::Eigen)
  target_compile_definitions(${target} PRIVATE
    M2S_SOURCE_DIR="${PROJECT_SOURCE_DIR}" M2S_BINARY_DIR="${CMAKE_BINARY_DIR}")
endfunction()

# m2s_add_test_pch(): one precompiled header of the third-party headers most tests include
# (GoogleTest, Eigen, the standard library), built once and reused by every m2s_add_test
# target: their parsing is most of a test source's compile time at -O0.
function(m2s_add_test_pch)
  file(CONFIGURE OUTPUT ${CMAKE_BINARY_DIR}/m2s_test_pch.cc
       CONTENT "// The owner of the tests' precompiled header.\n")
  add_library(m2s_test_pch OBJECT ${CMAKE_BINARY_DIR}/m2s_test_pch.cc)
  m2s_test_compile_settings(m2s_test_pch)
  target_precompile_headers(m2s_test_pch PRIVATE
    <algorithm> <cmath> <cstdint> <functional> <map> <memory> <optional> <string>
    <unordered_map> <vector> <Eigen/Dense> <gtest/gtest.h>)
endfunction()

# m2s_add_test(NAME [NO_LEAK_CHECK] SOURCES ... [DEPS ...] [LABELS ...]): one gtest executable
# (NO_LEAK_CHECK: ASan without LeakSanitizer, for tests whose leaks are in unloaded third-party
# modules), discovered by
# ctest. Labels: `threads` (runs threads: the ThreadSanitizer suite), `realtime` (asserts on
# wall-clock behaviour: left out of the sanitizer suites, whose slowdown it would measure).
# m2s_add_label_targets() then makes a target per label (m2s_tests_threads,
# m2s_tests_realtime) that builds only those tests.
function(m2s_add_test name)
  cmake_parse_arguments(ARG "NO_LEAK_CHECK" "" "SOURCES;DEPS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  m2s_test_compile_settings(${name})
  set_target_properties(${name} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/bin/tests)
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest_main)
  if(TARGET m2s_test_pch)
    target_precompile_headers(${name} REUSE_FROM m2s_test_pch)
  endif()
  set(_props TIMEOUT 600)
  if(ARG_NO_LEAK_CHECK AND "address" IN_LIST M2S_SANITIZE)
    list(APPEND _props ENVIRONMENT "ASAN_OPTIONS=detect_leaks=0:abort_on_error=1")
  endif()
  if(ARG_LABELS)
    list(APPEND _props LABELS "${ARG_LABELS}")
    foreach(_label ${ARG_LABELS})
      set_property(GLOBAL APPEND PROPERTY M2S_TESTS_LABELLED_${_label} ${name})
    endforeach()
  endif()
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES ${_props})
endfunction()

# m2s_add_benchmark(NAME SOURCES ... [DEPS ...]): built, never run by ctest.
function(m2s_add_benchmark name)
  if(NOT M2S_BUILD_BENCHMARKS)
    return()
  endif()
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE m2s::options ${ARG_DEPS} benchmark::benchmark)
endfunction()

# Adds every immediate sub-folder of the current source dir that has a CMakeLists.txt.
function(m2s_add_subdirectories)
  file(GLOB _children RELATIVE ${CMAKE_CURRENT_SOURCE_DIR} CONFIGURE_DEPENDS
       ${CMAKE_CURRENT_SOURCE_DIR}/*/CMakeLists.txt)
  list(SORT _children)
  foreach(_child ${_children})
    get_filename_component(_dir ${_child} DIRECTORY)
    add_subdirectory(${_dir})
  endforeach()
endfunction()

# m2s_check_layering(TARGET FORBIDDEN...): fails the configuration when TARGET links any of
# FORBIDDEN, directly or through the libraries it links (the layering of docs/ARCHITECTURE.md,
# checked on every configure). Call it after every target is defined.
function(m2s_check_layering target)
  set(_seen)
  set(_todo ${target})
  while(_todo)
    list(POP_FRONT _todo _t)
    if(NOT TARGET ${_t} OR _t IN_LIST _seen)
      continue()
    endif()
    list(APPEND _seen ${_t})
    get_target_property(_aliased ${_t} ALIASED_TARGET)
    if(_aliased)
      list(APPEND _todo ${_aliased})
    endif()
    foreach(_prop LINK_LIBRARIES INTERFACE_LINK_LIBRARIES)
      get_target_property(_deps ${_t} ${_prop})
      if(_deps)
        foreach(_d ${_deps})
          string(REGEX REPLACE "^\\$<LINK_ONLY:(.*)>$" "\\1" _d "${_d}")
          if(_d IN_LIST ARGN)
            message(FATAL_ERROR "layering: ${target} links ${_d} (through ${_t})")
          endif()
          list(APPEND _todo ${_d})
        endforeach()
      endif()
    endforeach()
  endwhile()
endfunction()

# One target per test label, building just the tests that carry it (and what they run).
function(m2s_add_label_targets)
  foreach(_label threads realtime)
    get_property(_tests GLOBAL PROPERTY M2S_TESTS_LABELLED_${_label})
    add_custom_target(m2s_tests_${_label})
    if(_tests)
      add_dependencies(m2s_tests_${_label} ${_tests})
    endif()
  endforeach()
endfunction()
