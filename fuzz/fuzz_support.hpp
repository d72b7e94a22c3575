// Shared helpers of the libFuzzer targets: a per-process temporary file and the check every
// message passes (printable ASCII of bounded length: user data quoted escaped and truncated).
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace gear_fuzz {

namespace detail {
inline std::vector<std::string>& tempFiles() {
  static std::vector<std::string> files;
  return files;
}
inline void removeTempFiles() {
  for (const std::string& f : tempFiles()) std::remove(f.c_str());
}
}  // namespace detail

/// A file name in $TMPDIR (or /tmp) unique to this process; the file is removed when the
/// process exits normally (libFuzzer's end of a campaign or of -runs; a crash leaves it).
inline std::string tempPath(const std::string& extension) {
  const char* dir = std::getenv("TMPDIR");
  std::string path = std::string(dir && *dir ? dir : "/tmp") + "/gear_fuzz_" +
                     std::to_string(::getpid()) + "." + extension;
  // The list exists before the handler is registered, so it outlives the handler's call.
  if (detail::tempFiles().empty()) std::atexit(detail::removeTempFiles);
  detail::tempFiles().push_back(path);
  return path;
}

inline bool writeFile(const std::string& path, const std::uint8_t* data, size_t size) {
  FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return false;
  const bool ok = std::fwrite(data, 1, size, f) == size;
  return std::fclose(f) == 0 && ok;
}

/// Longest message a hostile input may produce (quoted user data is cut at 80 characters).
constexpr size_t kMaxMessage = 2000;

/// Aborts (a libFuzzer finding) when a message echoes raw bytes or grows without bound.
inline void checkMessage(const std::string& message) {
  if (message.size() > kMaxMessage) std::abort();
  for (unsigned char c : message)
    if (c != '\n' && (c < 0x20 || c >= 0x7F)) std::abort();
}

}  // namespace gear_fuzz
