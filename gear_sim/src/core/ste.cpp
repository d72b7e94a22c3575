#include "gear_sim/ste.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include "gear_sim/message_text.hpp"

namespace gear_sim {

const char* steDampingName(SteDamping d) { return d == SteDamping::Dte ? "dte" : "relative"; }

Result<SteDamping> parseSteDamping(const std::string& name) {
  for (SteDamping d : {SteDamping::Relative, SteDamping::Dte})
    if (name == steDampingName(d)) return d;
  return Status::invalidArgument("unknown name " + quoteForMessage(name) +
                                 " (one of: relative, dte)");
}

bool SteOptions::active() const {
  return offset != 0.0 || !mesh_cos.empty() || !mesh_sin.empty() || !pinion_cos.empty() ||
         !pinion_sin.empty() || !gear_cos.empty() || !gear_sin.empty();
}

OptionStatus SteOptions::check() const {
  if (!std::isfinite(offset))
    return violated("SimConfig", "ste.offset", offset, "must be finite [m]");
  const std::pair<const char*, const std::vector<double>*> lists[] = {
      {"ste.mesh_cos", &mesh_cos},     {"ste.mesh_sin", &mesh_sin}, {"ste.pinion_cos", &pinion_cos},
      {"ste.pinion_sin", &pinion_sin}, {"ste.gear_cos", &gear_cos}, {"ste.gear_sin", &gear_sin}};
  for (const auto& [name, v] : lists) {
    if (v->size() > 64)
      return violated("SimConfig", std::string(name) + ".size()", v->size(), "at most 64 orders");
    for (size_t i = 0; i < v->size(); ++i) {
      const double x = (*v)[i];
      if (!std::isfinite(x) || std::abs(x) > 1e-3)
        return violated(
            "SimConfig", std::string(name) + "[" + std::to_string(i) + "]", x,
            "must be a finite amplitude within 1 mm (STE amplitudes are micrometres) [m]");
    }
  }
  return {};
}

void SteBasis::eval(double u, double* out, double* du) const {
  int j = 0;
  if (with_offset) {
    out[j] = 1.0;
    if (du) du[j] = 0.0;
    ++j;
  }
  auto block = [&](int orders, double scale) {  // angle = 2 pi scale u
    const double w = 2.0 * M_PI * scale;
    for (int h = 1; h <= orders; ++h) {
      // Reduce the phase before the trig call: u grows to 1e5 cycles on long records.
      const double frac = std::remainder(u * scale * h, 1.0);
      const double c = std::cos(2.0 * M_PI * frac), s = std::sin(2.0 * M_PI * frac);
      out[j] = c;
      out[j + 1] = s;
      if (du) {
        du[j] = -w * h * s;
        du[j + 1] = w * h * c;
      }
      j += 2;
    }
  };
  block(mesh_orders, 1.0);
  block(pinion_orders, 1.0 / z1);
  block(gear_orders, 1.0 / z2);
}

void SteBasis::describe(int j, std::string* kind, int* order, bool* sine) const {
  if (with_offset) {
    if (j == 0) {
      *kind = "offset", *order = 0, *sine = false;
      return;
    }
    --j;
  }
  *sine = j % 2 == 1;
  int h = j / 2;
  if (h < mesh_orders) {
    *kind = "mesh", *order = h + 1;
    return;
  }
  h -= mesh_orders;
  if (h < pinion_orders) {
    *kind = "pinion", *order = h + 1;
    return;
  }
  h -= pinion_orders;
  *kind = "gear", *order = h + 1;
}

StaticTransmissionError::StaticTransmissionError(const SteOptions& o, int z1, int z2)
    : active_(o.active()) {
  auto orders = [](const std::vector<double>& a, const std::vector<double>& b) {
    return static_cast<int>(std::max(a.size(), b.size()));
  };
  basis_.mesh_orders = orders(o.mesh_cos, o.mesh_sin);
  basis_.pinion_orders = orders(o.pinion_cos, o.pinion_sin);
  basis_.gear_orders = orders(o.gear_cos, o.gear_sin);
  basis_.z1 = z1;
  basis_.z2 = z2;
  coef_.assign(static_cast<size_t>(basis_.size()), 0.0);
  coef_[0] = o.offset;
  size_t j = 1;
  auto put = [&](const std::vector<double>& a, const std::vector<double>& b, int n) {
    for (int h = 0; h < n; ++h, j += 2) {
      coef_[j] = h < static_cast<int>(a.size()) ? a[h] : 0.0;
      coef_[j + 1] = h < static_cast<int>(b.size()) ? b[h] : 0.0;
    }
  };
  put(o.mesh_cos, o.mesh_sin, basis_.mesh_orders);
  put(o.pinion_cos, o.pinion_sin, basis_.pinion_orders);
  put(o.gear_cos, o.gear_sin, basis_.gear_orders);
  scratch_.resize(coef_.size());
  dscratch_.resize(coef_.size());
}

double StaticTransmissionError::value(double u) const {
  if (!active_) return 0.0;
  basis_.eval(u, scratch_.data());
  double e = 0.0;
  for (size_t j = 0; j < coef_.size(); ++j) e += coef_[j] * scratch_[j];
  return e;
}

double StaticTransmissionError::derivative(double u) const {
  if (!active_) return 0.0;
  basis_.eval(u, scratch_.data(), dscratch_.data());
  double d = 0.0;
  for (size_t j = 0; j < coef_.size(); ++j) d += coef_[j] * dscratch_[j];
  return d;
}

}  // namespace gear_sim
