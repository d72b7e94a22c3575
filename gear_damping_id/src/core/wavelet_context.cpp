// The gear's context of a wavelet analysis (see wavelet_context.hpp).
#include "gear_damping_id/wavelet_context.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>
#include <vector>

#include "gear_sim/message_text.hpp"
#include "gear_sim/simulator.hpp"

namespace gear_damping_id {

std::string meshPhaseProblem(const double* phase, size_t n, double sample_rate) {
  if (n < 2) return "fewer than 2 samples";
  std::vector<double> moving;  // the steps where the phase advances
  for (size_t k = 0; k < n; ++k) {
    if (!std::isfinite(phase[k])) return "a value is not finite (sample " + std::to_string(k) + ")";
    if (k == 0) continue;
    const double step = phase[k] - phase[k - 1];
    if (step < 0.0) return "it decreases (sample " + std::to_string(k) + ")";
    if (step > 0.0) moving.push_back(step);
  }
  const double span = phase[n - 1] - phase[0];
  if (!(span > 0.0) || moving.empty()) return "it does not advance";
  if (!std::isfinite(span * sample_rate / static_cast<double>(n - 1)))
    return "its mesh frequency overflows (a span of " + gear_sim::formatNumber(span) +
           " cycles over " + std::to_string(n) + " samples)";
  // Against the typical step while the gear moves (the median of the advancing steps): a
  // start or stop inside the samples, or an encoder's staircase, keeps it; a corrupt value does
  // not (before: against the mean step, which a start late in a window makes small).
  const auto mid = moving.begin() + static_cast<std::ptrdiff_t>(moving.size() / 2);
  std::nth_element(moving.begin(), mid, moving.end());
  const double typical = *mid;
  const double largest = *std::max_element(moving.begin(), moving.end());
  if (largest > kMaxMeshPhaseStepRatio * typical)
    return "a step of " + gear_sim::formatNumber(largest) + " cycles against a typical step of " +
           gear_sim::formatNumber(typical) + " (a corrupt value)";
  return "";
}

double applyGearContext(const MeshPhaseAt& phase, size_t n, double sample_rate,
                        const gear_sim::GearModel* model, WaveletOptions* options) {
  if (n < 2 || !(sample_rate > 0.0)) return 0.0;
  const double f_mesh = (phase(n - 1) - phase(0)) * sample_rate / static_cast<double>(n - 1);
  if (!std::isfinite(f_mesh) || !(f_mesh > 0.0)) return 0.0;
  if (options->order_frequencies.empty()) {
    options->order_frequencies = gearOrderFrequencies(f_mesh, model ? model->gears.pinion.teeth : 0,
                                                      model ? model->gears.gear.teeth : 0);
  }
  if (model == nullptr) return f_mesh;
  auto growth = [&](double f) {
    const double lambda = gear_sim::parametricGrowthRate(model->gears, model->mesh, f);
    return std::isfinite(lambda) ? lambda : 0.0;
  };
  if (n < 4 * kGrowthBlocks) {
    options->parametric_growth_rate = {growth(f_mesh)};
    options->parametric_growth_block = 0.0;
    return f_mesh;
  }
  const size_t b = n / kGrowthBlocks;
  options->parametric_growth_rate.assign(kGrowthBlocks, 0.0);
  options->parametric_growth_block = static_cast<double>(b) / sample_rate;
  // Blocks at the same speed share one evaluation (a smooth stiffness at a low mesh frequency
  // costs up to ~20 ms each).
  std::vector<std::pair<double, double>> done;  // (mesh frequency, rate)
  for (size_t k = 0; k < kGrowthBlocks; ++k) {
    const size_t i0 = k * b, i1 = k + 1 == kGrowthBlocks ? n - 1 : (k + 1) * b;
    const double f = (phase(i1) - phase(i0)) * sample_rate / static_cast<double>(i1 - i0);
    auto same = std::find_if(done.begin(), done.end(), [f](const auto& d) {
      return std::abs(f - d.first) <= kSameMeshFrequency * std::abs(d.first);
    });
    if (same == done.end()) same = done.insert(done.end(), {f, growth(f)});
    options->parametric_growth_rate[k] = same->second;
  }
  return f_mesh;
}

std::string applyGearContext(const double* phase, size_t n, double sample_rate,
                             const gear_sim::GearModel* model, WaveletOptions* options,
                             double* f_mesh) {
  std::string problem = meshPhaseProblem(phase, n, sample_rate);
  *f_mesh = std::numeric_limits<double>::quiet_NaN();
  if (problem.empty())
    *f_mesh =
        applyGearContext([phase](size_t k) { return phase[k]; }, n, sample_rate, model, options);
  return problem;
}

}  // namespace gear_damping_id
