# gear_sim: simulator core (no ROS), its file I/O, the `simulate` tool and gear_sim_node.
gear_check_core_purity(gear_sim/include gear_sim/src)

file(GLOB GEAR_SIM_CORE_SOURCES CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/gear_sim/src/core/*.cpp)
add_library(gear_sim_core ${GEAR_SIM_CORE_SOURCES})
target_include_directories(gear_sim_core PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/gear_sim/include)
target_link_libraries(gear_sim_core PUBLIC Eigen3::Eigen)
target_compile_options(gear_sim_core PRIVATE ${GEAR_WARNINGS})

# File I/O (YAML configuration, CSV signal tables): no ROS either.
file(GLOB GEAR_SIM_IO_SOURCES CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/gear_sim/src/io/*.cpp)
if(GEAR_SIM_IO_SOURCES)
  add_library(gear_sim_io ${GEAR_SIM_IO_SOURCES})
else()
  add_library(gear_sim_io INTERFACE)
endif()
if(GEAR_SIM_IO_SOURCES)
  target_link_libraries(gear_sim_io PUBLIC gear_sim_core yaml-cpp)
  target_compile_options(gear_sim_io PRIVATE ${GEAR_WARNINGS})
else()
  target_link_libraries(gear_sim_io INTERFACE gear_sim_core yaml-cpp)
endif()
