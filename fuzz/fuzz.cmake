# libFuzzer targets (GEAR_DAMPING_FUZZ=ON, clang; built by scripts/sanitize.sh in its own
# workspace, never in the normal build). Each fuzz/fuzz_<name>.cpp defines
# LLVMFuzzerTestOneInput; fuzz/corpus/<name>/ is its seed corpus.
foreach(name csv yaml bag stream rig)
  add_executable(fuzz_${name} ${CMAKE_CURRENT_SOURCE_DIR}/fuzz/fuzz_${name}.cpp)
  target_compile_options(fuzz_${name} PRIVATE -fsanitize=fuzzer ${GEAR_WARNINGS})
  target_link_options(fuzz_${name} PRIVATE -fsanitize=fuzzer)
  target_link_libraries(fuzz_${name} gear_damping_id_core gear_sim_io gear_ros_conversions)
endforeach()
add_custom_target(fuzz_targets DEPENDS fuzz_csv fuzz_yaml fuzz_bag fuzz_stream fuzz_rig)
