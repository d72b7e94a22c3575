// The outermost frame of every command-line tool's main: nothing escapes as an abort. No ROS.
#pragma once

#include <exception>
#include <iostream>
#include <new>

#include "gear_sim/message_text.hpp"

namespace gear_sim {

/// Returns run(); an exception escaping it (std::bad_alloc included) is reported on stderr as
/// "<tool>: out of memory ..." or "<tool>: internal error: '<what>'" and becomes the tool's
/// documented `internal_error_code`.
template <class Run>
int runToolMain(const char* tool, int internal_error_code, Run&& run) {
  try {
    return run();
  } catch (const std::bad_alloc&) {
    std::cerr << tool << ": out of memory (docs/limits.md gives the sizes accepted)\n";
  } catch (const std::exception& e) {
    std::cerr << tool << ": internal error: " << quoteForMessage(e.what()) << "\n";
  }
  return internal_error_code;
}

}  // namespace gear_sim
