// Shared main for every GoogleTest target: Debian's catkin links catkin_add_gtest targets
// without gtest_main. rostest testers that need ros::init provide their own main.
#include <gtest/gtest.h>

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
