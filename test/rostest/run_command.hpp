// Shared by the rostest testers: runs a shell command (e.g. `rosrun` of a node with invalid
// parameters) and returns its exit status and combined stdout + stderr.
#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
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

}  // namespace gear_test
