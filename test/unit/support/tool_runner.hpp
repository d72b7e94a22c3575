// Runs the package's command-line tools from the tests (the real executables, built beside the
// tests: GEAR_TOOL_DIR) and reads/writes small text files.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "scratch_dir.hpp"

namespace gear_test {

struct ToolRun {
  int code = -1;  ///< exit code (-1: killed by a signal)
  std::string out, err;
};

inline std::string readText(const std::filesystem::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

inline void writeText(const std::filesystem::path& p, const std::string& text) {
  std::ofstream(p) << text;
}

/// Runs GEAR_TOOL_DIR/`tool` with `args` (shell syntax), stdout and stderr captured via files in
/// `dir`.
/// Runs the shell command `cmd`, stdout and stderr captured via files `stem`.stdout/.stderr in
/// `dir`.
inline ToolRun runShell(const std::string& cmd, const std::filesystem::path& dir,
                        const std::string& stem) {
  const auto out = dir / (stem + ".stdout"), err = dir / (stem + ".stderr");
  const int status =
      std::system((cmd + " >'" + out.string() + "' 2>'" + err.string() + "'").c_str());
  ToolRun r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = readText(out);
  r.err = readText(err);
  return r;
}

inline ToolRun runTool(const std::string& tool, const std::string& args,
                       const std::filesystem::path& dir) {
  return runShell(std::string(GEAR_TOOL_DIR) + "/" + tool + " " + args, dir, tool);
}

}  // namespace gear_test
