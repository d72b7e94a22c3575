# Install space: everything `roslaunch gear_damping pipeline.launch`, `rosrun gear_damping ...`,
# `rosmsg`/`rossrv show gear_damping/...` and the docs need, under share/gear_damping (the
# executables and libraries are installed next to their targets in gear_sim/ and
# gear_damping_id/). test/rostest/install_space.test builds and launches it.
file(GLOB GEAR_MSG_FILES CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/gear_msgs/msg/*.msg)
file(GLOB GEAR_SRV_FILES CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/gear_msgs/srv/*.srv)
install(FILES ${GEAR_MSG_FILES} DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION}/msg)
install(FILES ${GEAR_SRV_FILES} DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION}/srv)
install(DIRECTORY launch config cfg docs DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION}
        USE_SOURCE_PERMISSIONS)
install(FILES README.md CONTRIBUTING.md DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})
install(DIRECTORY gear_sim/ros/include/ gear_damping_id/ros/include/
        DESTINATION ${CATKIN_GLOBAL_INCLUDE_DESTINATION})
# Scripts (set-up, storyline, result counting, key check) and the report's assets, if any.
install(PROGRAMS scripts/common.sh scripts/demo.sh scripts/test.sh scripts/storyline.py
                 scripts/count_test_results.py scripts/check_rosdep_keys.py
        DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION}/scripts)
foreach(assets gear_damping_id/scripts/assets gear_damping_id/scripts/report_assets)
  if(IS_DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/${assets})
    install(DIRECTORY ${assets}/ DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION}/report_assets)
  endif()
endforeach()
