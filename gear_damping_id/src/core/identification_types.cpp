#include "gear_damping_id/identification_types.hpp"

#include <cmath>
#include <sstream>

namespace gear_damping_id {

std::string toString(Formulation f) {
  switch (f) {
    case Formulation::Known: return "known";
    case Formulation::Greybox: return "greybox";
    case Formulation::Paper: return "paper";
    case Formulation::Legacy: return "legacy";
  }
  return "?";
}

std::string toString(DampingModel m) {
  switch (m) {
    case DampingModel::Piecewise: return "piecewise";
    case DampingModel::Constant: return "constant";
    case DampingModel::LoadLaw: return "load_law";
  }
  return "?";
}

bool parseFormulation(const std::string& s, Formulation* out) {
  for (Formulation f :
       {Formulation::Known, Formulation::Greybox, Formulation::Paper, Formulation::Legacy}) {
    if (s == toString(f)) {
      *out = f;
      return true;
    }
  }
  return false;
}

bool parseDampingModel(const std::string& s, DampingModel* out) {
  for (DampingModel m : {DampingModel::Piecewise, DampingModel::Constant, DampingModel::LoadLaw}) {
    if (s == toString(m)) {
      *out = m;
      return true;
    }
  }
  return false;
}

std::string IdentificationOptions::validate() const {
  std::ostringstream e;
  if (!(segment_length >= 0.0)) {
    e << "segment_length = " << segment_length
      << ": must be >= 0 [s] (0 or .inf = the whole analysed record)";
  } else if (!(window_length >= 0.0) || !std::isfinite(window_length)) {
    e << "window_length = " << window_length << ": must be >= 0 [s] (0 = automatic)";
  } else if (std::isnan(t_start) || std::isnan(t_end) || !(t_end > t_start)) {
    e << "t_start = " << t_start << ", t_end = " << t_end << ": need t_start < t_end";
  } else if (!(max_condition > 1.0) || max_condition > 1e7) {
    e << "max_condition = " << max_condition << ": must be in (1, 1e7]";
  } else if (!(time_tolerance > 0.0) || !(time_tolerance < 0.5)) {
    e << "time_tolerance = " << time_tolerance << ": must be in (0, 0.5)";
  } else if (!(refine_threshold >= 0.0)) {
    e << "refine_threshold = " << refine_threshold << ": must be >= 0";
  } else if (max_iterations < 1 || max_iterations > 1000) {
    e << "max_iterations = " << max_iterations << ": must be in [1, 1000]";
  }
  return e.str();
}

}  // namespace gear_damping_id
