#include "gear_damping_id/ste_io.hpp"

#include <cmath>
#include <sstream>

namespace gear_damping_id {

namespace {

nlohmann::json num(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); }

std::string csvNumber(double v) {
  if (!std::isfinite(v)) return "";
  std::ostringstream os;
  os.precision(17);
  os << v;
  return os.str();
}

double amplitude(const SteTerm& t) { return std::hypot(t.cos, t.sin); }
// e = A cos(order * angle - phase)
double phase(const SteTerm& t) { return std::atan2(t.sin, t.cos); }

}  // namespace

nlohmann::json steJson(const SteResult& s) {
  nlohmann::json j;
  j["damping"] = gear_sim::steDampingName(s.options.damping);
  j["shared"] = true;
  j["offset"] = nullptr;
  j["mesh"] = nlohmann::json::array();
  j["shaft"] = nlohmann::json::array();
  for (const SteTerm& t : s.terms) {
    if (t.kind == "offset") {
      j["offset"] = {{"value", num(t.cos)}, {"std", num(t.cos_std)}};
      continue;
    }
    nlohmann::json e = {{"order", t.order},          {"cos", num(t.cos)},
                        {"sin", num(t.sin)},         {"cos_std", num(t.cos_std)},
                        {"sin_std", num(t.sin_std)}, {"amplitude", num(amplitude(t))},
                        {"phase", num(phase(t))}};
    if (t.kind == "mesh") {
      j["mesh"].push_back(e);
    } else {
      e["shaft"] = t.kind;
      j["shaft"].push_back(e);
    }
  }
  j["condition"] = num(s.condition);
  j["max_correlation"] = num(s.max_correlation);
  j["separable"] = s.separable;
  j["iterations"] = s.iterations;
  j["residual_rms"] = num(s.residual_rms);
  j["refined"] = s.refined;
  return j;
}

gear_sim::Status writeSteCsv(const std::string& dir, const SteResult& s, OutputStage* stage) {
  std::ostringstream os;
  os << "kind,order,cos,sin,cos_std,sin_std,amplitude,phase\n";
  for (const SteTerm& t : s.terms)
    os << t.kind << "," << t.order << "," << csvNumber(t.cos) << "," << csvNumber(t.sin) << ","
       << csvNumber(t.cos_std) << "," << csvNumber(t.sin_std) << "," << csvNumber(amplitude(t))
       << "," << csvNumber(phase(t)) << "\n";
  return writeFileAtomically(dir + "/ste.csv", os.str(), stage);
}

}  // namespace gear_damping_id
