// Quality warnings: the one shape in which every estimate (segment, run, wavelet mode) says why
// it should not be trusted as is. No ROS.
#pragma once

#include <string>
#include <vector>

namespace gear_damping_id {

/// One warning attached to an estimate: a short stable machine-readable `code` (lower snake
/// case, e.g. "refine_disagrees", "not_free_decay") and a human-readable `text` with the numbers
/// behind it. Codes never change meaning once released; the texts may be reworded.
struct QualityWarning {
  std::string code;
  std::string text;
};

/// Empty when the estimate is clean.
using QualityWarnings = std::vector<QualityWarning>;

}  // namespace gear_damping_id
