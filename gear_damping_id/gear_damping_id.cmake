# gear_damping_id: identification + wavelet core (no ROS), the `analyze` tool and the nodes.
gear_check_core_purity(gear_damping_id/include gear_damping_id/src)

file(GLOB GEAR_ID_CORE_SOURCES CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/gear_damping_id/src/core/*.cpp)
add_library(gear_damping_id_core ${GEAR_ID_CORE_SOURCES})
target_include_directories(gear_damping_id_core PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/gear_damping_id/include)
target_link_libraries(gear_damping_id_core PUBLIC gear_sim_core Eigen3::Eigen PkgConfig::FFTW3)
target_compile_options(gear_damping_id_core PRIVATE ${GEAR_WARNINGS})
