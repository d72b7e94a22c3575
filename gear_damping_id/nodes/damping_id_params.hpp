// damping_id_node's private parameters: NodeOptions and the one function that reads and
// validates them, shared by the node and the shipped-configuration test (which feeds it
// config/damping_id.yaml without a parameter server).
#pragma once

#include <string>
#include <utility>

#include "gear_damping_id/identification_types.hpp"
#include "gear_damping_id/live_identification.hpp"
#include "gear_damping_id/ste_model.hpp"
#include "gear_damping_id/stream_assembler.hpp"
#include "node_common.hpp"

namespace gear_damping_nodes {

struct DampingIdNodeOptions {
  gear_damping_id::IdentificationOptions id;
  gear_damping_id::StreamOptions stream;
  IntakeOptions intake;
  bool publish_modeled_response = true;
  double cumulative_period = 0.1;  // [s] wall: most frequent /gear/damping update
  int cumulative_segments = 1000;  // last segments in /gear/damping
  int history_segments = 20000;    // segments kept for ~get_damping (bounded store)
  int shared_segments = 1000;      // constant/load_law: span of the sliding problem
  double refine_budget = 0.7;      // refinement while the node stays within this fraction of a core
  std::string gear_config;         // YAML path; empty: /gear/params
  // STE (docs/ste.md): "" = none, else an `analyze --ste` spec; calibrated jointly on the first
  // ste_calibration_segments segments, then held. The tooth counts come with the gear.
  std::string ste;
  std::string ste_damping = gear_sim::steDampingName(gear_sim::SteDamping::Relative);
  int ste_calibration_segments = 10;
  gear_damping_id::SteModelOptions ste_options;
};

/// Reads and validates every private parameter of damping_id_node from `p`; false after
/// ROS_FATAL naming the parameter.
inline bool readDampingIdParameters(ParamReader& p, DampingIdNodeOptions* o) {
  std::string formulation = "known", model = "piecewise", refine = "auto";
  std::string stiffness_shape = "square";
  int max_iterations = o->id.max_iterations;
  if (!p.get("formulation", &formulation) || !p.get("model", &model) ||
      !p.getDouble("segment_length", &o->id.segment_length, "s") ||
      !p.getDouble("window_length", &o->id.window_length, "s") ||
      !p.getDouble("t_start", &o->id.t_start, "s") || !p.getDouble("t_end", &o->id.t_end, "s") ||
      !p.getDouble("max_condition", &o->id.max_condition) || !p.get("refine", &refine) ||
      !p.getDouble("refine_threshold", &o->id.refine_threshold) ||
      !p.get("max_iterations", &max_iterations) || !p.get("stiffness_shape", &stiffness_shape) ||
      !readIntakeParams(p, &o->intake) ||
      !p.getDouble("cumulative_period", &o->cumulative_period, "s") ||
      !p.get("publish_modeled_response", &o->publish_modeled_response) ||
      !p.get("cumulative_segments", &o->cumulative_segments, "segments") ||
      !p.get("history_segments", &o->history_segments, "segments") ||
      !p.get("shared_segments", &o->shared_segments, "segments") ||
      !p.getDouble("refine_budget", &o->refine_budget, "of one core") ||
      !p.get("gear_config", &o->gear_config) || !p.get("ste", &o->ste) ||
      !p.get("ste_damping", &o->ste_damping) ||
      !p.get("ste_calibration_segments", &o->ste_calibration_segments, "segments")) {
    return false;
  }
  p.allow("diagnostic_period");  // read by diagnostic_updater
  if (!p.rejectUnknown()) return false;
  if (!gear_damping_id::parseFormulation(formulation, &o->id.formulation)) {
    ROS_FATAL("~formulation = '%s': must be known, greybox, paper or legacy", formulation.c_str());
    return false;
  }
  if (!gear_damping_id::parseDampingModel(model, &o->id.model)) {
    ROS_FATAL("~model = '%s': must be piecewise, constant or load_law", model.c_str());
    return false;
  }
  using R = gear_damping_id::IdentificationOptions::Refine;
  if (refine == "auto")
    o->id.refine = R::Auto;
  else if (refine == "always")
    o->id.refine = R::Always;
  else if (refine == "never")
    o->id.refine = R::Never;
  else {
    ROS_FATAL("~refine = '%s': must be auto, always or never", refine.c_str());
    return false;
  }
  o->id.max_iterations = max_iterations;
  if (!gear_damping_id::parseStiffnessShape(stiffness_shape, &o->id.stiffness_shape)) {
    ROS_FATAL("~stiffness_shape = '%s': must be square, fourier:H (1..16) or table:N (3..32)",
              stiffness_shape.c_str());
    return false;
  }
  gear_sim::OptionStatus e = o->id.check();
  if (e.ok()) {
    o->stream.segment_length = o->id.segment_length;
    o->stream.t_start = o->id.t_start;
    o->stream.t_end = o->id.t_end;
    applyIntake(o->intake, &o->stream);
    e = o->stream.check();
  }
  if (!e.ok()) {
    ROS_FATAL("%s", paramError(e).c_str());
    return false;
  }
  for (const auto& [name, v] :
       {std::pair<const char*, int>{"cumulative_segments", o->cumulative_segments},
        {"history_segments", o->history_segments},
        {"shared_segments", o->shared_segments}}) {
    if (v < 1 || v > 10000000) {
      ROS_FATAL("~%s = %d: must be in [1, 1e7] [segments]", name, v);
      return false;
    }
  }
  if (!o->ste.empty()) {
    gear_sim::Status s = gear_damping_id::parseSteSpec(o->ste, &o->ste_options);
    if (s.ok()) s = gear_damping_id::LiveIdentification::checkSte(o->id);
    if (!s.ok()) {
      ROS_FATAL("~ste = '%s': %s", o->ste.c_str(), s.message().c_str());
      return false;
    }
    const gear_sim::Result<gear_sim::SteDamping> damping =
        gear_sim::parseSteDamping(o->ste_damping);
    if (!damping.ok()) {
      ROS_FATAL("~ste_damping = '%s': must be relative or dte", o->ste_damping.c_str());
      return false;
    }
    o->ste_options.damping = *damping;
    if (o->publish_modeled_response) {
      ROS_WARN("~ste: the modeled response does not include the STE: not published");
      o->publish_modeled_response = false;
    }
    if (o->ste_calibration_segments < 1 || o->ste_calibration_segments > 100000) {
      ROS_FATAL("~ste_calibration_segments = %d: must be in [1, 1e5] [segments]",
                o->ste_calibration_segments);
      return false;
    }
  }
  if (!(o->refine_budget > 0.0 && o->refine_budget <= 1.0)) {
    ROS_FATAL("~refine_budget = %g: must be in (0, 1] [fraction of one core]", o->refine_budget);
    return false;
  }
  if (!(o->cumulative_period >= 0.0)) {
    ROS_FATAL("~cumulative_period = %g: must be >= 0 [s]", o->cumulative_period);
    return false;
  }
  ROS_INFO("damping_id_node:%s", p.summary().c_str());
  return true;
}

}  // namespace gear_damping_nodes
