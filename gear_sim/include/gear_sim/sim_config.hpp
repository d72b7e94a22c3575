// Simulation configuration: one struct per YAML section (README "Simulator configuration").
// Default-constructed = the docs/method.md §3 default case: Table 1 gears, 3000 rpm pinion (1 kHz
// mesh), T1(t) = 100 N*m * (1 + 0.5 sin(2*pi*100 t)), load-dependent xi(t) =
// 0.05 * (1 + 0.6 (T1/T1_mean - 1)), RK4 at 1 MHz for 10 ms, no noise. No ROS; SI units
// (speeds in rpm).
#pragma once

#include <limits>
#include <string>
#include <vector>

#include "gear_sim/gear_pair.hpp"
#include "gear_sim/option_status.hpp"
#include "gear_sim/sdof_integrator.hpp"
#include "gear_sim/ste.hpp"

namespace gear_sim {

enum class StiffnessModel {
  Square,     ///< eq. (2): k_max for the first (eps-1)*Te of each mesh period, k_min after
  Trapezoid,  ///< square wave with linear transitions lasting transition_fraction*Te
  Fourier,    ///< k_mean + sum_h (a_h cos(2 pi h u) + b_h sin(2 pi h u)), u = mesh phase
  Constant    ///< k_mean
};

struct MeshOptions {
  StiffnessModel model = StiffnessModel::Square;
  double k_max = 4.0e8;               ///< [N/m] double-contact stiffness
  double k_min = 2.0e8;               ///< [N/m] single-contact stiffness
  double contact_ratio = 1.6;         ///< [-] eps_alpha in (1, 2]
  double transition_fraction = 0.05;  ///< [-] trapezoid ramp length / Te, in (0, min(eps-1, 2-eps)]
  double k_mean = 3.2e8;              ///< [N/m] fourier / constant models
  std::vector<double> fourier_cos;    ///< [N/m] a_h, h = 1.. (fourier model)
  std::vector<double> fourier_sin;    ///< [N/m] b_h, h = 1.. (fourier model)
  double initial_phase = 0.0;         ///< [mesh cycles] mesh phase at t = 0, in [0, 1)
  OptionStatus check() const;         ///< ok, or the first rule broken (option_status.hpp)
};

enum class SpeedProfile {
  Constant,  ///< pinion_rpm throughout
  Ramp       ///< linear from pinion_rpm to end_rpm over ramp_time, then constant
};

struct SpeedOptions {
  SpeedProfile profile = SpeedProfile::Constant;
  double pinion_rpm = 3000.0;  ///< [rev/min] (initial) pinion speed, > 0
  double end_rpm = 3000.0;     ///< [rev/min] ramp: final speed, > 0
  double ramp_time = 0.01;     ///< [s] ramp: duration of the linear change, > 0
  OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

enum class LoadProfile {
  Constant,   ///< mean
  Sine,       ///< mean + amplitude * sin(2 pi frequency t + phase)
  Step,       ///< initial before step_time, final after
  Ramp,       ///< initial until ramp_start, linear to final at ramp_end, final after
  Trapezoid,  ///< periodic cycle: low, rise to high over rise, hold high, fall over fall, hold low
  Table       ///< piecewise linear through (times, values), held constant outside
};

struct LoadOptions {
  LoadProfile profile = LoadProfile::Sine;
  double mean = 100.0;         ///< [N*m] constant / sine
  double amplitude = 50.0;     ///< [N*m] sine
  double frequency = 100.0;    ///< [Hz] sine
  double phase = 0.0;          ///< [rad] sine
  double initial = 50.0;       ///< [N*m] step / ramp
  double final_value = 150.0;  ///< [N*m] step / ramp (YAML key `final`)
  double step_time = 0.005;    ///< [s] step
  double ramp_start = 0.0;     ///< [s] ramp
  double ramp_end = 0.01;      ///< [s] ramp
  double low = 50.0;           ///< [N*m] trapezoid
  double high = 150.0;         ///< [N*m] trapezoid
  double period = 0.01;        ///< [s] trapezoid cycle length
  double rise = 0.001;         ///< [s] trapezoid
  double hold = 0.004;         ///< [s] trapezoid time at `high`
  double fall = 0.001;         ///< [s] trapezoid (the rest of the period stays at `low`)
  std::vector<double> times;   ///< [s] table, strictly increasing
  std::vector<double> values;  ///< [N*m] table
  OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

/// How the simulated (true) damping varies over the run, like SpeedProfile and LoadProfile: a
/// law and its parametrisation (YAML damping.model). The one DampingModel of the package is
/// gear_damping_id::DampingModel, the model the identification fits (piecewise, constant,
/// load_law); ConstantRatio/ConstantCoefficient are its `constant`, LoadDependent/LoadLinear
/// (both c linear in T1) its `load_law`, Piecewise its `piecewise` on aligned segments.
enum class DampingProfile {
  ConstantRatio,        ///< xi = ratio
  ConstantCoefficient,  ///< c = coefficient
  Piecewise,            ///< xi = ratios[i] for times[i] <= t < times[i+1] (times[0] = 0)
  LoadDependent,        ///< xi(t) = ratio * (1 + load_sensitivity * (T1(t)/T1_mean - 1))
  LoadLinear            ///< c(t) = c0 + c1 * T1(t)
};

/// Damping ratio convention: xi = c / (2 sqrt(k_mean * Me)), k_mean the time-mean stiffness of
/// the mesh model; T1_mean is the time-mean of the load over the simulated duration.
struct DampingOptions {
  DampingProfile model = DampingProfile::LoadDependent;
  double ratio = 0.05;            ///< [-]
  double coefficient = 0.0;       ///< [N*s/m] constant coefficient model
  double load_sensitivity = 0.6;  ///< [-] beta of the load-dependent model
  std::vector<double> times;      ///< [s] piecewise: segment starts, times[0] == 0, increasing
  std::vector<double> ratios;     ///< [-] piecewise: one per segment
  double c0 = 0.0;                ///< [N*s/m] load_linear
  double c1 = 0.0;                ///< [N*s/m per N*m] load_linear
  OptionStatus check() const;     ///< ok, or the first rule broken (option_status.hpp)
};

enum class DynamicsModel {
  Reduced,   ///< eq. (3)/(4): the DTE equation (default)
  Torsional  ///< eq. (1): two rotational DOF; also outputs theta1, theta2
};

/// Size limits of a simulation, checked before anything is allocated (README "Limits"):
/// samples round(duration * sample_rate) (the 8 signal columns take 64 bytes per sample, so
/// 2e7 samples are 1.3 GB), integration substeps per sample, and mesh cycles per sample (a
/// mesh frequency above the sample rate only aliases, and each cycle costs two breakpoints).
constexpr double kMaxSimulationSamples = 2e7;
constexpr int kMaxSubsteps = 1000;
/// Largest damping ratio accepted (xi > 1 is already overdamped; gears have 0.01 to 0.2).
constexpr double kMaxDampingRatio = 10.0;

struct SimulationOptions {
  double duration = 0.01;      ///< [s] > 0; samples n = 0..round(duration*fs)-1 at t = n/fs
  double sample_rate = 1.0e6;  ///< [Hz] output rate, >= 20x the natural frequency
  Integrator integrator = Integrator::Rk4;
  int substeps = 1;  ///< integration steps per output sample, >= 1
  DynamicsModel dynamics = DynamicsModel::Reduced;
  double initial_dte = 0.0;                                       ///< [m] y(0)
  double initial_velocity = 0.0;                                  ///< [m/s] y'(0)
  double noise_snr_db = std::numeric_limits<double>::infinity();  ///< [dB]; inf = no noise
  unsigned long seed = 1;                                         ///< noise generator seed
  OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

/// The gear model alone (what `analyze --params` needs): gears, mesh and speed.
struct GearModel {
  GearPair gears;
  MeshOptions mesh;
  SpeedOptions speed;
  OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

struct SimConfig {
  GearPair gears;
  MeshOptions mesh;
  SpeedOptions speed;
  LoadOptions load;
  DampingOptions damping;
  SimulationOptions simulation;
  SteOptions ste;  ///< static transmission error (YAML section `ste`, docs/ste.md); none by default

  GearModel gearModel() const { return {gears, mesh, speed}; }
  /// The first rule broken; its field is the YAML key (e.g. "mesh.contact_ratio"). Covers
  /// cross-section rules too (sample rate >= 20x the natural frequency, mesh frequency
  /// <= sample rate, load period >= sample step) and the size limits above.
  OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

/// YAML names of the enums ("square", "trapezoid", "fourier", "constant"; "constant", "ramp";
/// "constant", "sine", "step", "ramp", "trapezoid", "table"; "constant", "piecewise",
/// "load_dependent", "load_linear"; "reduced", "torsional"; "rk2", "rk4").
std::string toString(StiffnessModel m);
std::string toString(SpeedProfile p);
std::string toString(LoadProfile p);
std::string toString(DynamicsModel m);
std::string toString(Integrator m);
/// Parsers: false when the name is unknown (the caller names the key in its message).
bool parse(const std::string& s, StiffnessModel* out);
bool parse(const std::string& s, SpeedProfile* out);
bool parse(const std::string& s, LoadProfile* out);
bool parse(const std::string& s, DynamicsModel* out);
bool parse(const std::string& s, Integrator* out);

}  // namespace gear_sim
