// The gear's context of a wavelet analysis: what the trust checks of analyzeWavelet need to know
// about the gear pair (WaveletOptions::order_frequencies, parametric_growth_rate), derived from
// the record's cumulative mesh phase and, where known, the gear parameters. One code path for
// `analyze --wavelet` and the live wavelet_node. No ROS.
#pragma once

#include <cstddef>
#include <functional>
#include <string>

#include "gear_damping_id/wavelet_analysis.hpp"
#include "gear_sim/sim_config.hpp"

namespace gear_damping_id {

/// A mesh phase step above this multiple of the typical step (the median of the steps where the
/// phase advances) is not a rotation: a corrupt value (a jump to 1e308 is finite and
/// increasing). A speed ramp, a start or a stop inside the samples, and an encoder's staircase
/// stay well below it.
constexpr double kMaxMeshPhaseStepRatio = 64.0;

/// Why the cumulative mesh phase phase[0..n) [mesh cycles] at sample_rate [Hz] cannot give the
/// mesh frequency, or "" when it can: every value finite, never decreasing, advancing
/// (phase[n-1] > phase[0]) with a finite mean frequency, and no step above
/// kMaxMeshPhaseStepRatio times the typical step.
std::string meshPhaseProblem(const double* phase, size_t n, double sample_rate);

/// The mesh phase [mesh cycles] at sample k of the analysed samples.
using MeshPhaseAt = std::function<double(size_t k)>;

/// Number of blocks of the record with their own parametric growth rate (a speed ramp can cross
/// instability regions of the mesh stiffness).
constexpr size_t kGrowthBlocks = 32;

/// Blocks whose mesh frequencies agree within this relative difference share one growth-rate
/// evaluation (a smooth stiffness at a low mesh frequency costs up to ~20 ms per evaluation; a
/// speed from encoders is not known to better than this).
constexpr double kSameMeshFrequency = 1e-4;

/// Sets the gear's context of a wavelet analysis of n samples at sample_rate [Hz] in *options
/// and returns the mean mesh frequency [Hz] ((phase(n-1) - phase(0)) sample_rate / (n-1); 0 when
/// that is not finite and > 0, and then nothing is set):
/// - options->order_frequencies, when empty: gearOrderFrequencies of that mesh frequency and the
///   tooth counts of `model` (without a model: the mesh frequency alone);
/// - with a model: options->parametric_growth_rate, the Floquet growth rate of its mesh
///   stiffness (gear_sim::parametricGrowthRate) at the mesh frequency of each of kGrowthBlocks
///   blocks of the samples (parametric_growth_block their length [s]; fewer than
///   4 kGrowthBlocks samples: one rate at the mean mesh frequency; blocks within
///   kSameMeshFrequency of a block before them take its rate). A rate that cannot be computed
///   counts as 0.
/// phase(k) is read at the block boundaries only.
double applyGearContext(const MeshPhaseAt& phase, size_t n, double sample_rate,
                        const gear_sim::GearModel* model, WaveletOptions* options);

/// applyGearContext from the samples' own mesh phase phase[0..n) [mesh cycles] (a record's or a
/// live window's mesh_phase): "" after setting the context (the mean mesh frequency into
/// *f_mesh) when meshPhaseProblem finds nothing wrong, else that problem, with nothing set and
/// *f_mesh NaN.
std::string applyGearContext(const double* phase, size_t n, double sample_rate,
                             const gear_sim::GearModel* model, WaveletOptions* options,
                             double* f_mesh);

}  // namespace gear_damping_id
