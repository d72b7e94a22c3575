// Simulator throughput (issue 3 bar: >= 50 M output samples/s, single thread, default case;
// issue 18: >= 40 M samples/s for every stiffness model, load profile and the torsional model).
// The SignalTable is allocated once before the timed loop and reused (simulate() resizes only
// when the size changes), so first-touch page faults are NOT in the timed region.
#include <benchmark/benchmark.h>

#include <cmath>

#include "../test/unit/support/status_support.hpp"
#include "gear_sim/simulator.hpp"

namespace {

void runSim(benchmark::State& state, gear_sim::SimConfig c) {
  c.simulation.duration = static_cast<double>(state.range(0)) / c.simulation.sample_rate;
  gear_sim::SignalTable t;
  std::string error;
  if (!gear_test::ok(gear_sim::simulate(c, &t), &error))
    state.SkipWithError(error.c_str());  // allocation here
  for (auto _ : state) {
    gear_test::ok(gear_sim::simulate(c, &t), &error);
    benchmark::DoNotOptimize(t.dte.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
  state.counters["samples/s"] = benchmark::Counter(
      static_cast<double>(state.iterations() * state.range(0)), benchmark::Counter::kIsRate);
}

void BM_SimulateDefaultRk4(benchmark::State& s) { runSim(s, gear_sim::SimConfig{}); }

void BM_SimulateDefaultRk4SwitchesBetweenSamples(benchmark::State& s) {
  gear_sim::SimConfig c;
  c.speed.pinion_rpm = 2950.0;
  runSim(s, c);
}

void BM_SimulateRk2(benchmark::State& s) {
  gear_sim::SimConfig c;
  c.simulation.integrator = gear_sim::Integrator::Rk2;
  runSim(s, c);
}

void BM_SimulateTorsional(benchmark::State& s) {
  gear_sim::SimConfig c;
  c.simulation.dynamics = gear_sim::DynamicsModel::Torsional;
  runSim(s, c);
}

void BM_SimulateTrapezoidStiffness(benchmark::State& s) {
  gear_sim::SimConfig c;
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  runSim(s, c);
}

void BM_SimulateFourierStiffness(benchmark::State& s) {
  gear_sim::SimConfig c;
  c.mesh.model = gear_sim::StiffnessModel::Fourier;
  c.mesh.fourier_cos = {4e7, -1e7, 5e6};
  c.mesh.fourier_sin = {2e7, 8e6, -3e6};
  runSim(s, c);
}

void BM_SimulateConstantStiffness(benchmark::State& s) {
  gear_sim::SimConfig c;
  c.mesh.model = gear_sim::StiffnessModel::Constant;
  runSim(s, c);
}

// A load table: a piecewise-linear load with a breakpoint every 0.1 ms.
void BM_SimulateTableLoad(benchmark::State& s) {
  gear_sim::SimConfig c;
  c.load.profile = gear_sim::LoadProfile::Table;
  const double duration = static_cast<double>(s.range(0)) / c.simulation.sample_rate;
  for (int i = 0; i <= 10000; ++i) {
    c.load.times.push_back(duration * i / 10000.0);
    c.load.values.push_back(100.0 + 30.0 * std::sin(0.37 * i));
  }
  runSim(s, c);
}

void BM_SimulateTorsionalTrapezoid(benchmark::State& s) {
  gear_sim::SimConfig c;
  c.simulation.dynamics = gear_sim::DynamicsModel::Torsional;
  c.mesh.model = gear_sim::StiffnessModel::Trapezoid;
  runSim(s, c);
}

}  // namespace

BENCHMARK(BM_SimulateDefaultRk4)->Arg(10000)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateDefaultRk4SwitchesBetweenSamples)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateRk2)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateTorsional)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateTrapezoidStiffness)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateFourierStiffness)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateConstantStiffness)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateTableLoad)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateTorsionalTrapezoid)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
