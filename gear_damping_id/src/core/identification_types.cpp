#include "gear_damping_id/identification_types.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace gear_damping_id {

std::string toString(Formulation f) {
  switch (f) {
    case Formulation::Known:
      return "known";
    case Formulation::Greybox:
      return "greybox";
    case Formulation::Paper:
      return "paper";
    case Formulation::Legacy:
      return "legacy";
  }
  return "?";
}

std::string toString(DampingModel m) {
  switch (m) {
    case DampingModel::Piecewise:
      return "piecewise";
    case DampingModel::Constant:
      return "constant";
    case DampingModel::LoadLaw:
      return "load_law";
  }
  return "?";
}

std::vector<std::string> formulationNames() {
  std::vector<std::string> out;
  for (Formulation f : kFormulations) out.push_back(toString(f));
  return out;
}

std::vector<std::string> dampingModelNames() {
  std::vector<std::string> out;
  for (DampingModel m : kDampingModels) out.push_back(toString(m));
  return out;
}

bool parseFormulation(const std::string& s, Formulation* out) {
  for (Formulation f : kFormulations) {
    if (s == toString(f)) {
      *out = f;
      return true;
    }
  }
  return false;
}

bool parseDampingModel(const std::string& s, DampingModel* out) {
  for (DampingModel m : kDampingModels) {
    if (s == toString(m)) {
      *out = m;
      return true;
    }
  }
  return false;
}

int StiffnessShape::unknowns() const {
  switch (kind) {
    case Kind::Square:
      return 2;
    case Kind::Fourier:
      return 2 * n + 1;
    case Kind::Table:
      return n;
  }
  return 0;
}

void StiffnessShape::basis(double u, double* out) const {
  if (!std::isfinite(u)) {  // (a NaN phase sample: an unknown stiffness, never a table index)
    if (kind != Kind::Square)
      std::fill(out, out + unknowns(), std::numeric_limits<double>::quiet_NaN());
    return;
  }
  const double frac = u - std::floor(u);  // phase within the mesh cycle, [0, 1)
  if (kind == Kind::Fourier) {
    out[0] = 1.0;
    for (int h = 1; h <= n; ++h) {
      const double a = 2.0 * M_PI * h * frac;
      out[2 * h - 1] = std::cos(a);
      out[2 * h] = std::sin(a);
    }
  } else if (kind == Kind::Table) {
    // Periodic hat functions on the nodes j/N.
    for (int j = 0; j < n; ++j) out[j] = 0.0;
    const double x = frac * n;
    const int j0 = std::min(static_cast<int>(std::floor(x)), n - 1);
    const double w = x - j0;
    out[j0] += 1.0 - w;
    out[(j0 + 1) % n] += w;
  }
}

std::string toString(const StiffnessShape& s) {
  switch (s.kind) {
    case StiffnessShape::Kind::Square:
      return "square";
    case StiffnessShape::Kind::Fourier:
      return "fourier:" + std::to_string(s.n);
    case StiffnessShape::Kind::Table:
      return "table:" + std::to_string(s.n);
  }
  return "?";
}

bool parseStiffnessShape(const std::string& s, StiffnessShape* out) {
  if (s == "square") {
    *out = StiffnessShape();
    return true;
  }
  const auto colon = s.find(':');
  if (colon == std::string::npos) return false;
  const std::string kind = s.substr(0, colon), num = s.substr(colon + 1);
  if (num.empty() || num.size() > 3 || num.find_first_not_of("0123456789") != std::string::npos) {
    return false;
  }
  const int n = std::stoi(num);
  StiffnessShape r;
  r.n = n;
  if (kind == "fourier" && n >= 1 && n <= StiffnessShape::kMaxHarmonics) {
    r.kind = StiffnessShape::Kind::Fourier;
  } else if (kind == "table" && n >= 3 && n <= StiffnessShape::kMaxNodes) {
    r.kind = StiffnessShape::Kind::Table;
  } else {
    return false;
  }
  *out = r;
  return true;
}

gear_sim::OptionStatus IdentificationOptions::check() const {
  auto bad = [](const std::string& field, const auto& value, const std::string& rule) {
    return gear_sim::violated("IdentificationOptions", field, value, rule);
  };
  if (!(segment_length >= 0.0))
    return bad("segment_length", segment_length,
               "must be >= 0 [s] (0 or .inf = the whole analysed record)");
  if (!(window_length >= 0.0) || !std::isfinite(window_length))
    return bad("window_length", window_length, "must be finite and >= 0 [s] (0 = automatic)");
  if (std::isnan(t_start)) return bad("t_start", t_start, "must be a number [s]");
  if (!(t_end > t_start))
    return bad("t_start", t_start, "must be < t_end = " + gear_sim::formatNumber(t_end) + " [s]");
  if (!(max_condition > 1.0) || max_condition > 1e7)
    return bad("max_condition", max_condition, "must be in (1, 1e7]");
  if (!(time_tolerance > 0.0) || !(time_tolerance < 0.5))
    return bad("time_tolerance", time_tolerance, "must be in (0, 0.5)");
  if (!(refine_threshold >= 0.0)) return bad("refine_threshold", refine_threshold, "must be >= 0");
  if (max_iterations < 1 || max_iterations > 1000)
    return bad("max_iterations", max_iterations, "must be in [1, 1000]");
  if (StiffnessShape parsed; !parseStiffnessShape(toString(stiffness_shape), &parsed))
    return bad(
        "stiffness_shape", toString(stiffness_shape),
        "must be square, fourier:H (1 <= H <= " + std::to_string(StiffnessShape::kMaxHarmonics) +
            ") or table:N (3 <= N <= " + std::to_string(StiffnessShape::kMaxNodes) + ")");
  return {};
}

}  // namespace gear_damping_id
