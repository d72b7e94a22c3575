// Shared by the rostest testers: runs a shell command (e.g. `rosrun` of a node with invalid
// parameters) and returns its exit status and combined stdout + stderr; waits (spinning) for a
// condition with a wall-clock deadline.
#pragma once

#include <ros/ros.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <utility>

namespace gear_test {

/// (exit status, output); status -1 if the command could not run or did not exit normally.
inline std::pair<int, std::string> runCommand(const std::string& cmd) {
  std::array<char, 512> buf;
  std::string out;
  std::unique_ptr<FILE, int (*)(FILE*)> p(popen((cmd + " 2>&1").c_str(), "r"), &pclose);
  if (!p) return {-1, ""};
  while (fgets(buf.data(), buf.size(), p.get())) out += buf.data();
  const int status = pclose(p.release());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

/// Waits (spinning) until pred() or the wall-clock timeout [s]; returns pred().
inline bool waitFor(const std::function<bool()>& pred, double timeout) {
  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(timeout);
  while (ros::ok() && !pred() && ros::WallTime::now() < deadline) {
    ros::spinOnce();
    ros::WallDuration(0.01).sleep();
  }
  ros::spinOnce();
  return pred();
}

}  // namespace gear_test
