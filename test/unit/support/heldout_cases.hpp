// Held-out gear cases of the wavelet validation (scripts/heldout_sweep.py --check wavelet draws),
// shared by the core tests (wavelet_gear_case_test) and the CLI tests (analyze_cli_test).
#pragma once

#include <sstream>
#include <string>
#include <vector>

namespace gear_test {

// The drawn gear, mesh, speed, load and damping; the simulation: 50 ms at the given rate
// and SNR [dB], the simulator's noise seed.
struct HeldOut {
  std::string name, yaml;
  double rate;
  const char* snr;  // (YAML: .inf for none)
  long seed;
};

// The held-out cases (scripts/heldout_sweep.py --check wavelet draws).
inline const std::vector<HeldOut>& heldOutCases() {
  static const std::vector<HeldOut> cases = {
      {"8033", R"(pinion:
  teeth: 36
  inertia: 0.0009225690706884249
  base_radius: 0.05448002840744317
gear:
  teeth: 37
  inertia: 0.010988557559395866
  base_radius: 0.055993362529872144
mesh:
  stiffness_model: square
  k_max: 509690814.3487916
  k_min: 345273544.2571077
  contact_ratio: 1.59523751224908
  initial_phase: 0.4310186229534967
speed:
  profile: constant
  pinion_rpm: 3750.982855398525
load:
  profile: step
  initial: 218.6687092285614
  final: 320.2762699946773
  step_time: 0.033056450747272134
damping:
  model: piecewise
  ratios: [0.043462126806109905, 0.03531790635299718, 0.05591691775703924]
  times: [0.0, 0.01073374998094656, 0.0308954746883053]
)",
       500000.0, "30", 46349},
      {"9109", R"(pinion:
  teeth: 24
  inertia: 0.00034553136046871667
  base_radius: 0.05501589542005936
gear:
  teeth: 46
  inertia: 0.019470757184636346
  base_radius: 0.10544713288844709
mesh:
  stiffness_model: square
  k_max: 450938290.6450703
  k_min: 213276565.53698123
  contact_ratio: 1.5133575509627497
  initial_phase: 0.03715291573867685
speed:
  profile: constant
  pinion_rpm: 1043.0306793656557
load:
  profile: constant
  mean: 303.00474347720996
damping:
  model: load_linear
  c0: 363.07653382017594
  c1: 0.0025626686253434894
)",
       250000.0, "20", 348313},
      {"9007", R"(pinion:
  teeth: 27
  inertia: 0.0006625237811226723
  base_radius: 0.0645244038466517
gear:
  teeth: 80
  inertia: 0.0052187321002550215
  base_radius: 0.19118341880489392
mesh:
  stiffness_model: square
  k_max: 321282772.70631516
  k_min: 211895051.08087632
  contact_ratio: 1.6538104604367996
  initial_phase: 0.39589250355689376
speed:
  profile: constant
  pinion_rpm: 5964.076547852278
load:
  profile: sine
  mean: 219.83577651837516
  amplitude: 95.81099158915706
  frequency: 73.24953650339107
damping:
  model: load_linear
  c0: 121.30443119211556
  c1: 0.48924494381241146
)",
       250000.0, "20", 79776},
      {"10020", R"(pinion:
  teeth: 40
  inertia: 0.00012367457233873483
  base_radius: 0.03315866482089838
gear:
  teeth: 52
  inertia: 0.01009962546208145
  base_radius: 0.04310626426716789
mesh:
  stiffness_model: square
  k_max: 783492128.6062533
  k_min: 362924239.6361788
  contact_ratio: 1.8858860556591517
  initial_phase: 0.6350397562361249
speed:
  profile: constant
  pinion_rpm: 1843.195075481594
load:
  profile: ramp
  initial: 36.34788899723196
  final: 41.99772996917685
  ramp_start: 0.0
  ramp_end: 0.05
damping:
  model: load_linear
  c0: 159.7089908847342
  c1: 0.6979642225513204
)",
       1000000.0, ".inf", 849604},
  };
  return cases;
}

// Case c's simulator configuration (YAML): its gear, speed, load and damping, 50 ms at its rate
// and SNR with its noise seed.
inline std::string heldOutConfig(const HeldOut& c) {
  std::ostringstream yaml;
  yaml << c.yaml << "simulation:\n  duration: 0.05\n  sample_rate: " << c.rate
       << "\n  integrator: rk4\n  substeps: 1\n  dynamics: reduced\n  noise_snr_db: " << c.snr
       << "\n  seed: " << c.seed << "\n";
  return yaml.str();
}

// The case named `name` (its config's YAML), or "" when there is none.
inline std::string heldOutConfig(const std::string& name) {
  for (const HeldOut& c : heldOutCases())
    if (c.name == name) return heldOutConfig(c);
  return "";
}

}  // namespace gear_test
