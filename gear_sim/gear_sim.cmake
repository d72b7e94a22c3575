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

# ROS side: message <-> core conversions shared by the tools and nodes.
add_library(gear_ros_conversions gear_sim/ros/conversions.cpp gear_sim/ros/bag_io.cpp
            gear_sim/ros/rig_bag_io.cpp gear_sim/ros/bag_format.cpp)
target_include_directories(gear_ros_conversions PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/gear_sim/ros/include
                           ${CATKIN_DEVEL_PREFIX}/${CATKIN_GLOBAL_INCLUDE_DESTINATION})
# bz2 and roslz4 (rosbag's own dependencies) decompress chunks for checkBagStructure.
target_link_libraries(gear_ros_conversions PUBLIC gear_sim_io ${catkin_LIBRARIES} PRIVATE bz2 roslz4)
target_compile_options(gear_ros_conversions PRIVATE ${GEAR_WARNINGS})
add_dependencies(gear_ros_conversions ${PROJECT_NAME}_generate_messages_cpp)

# `rosrun gear_damping simulate`: the simulator from the command line (CSV or bag output).
add_executable(simulate gear_sim/tools/simulate.cpp)
target_link_libraries(simulate gear_sim_io gear_ros_conversions CLI11::CLI11 ${catkin_LIBRARIES})
target_compile_options(simulate PRIVATE ${GEAR_WARNINGS})

# `rosrun gear_damping convert`: signal records CSV <-> bag.
add_executable(convert gear_sim/tools/convert.cpp)
target_link_libraries(convert gear_sim_io gear_ros_conversions CLI11::CLI11 ${catkin_LIBRARIES})
target_compile_options(convert PRIVATE ${GEAR_WARNINGS})

# gear_sim_node: publishes the simulated signal as chunks, the gear parameters latched.
add_executable(gear_sim_node gear_sim/nodes/gear_sim_node.cpp)
# The strict parameter reader (ParamReader) is shared with the identification nodes.
target_include_directories(gear_sim_node PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/gear_damping_id/nodes)
target_link_libraries(gear_sim_node gear_sim_io gear_ros_conversions gear_live_ros_conversions
                      ${catkin_LIBRARIES})
target_compile_options(gear_sim_node PRIVATE ${GEAR_WARNINGS})

install(TARGETS gear_sim_core gear_sim_io gear_ros_conversions simulate convert gear_sim_node
        ARCHIVE DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
        LIBRARY DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
        RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
install(DIRECTORY gear_sim/include/ DESTINATION ${CATKIN_GLOBAL_INCLUDE_DESTINATION})
