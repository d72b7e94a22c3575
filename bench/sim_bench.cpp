// Simulator throughput (issue 3 bar: >= 50 M output samples/s, single thread, default case).
// The SignalTable is allocated once before the timed loop and reused (simulate() resizes only
// when the size changes), so first-touch page faults are NOT in the timed region.
#include <benchmark/benchmark.h>

#include "gear_sim/simulator.hpp"

namespace {

void runSim(benchmark::State& state, gear_sim::SimConfig c) {
  c.simulation.duration = static_cast<double>(state.range(0)) / c.simulation.sample_rate;
  gear_sim::SignalTable t;
  std::string error;
  if (!gear_sim::simulate(c, &t, &error)) state.SkipWithError(error.c_str());  // allocation here
  for (auto _ : state) {
    gear_sim::simulate(c, &t, &error);
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
  c.simulation.integrator = gear_sim::Integrator::RK2;
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

}  // namespace

BENCHMARK(BM_SimulateDefaultRk4)->Arg(10000)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateDefaultRk4SwitchesBetweenSamples)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateRk2)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateTorsional)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SimulateTrapezoidStiffness)->Arg(1000000)->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
