// The spur-gear-pair simulator (docs/method.md §3): integrates eq. (4) (or the torsional eq. 1)
// with RK4/RK2, stepping exactly onto every stiffness switch, load kink and damping change,
// and fills a SignalTable with every docs/method.md §6 column. No ROS.
#pragma once

#include <string>

#include "gear_sim/signal_table.hpp"
#include "gear_sim/sim_config.hpp"
#include "gear_sim/status.hpp"

namespace gear_sim {

/// Runs the simulation. Output columns: time, dte (with measurement noise when
/// simulation.noise_snr_db is finite: white Gaussian, sigma = std(y - mean y) / 10^(SNR/20),
/// std::mt19937_64 seeded with simulation.seed), dte_velocity (noise-free), stiffness (value
/// holding from each sample's instant on), torque, mesh_state, mesh_phase, damping (true c(t));
/// theta1, theta2 for the torsional model. Samples n = 0..N-1, N = round(duration*fs), at
/// t = n/fs. `out` is resized only when its size differs, so a caller can reuse its buffers.
/// InvalidArgument (message and Status::field() naming the YAML key) when the configuration is
/// invalid or the integration diverges.
Status simulate(const SimConfig& config, SignalTable* out);

/// Natural frequency sqrt(k_mean/Me) / (2 pi) [Hz] of the gear model.
double naturalFrequencyHz(const GearPair& gears, const MeshOptions& mesh);

/// Floquet growth rate [1/s] of the undamped mesh equation Me y'' + k(u(t)) y = 0 at a constant
/// mesh frequency f_mesh [Hz]: lambda = acosh(|tr Phi| / 2) f_mesh, Phi the equation's monodromy
/// (state transition) matrix over one mesh cycle; 0 where |tr Phi| <= 2 (outside every
/// parametric instability region). With damping C = c/Me the free response then decays on
/// average at C/2 exactly where lambda = 0, and as exp(-(C/2 -+ lambda) t) (two Floquet
/// solutions) inside a region: a decay rate measured from the response (the wavelet) is off the
/// damping's by up to lambda. Exact rotations on the pieces where k is constant, RK4 at
/// omega h <= 0.01 elsewhere (relative error of tr Phi ~1e-11); 0 for a Fourier stiffness
/// without harmonics. NaN for f_mesh <= 0, a non-finite value, or a cycle needing more than 6e4
/// RK4 steps (2 ms, 6 ms with 100 Fourier harmonics: a mesh frequency below 1/76 of the natural
/// frequency at the stiffness maximum for a Fourier stiffness, 1/760 for a trapezoid with 5 %
/// ramps, where the resonance orders are above ~150 and their regions negligibly narrow).
double parametricGrowthRate(const GearPair& gears, const MeshOptions& mesh, double f_mesh);

/// Adds white Gaussian noise to `y` at the given SNR [dB] (SNR = 20 log10(std(y - mean)/sigma));
/// returns sigma. Deterministic for a given seed.
double addNoise(Eigen::VectorXd* y, double snr_db, unsigned long seed);

}  // namespace gear_sim
