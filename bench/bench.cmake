# Google Benchmark suites (not tests: they report numbers and assert nothing about time).
# Every bench/*_bench.cpp becomes an executable bench_<name> in the package's lib dir, so
# `rosrun gear_damping bench_<name>` runs it.
find_package(benchmark QUIET)
if(benchmark_FOUND)
  file(GLOB GEAR_BENCH_SOURCES CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/bench/*_bench.cpp)
  foreach(src IN LISTS GEAR_BENCH_SOURCES)
    get_filename_component(name ${src} NAME_WE)
    string(REGEX REPLACE "_bench$" "" name ${name})
    add_executable(bench_${name} ${src})
    target_link_libraries(bench_${name} gear_damping_id_core gear_sim_io benchmark::benchmark)
    target_compile_options(bench_${name} PRIVATE ${GEAR_WARNINGS})
  endforeach()
else()
  message(STATUS "Google Benchmark not found: benchmarks are not built")
endif()

# The bag-read floor of bench/compare_peers (a plain executable, not a Google Benchmark suite).
add_executable(bag_read_floor bench/bag_read_floor.cpp)
target_link_libraries(bag_read_floor gear_sim_core ${catkin_LIBRARIES})
add_dependencies(bag_read_floor ${PROJECT_NAME}_generate_messages_cpp)
target_compile_options(bag_read_floor PRIVATE ${GEAR_WARNINGS})
