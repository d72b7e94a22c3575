// Output-error refinement throughput (issue bar: >= 25 M samples/s on one thread), the
// refinement alone: the integral-method estimate it starts from is computed once, outside the
// timed region, and each iteration refines a fresh copy of it. Reported, not asserted.
//
// Data: the Table 1 default case (sine load, load-dependent damping, 1 MHz) with white noise at
// 40 dB, 1e6 samples in 1 ms segments; `trapezoid` the same with trapezoid stiffness (smooth
// stiffness: the tabled RK4 step instead of the affine maps). The piecewise cases include the
// within-segment load test (its enlarged fit iterated where the damping varies, as it does in
// this case). "Reference" runs the generic RK4 of the state and sensitivities with per-stage
// look-ups everywhere (the slow path the tables and affine maps replace). `TorqueNoise`: the
// known piecewise case with white noise of 0.2 % of the mean load on the torque samples, whose
// response the refinement propagates into C_std (output_error.hpp: the adjoint pass).
#include <benchmark/benchmark.h>

#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <tuple>

#include "../test/unit/support/status_support.hpp"
#include "gear_damping_id/integral_method.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_sim/simulator.hpp"

namespace {

using gear_damping_id::DampingModel;
using gear_damping_id::Formulation;
using gear_damping_id::IdentificationOptions;

struct Case {
  gear_sim::SimConfig config;
  gear_sim::SignalTable table;
  gear_damping_id::GearConstants gear;
};

const Case& data(long n, bool trapezoid, bool torque_noise = false) {
  static std::map<std::tuple<long, bool, bool>, Case> cache;
  auto it = cache.find({n, trapezoid, torque_noise});
  if (it != cache.end()) return it->second;
  Case d;
  d.config.simulation.sample_rate = 1e6;
  d.config.simulation.duration = static_cast<double>(n) / 1e6;
  d.config.simulation.noise_snr_db = 40.0;
  if (trapezoid) {
    d.config.mesh.model = gear_sim::StiffnessModel::Trapezoid;
    d.config.mesh.transition_fraction = 0.12;
  }
  std::string e;
  if (!gear_test::ok(gear_sim::simulate(d.config, &d.table), &e)) throw std::runtime_error(e);
  d.gear = gear_damping_id::gearConstants(d.config.gearModel());
  if (torque_noise) {
    std::mt19937_64 gen(18);
    std::normal_distribution<double> nd(0.0, 2e-3 * d.config.load.mean);
    for (Eigen::Index i = 0; i < d.table.size(); ++i) d.table.torque[i] += nd(gen);
  }
  return cache.emplace(std::make_tuple(n, trapezoid, torque_noise), std::move(d)).first->second;
}

void runRefine(benchmark::State& state, Formulation f, DampingModel m, bool trapezoid,
               bool reference, bool torque_noise = false) {
  const long n = state.range(0);
  const Case& d = data(n, trapezoid, torque_noise);
  const auto view = gear_damping_id::SignalView::of(d.table);
  IdentificationOptions o;
  o.formulation = f;
  o.model = m;
  o.refine = IdentificationOptions::Refine::Never;
  o.window_length = gear_damping_id::defaultWindowLength(view, d.gear);
  const auto ranges = gear_damping_id::segmentRanges(view, o);
  gear_damping_id::IdentificationResult start, r;
  std::string e;
  if (!gear_test::ok(gear_damping_id::identify(d.table, d.gear, o, &start), &e)) {
    state.SkipWithError(e.c_str());
    return;
  }
  for (auto _ : state) {
    state.PauseTiming();
    r = start;
    state.ResumeTiming();
    if (!gear_test::ok(gear_damping_id::refineOutputError(view, ranges, d.gear, o, &r, reference),
                       &e)) {
      state.SkipWithError(e.c_str());
      break;
    }
    benchmark::DoNotOptimize(r.segments.data());
  }
  state.counters["samples/s"] =
      benchmark::Counter(static_cast<double>(state.iterations() * n), benchmark::Counter::kIsRate);
  state.counters["gn_iterations"] = r.iterations;
}

void BM_RefineKnownPiecewise(benchmark::State& s) {
  runRefine(s, Formulation::Known, DampingModel::Piecewise, false, false);
}
void BM_RefineKnownPiecewiseReference(benchmark::State& s) {
  runRefine(s, Formulation::Known, DampingModel::Piecewise, false, true);
}
void BM_RefineGreyboxPiecewise(benchmark::State& s) {
  runRefine(s, Formulation::Greybox, DampingModel::Piecewise, false, false);
}
void BM_RefineKnownConstant(benchmark::State& s) {
  runRefine(s, Formulation::Known, DampingModel::Constant, false, false);
}
void BM_RefineKnownLoadLaw(benchmark::State& s) {
  runRefine(s, Formulation::Known, DampingModel::LoadLaw, false, false);
}
void BM_RefineTrapezoidKnownPiecewise(benchmark::State& s) {
  runRefine(s, Formulation::Known, DampingModel::Piecewise, true, false);
}
void BM_RefineKnownPiecewiseTorqueNoise(benchmark::State& s) {
  runRefine(s, Formulation::Known, DampingModel::Piecewise, false, false, true);
}

}  // namespace

BENCHMARK(BM_RefineKnownPiecewise)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RefineKnownPiecewiseReference)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RefineGreyboxPiecewise)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RefineKnownConstant)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RefineKnownLoadLaw)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RefineTrapezoidKnownPiecewise)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RefineKnownPiecewiseTorqueNoise)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
