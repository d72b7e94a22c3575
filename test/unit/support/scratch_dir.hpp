// A scratch directory for a test's files, removed with everything in it when the object is
// destroyed; processScratch() gives one per test binary, removed at the process's exit, for
// tests that write files from free functions.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>

namespace gear_test {

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

/// The test binary's scratch directory `<temp>/<name>_<pid>`, made on the first call and removed
/// (with its files) when the process exits normally. One name per binary.
inline const std::filesystem::path& processScratch(const std::string& name) {
  static const ScratchDir dir(name);
  return dir.path();
}

}  // namespace gear_test
