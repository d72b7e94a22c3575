// wavelet_node's private parameters: NodeOptions and the one function that reads and validates
// them, shared by the node and the shipped-configuration test (which feeds it config/wavelet.yaml
// without a parameter server).
#pragma once

#include <cmath>
#include <map>
#include <string>

#include "gear_damping_id/stream_assembler.hpp"
#include "gear_damping_id/wavelet_analysis.hpp"
#include "node_common.hpp"

namespace gear_damping_nodes {

// The node parameter that sets a StreamOptions field of another name.
inline const std::map<std::string, std::string> kStreamParams = {{"segment_length", "window"}};

struct WaveletNodeOptions {
  gear_damping_id::WaveletOptions wavelet;
  gear_damping_id::StreamOptions stream;
  double window = 0.1;           // [s] > 0
  double analysis_budget = 0.8;  // [fraction of one core] above it, windows are skipped
  int min_window_samples = 256;  // [samples]
  IntakeOptions intake;
  std::string gear_config;  // gear YAML for the parametric checks; empty: gear/params if published
};

/// Reads and validates every private parameter of wavelet_node from `p`; false after ROS_FATAL
/// naming the parameter.
inline bool readWaveletParameters(ParamReader& p, WaveletNodeOptions* o) {
  gear_damping_id::WaveletOptions& w = o->wavelet;
  int n_scales = w.n_scales, max_modes = w.max_modes;
  if (!p.getDouble("window", &o->window, "s") ||
      !p.get("min_window_samples", &o->min_window_samples, "samples") ||
      !p.getDouble("analysis_budget", &o->analysis_budget, "of one core") ||
      !p.getDouble("f_min", &w.f_min, "Hz") || !p.getDouble("f_max", &w.f_max, "Hz") ||
      !p.get("n_scales", &n_scales) || !p.getDouble("omega0", &w.omega0) ||
      !p.getDouble("peak_omega0", &w.peak_omega0) || !p.getDouble("fit_omega0", &w.fit_omega0) ||
      !p.getDouble("max_fit_omega0", &w.max_fit_omega0) ||
      !p.getDouble("peak_prominence", &w.peak_prominence) ||
      !p.getDouble("min_separation_hz", &w.min_separation_hz, "Hz") ||
      !p.get("max_modes", &max_modes) || !p.getDouble("coi_factor", &w.coi_factor) ||
      !p.getDouble("floor_factor", &w.floor_factor) || !p.getDouble("min_r2", &w.min_r2) ||
      !p.getDouble("min_decay_nepers", &w.min_decay_nepers) ||
      !p.get("order_frequencies", &w.order_frequencies, "Hz") ||
      !p.get("mode_frequencies", &w.mode_frequencies, "Hz") || !p.get("threads", &w.threads) ||
      !p.get("gear_config", &o->gear_config) || !readIntakeParams(p, &o->intake)) {
    return false;
  }
  p.allow("diagnostic_period");
  if (!p.rejectUnknown()) return false;
  w.n_scales = n_scales;
  w.max_modes = max_modes;
  w.full_scalogram = false;  // no figure here: only the rows the fits need
  if (!(o->window > 0.0) || !std::isfinite(o->window)) {
    ROS_FATAL("~window = %g: must be > 0 and finite [s] (the node buffers one window)", o->window);
    return false;
  }
  if (!(o->analysis_budget > 0.0 && o->analysis_budget <= 1.0)) {
    ROS_FATAL("~analysis_budget = %g: must be in (0, 1] [fraction of one core]",
              o->analysis_budget);
    return false;
  }
  if (o->min_window_samples < 64) {
    ROS_FATAL("~min_window_samples = %d: must be >= 64 [samples]", o->min_window_samples);
    return false;
  }
  o->stream.segment_length = o->window;
  applyIntake(o->intake, &o->stream);
  o->stream.context = 0;
  gear_sim::OptionStatus e = w.check();
  if (e.ok()) e = o->stream.check();
  if (!e.ok()) {
    ROS_FATAL("%s", paramError(e, kStreamParams).c_str());
    return false;
  }
  ROS_INFO("wavelet_node:%s", p.summary().c_str());
  return true;
}

}  // namespace gear_damping_nodes
