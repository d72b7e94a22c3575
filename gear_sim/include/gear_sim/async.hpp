#pragma once
// Work that overlaps the caller's: f() on a thread of its own (std::async), or, when no thread
// can be started, on the caller's thread when it asks for the result (std::launch::deferred), so
// that the work is never lost for want of a thread. The future's get() returns f's result or
// rethrows its exception; its destructor waits for a started thread.
#include <future>
#include <system_error>
#include <type_traits>

namespace gear_sim {

template <class F>
std::future<std::invoke_result_t<F&>> startAsync(F f) {
  try {
    return std::async(std::launch::async, f);
  } catch (const std::system_error&) {
    return std::async(std::launch::deferred, f);
  }
}

}  // namespace gear_sim
