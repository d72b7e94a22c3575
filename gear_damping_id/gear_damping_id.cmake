# gear_damping_id: identification + wavelet core (no ROS), the `analyze` tool and the nodes.
gear_check_core_purity(gear_damping_id/include gear_damping_id/src)

file(GLOB GEAR_ID_CORE_SOURCES CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/gear_damping_id/src/core/*.cpp)
add_library(gear_damping_id_core ${GEAR_ID_CORE_SOURCES})
target_include_directories(gear_damping_id_core PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/gear_damping_id/include)
target_link_libraries(gear_damping_id_core PUBLIC gear_sim_core Eigen3::Eigen PkgConfig::FFTW3
                      PkgConfig::FFTW3F)
target_compile_options(gear_damping_id_core PRIVATE ${GEAR_WARNINGS})
# glibc's vector math library (libmvec: the wavelet fits' log and atan2 four at a time on AVX2
# processors, src/core/vector_math.cpp); without it the fits take libm's scalar functions.
find_library(GEAR_LIBMVEC NAMES mvec libmvec.so.1)
if(GEAR_LIBMVEC AND CMAKE_SYSTEM_PROCESSOR MATCHES "x86_64|AMD64")
  target_link_libraries(gear_damping_id_core PRIVATE ${GEAR_LIBMVEC})
  target_compile_definitions(gear_damping_id_core PRIVATE GEAR_HAVE_LIBMVEC)
endif()

# Analysis outputs (JSON, tables, CSV): no ROS either, shared by the tools and the tests.
file(GLOB GEAR_ID_IO_SOURCES CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/gear_damping_id/src/io/*.cpp)
add_library(gear_damping_id_io ${GEAR_ID_IO_SOURCES})
target_link_libraries(gear_damping_id_io PUBLIC gear_damping_id_core nlohmann_json::nlohmann_json)
target_compile_options(gear_damping_id_io PRIVATE ${GEAR_WARNINGS})

# ROS side: identification results <-> messages, shared by the tools and the nodes.
add_library(gear_id_ros_conversions gear_damping_id/ros/id_conversions.cpp)
target_include_directories(gear_id_ros_conversions PUBLIC
                           ${CMAKE_CURRENT_SOURCE_DIR}/gear_damping_id/ros/include)
target_link_libraries(gear_id_ros_conversions PUBLIC gear_damping_id_core gear_ros_conversions)
target_compile_options(gear_id_ros_conversions PRIVATE ${GEAR_WARNINGS})
add_dependencies(gear_id_ros_conversions ${PROJECT_NAME}_generate_messages_cpp)

# `rosrun gear_damping analyze`: identification (and wavelet validation) of a recorded signal.
add_executable(analyze gear_damping_id/tools/analyze.cpp)
target_link_libraries(analyze gear_damping_id_io gear_id_ros_conversions gear_sim_io CLI11::CLI11
                      ${catkin_LIBRARIES})
target_compile_options(analyze PRIVATE ${GEAR_WARNINGS})
target_compile_definitions(analyze PRIVATE GEAR_DAMPING_VERSION="${gear_damping_VERSION}")

install(TARGETS gear_damping_id_core gear_damping_id_io gear_id_ros_conversions analyze
        ARCHIVE DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
        LIBRARY DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
        RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
install(DIRECTORY gear_damping_id/include/ DESTINATION ${CATKIN_GLOBAL_INCLUDE_DESTINATION})

# `rosrun gear_damping report RESULT_DIR`: figures and index.html (Python 3 + matplotlib).
catkin_install_python(PROGRAMS gear_damping_id/scripts/report
                      DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
install(FILES gear_damping_id/scripts/gear_report.py DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})

# ---------------------------------------------------------------------------------------------
# Live nodes (issue 6): damping_id_node, wavelet_node, and the conversion only they need
# (chunk -> StreamAssembler input). The sequencing and
# segment-by-segment identification they share (StreamAssembler, LiveIdentification) are in the
# core library above.
add_library(gear_live_ros_conversions gear_damping_id/ros/live_conversions.cpp)
target_include_directories(gear_live_ros_conversions PUBLIC
  ${CMAKE_CURRENT_SOURCE_DIR}/gear_damping_id/ros/include
  ${CATKIN_DEVEL_PREFIX}/${CATKIN_GLOBAL_INCLUDE_DESTINATION})
target_link_libraries(gear_live_ros_conversions PUBLIC gear_id_ros_conversions gear_damping_id_core
                      ${catkin_LIBRARIES})
target_compile_options(gear_live_ros_conversions PRIVATE ${GEAR_WARNINGS})
add_dependencies(gear_live_ros_conversions ${PROJECT_NAME}_generate_messages_cpp)
foreach(node damping_id_node wavelet_node)
  add_executable(${node} gear_damping_id/nodes/${node}.cpp)
  target_link_libraries(${node} gear_live_ros_conversions gear_id_ros_conversions
                        gear_damping_id_io gear_ros_conversions gear_sim_io ${catkin_LIBRARIES})
  target_compile_options(${node} PRIVATE ${GEAR_WARNINGS})
  add_dependencies(${node} ${PROJECT_NAME}_generate_messages_cpp ${PROJECT_NAME}_gencfg)
endforeach()
install(TARGETS gear_live_ros_conversions damping_id_node wavelet_node
        ARCHIVE DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
        LIBRARY DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
        RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})

# rig_frontend_node: shaft encoders (JointState) + torque -> SignalChunk (docs/rig.md).
add_executable(rig_frontend_node gear_damping_id/nodes/rig_frontend_node.cpp)
target_link_libraries(rig_frontend_node gear_damping_id_core gear_ros_conversions gear_sim_io
                      ${catkin_LIBRARIES})
target_compile_options(rig_frontend_node PRIVATE ${GEAR_WARNINGS})
add_dependencies(rig_frontend_node ${PROJECT_NAME}_generate_messages_cpp)
install(TARGETS rig_frontend_node RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
