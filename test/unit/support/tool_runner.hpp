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
inline ToolRun runTool(const std::string& tool, const std::string& args,
                       const std::filesystem::path& dir) {
  const auto out = dir / (tool + ".stdout"), err = dir / (tool + ".stderr");
  const std::string cmd = std::string(GEAR_TOOL_DIR) + "/" + tool + " " + args + " >" +
                          out.string() + " 2>" + err.string();
  const int status = std::system(cmd.c_str());
  ToolRun r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = readText(out);
  r.err = readText(err);
  return r;
}

/// A fresh scratch directory under the system temp dir, removed by the destructor.
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& name)
      : path_(std::filesystem::temp_directory_path() / (name + "_" + std::to_string(::getpid()))) {
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace gear_test
