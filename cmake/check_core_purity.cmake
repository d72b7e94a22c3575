# The numerical cores must stay free of ROS: this fails the configure step if any file of a
# core library includes a ROS header. (Link purity is enforced by the core targets linking
# only Eigen / FFTW / yaml-cpp, never ${catkin_LIBRARIES}.)
function(gear_check_core_purity)
  foreach(dir IN LISTS ARGN)
    file(GLOB_RECURSE _files CONFIGURE_DEPENDS
      ${CMAKE_CURRENT_SOURCE_DIR}/${dir}/*.hpp ${CMAKE_CURRENT_SOURCE_DIR}/${dir}/*.cpp)
    foreach(f IN LISTS _files)
      file(STRINGS "${f}" _hits REGEX "^[ \t]*#[ \t]*include[ \t]*[<\"](ros|rosbag|std_msgs|diagnostic_updater|gear_damping)/")
      if(_hits)
        message(FATAL_ERROR "ROS include in a core file ${f}: ${_hits}. Cores must not include ROS headers.")
      endif()
    endforeach()
  endforeach()
endfunction()
