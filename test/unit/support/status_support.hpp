// Tests keep a std::string of the last message beside a Status-returning call, so their
// assertions (and the text they match) read as before: ok(f(...), &e) is f's ok(), with its
// message (empty when ok) in e. Production code uses the Status itself (gear_sim/status.hpp).
#pragma once

#include <string>

#include "gear_sim/status.hpp"

namespace gear_test {

inline bool ok(const gear_sim::Status& s, std::string* message) {
  *message = s.message();
  return s.ok();
}

template <class T>
bool ok(const gear_sim::Result<T>& r, std::string* message) {
  return ok(r.status(), message);
}

}  // namespace gear_test
