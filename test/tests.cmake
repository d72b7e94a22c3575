# Unit tests: every test/unit/*_test.cpp is its own GoogleTest target linked against both
# cores and the shared main (Debian's catkin links catkin_add_gtest targets without gtest_main).
file(GLOB GEAR_UNIT_TESTS CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/test/unit/*_test.cpp)
add_library(gear_test_main STATIC ${CMAKE_CURRENT_SOURCE_DIR}/test/unit/support/gtest_main.cpp)
target_link_libraries(gear_test_main PUBLIC ${GTEST_LIBRARIES})
target_include_directories(gear_test_main PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/test/unit/support)
# GEAR_TEST_PCH: one precompiled header of what nearly every test includes (GoogleTest, Eigen,
# the simulator and the integral method's headers, nlohmann-json), built once and reused by every
# unit test. It roughly halves the test targets' compile time in scripts/sanitize.sh's ASan build
# (which turns it on) and in .ci/run's Release build (GEAR_TEST_PCH=ON in the environment of
# scripts/test.sh); off by default because ccache does not cache compiles that use a PCH.
option(GEAR_TEST_PCH "precompile the unit tests' common headers once" OFF)
# GEAR_UNIT_TEST_FLAGS: compile options for the unit test sources only (after the build type's
# flags, so they win). scripts/sanitize.sh passes -O0: the tests' own code (assertions, fixtures,
# drivers) then compiles in about half the time under ASan + UBSan, while the code they test (the
# libraries and tools) stays at the stage's -O1; the sanitizers check at least as much at -O0.
set(GEAR_UNIT_TEST_FLAGS "" CACHE STRING "extra compile options of the unit test sources")
separate_arguments(GEAR_UNIT_TEST_FLAG_LIST UNIX_COMMAND "${GEAR_UNIT_TEST_FLAGS}")
set(GEAR_TEST_PCH_FIRST "")
set(GEAR_UNIT_TEST_NAMES "")
foreach(src IN LISTS GEAR_UNIT_TESTS)
  get_filename_component(name ${src} NAME_WE)
  list(APPEND GEAR_UNIT_TEST_NAMES ${name})
  catkin_add_gtest(${name} ${src} WORKING_DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR})
  if(GEAR_TEST_PCH AND TARGET ${name})
    if(GEAR_TEST_PCH_FIRST STREQUAL "")
      set(GEAR_TEST_PCH_FIRST ${name})
      target_precompile_headers(${name} PRIVATE
        <gtest/gtest.h> <Eigen/Core> <Eigen/Dense> <nlohmann/json.hpp>
        <algorithm> <cmath> <cstdio> <filesystem> <fstream> <functional> <iostream> <limits>
        <map> <memory> <random> <sstream> <string> <vector>
        <gear_sim/simulator.hpp> <gear_sim/config_yaml.hpp> <gear_damping_id/integral_method.hpp>)
    else()
      target_precompile_headers(${name} REUSE_FROM ${GEAR_TEST_PCH_FIRST})
    endif()
  endif()
  target_link_libraries(${name} gear_test_main gear_damping_id_io gear_sim_io gear_ros_conversions
                        gear_id_ros_conversions gear_live_ros_conversions)
  target_compile_options(${name} PRIVATE ${GEAR_WARNINGS} ${GEAR_UNIT_TEST_FLAG_LIST})
  # The nodes' parameter readers (header-only) are tested on the shipped configuration files.
  target_include_directories(${name} PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/gear_damping_id/nodes)
  target_compile_definitions(${name} PRIVATE GEAR_SOURCE_DIR="${CMAKE_CURRENT_SOURCE_DIR}"
                             GEAR_TOOL_DIR="$<TARGET_FILE_DIR:analyze>")
  add_dependencies(${name} analyze convert simulate)  # tests of the tools run the executables
endforeach()
# Every unit test as one target: make's top-level Makefile builds the goals named on its command
# line one after the other (.NOTPARALLEL), each with -j, so naming the ~45 one-source test
# targets one by one (as scripts/sanitize.sh did) compiled them one at a time.
add_custom_target(gear_unit_tests)
add_dependencies(gear_unit_tests ${GEAR_UNIT_TEST_NAMES})

# Integration tests (rostest): tester executables in test/rostest/*_tester.cpp, reused by
# the .test files beside them. Each .test file is registered with add_rostest.
find_package(rostest REQUIRED)
file(GLOB GEAR_ROSTEST_TESTERS CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/test/rostest/*_tester.cpp)
foreach(src IN LISTS GEAR_ROSTEST_TESTERS)
  get_filename_component(name ${src} NAME_WE)
  add_executable(${name} EXCLUDE_FROM_ALL ${src})
  target_link_libraries(${name} gear_damping_id_core gear_sim_io gear_ros_conversions ${catkin_LIBRARIES} ${GTEST_LIBRARIES})
  target_compile_options(${name} PRIVATE ${GEAR_WARNINGS})
  add_dependencies(${name} ${PROJECT_NAME}_generate_messages_cpp)
  add_dependencies(tests ${name})
endforeach()
file(GLOB GEAR_ROSTESTS CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/test/rostest/*.test)
foreach(t IN LISTS GEAR_ROSTESTS)
  file(RELATIVE_PATH rel ${CMAKE_CURRENT_SOURCE_DIR} ${t})
  add_rostest(${rel})
endforeach()
