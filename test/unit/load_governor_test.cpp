// LoadGovernor (gear_damping_id/nodes/load_governor.hpp) on a synthetic clock: a node whose
// items cost `base` without the optional stage and `full` with it, arriving at `rate` per
// second. The governor must keep the node's whole load within its budget (so the base work, the
// integral estimate, is never late), use the room it has, and drop the stage entirely when the
// base alone fills the budget.
#include "load_governor.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace {

struct StreamRun {
  double load = 0.0;    // CPU s per s over the measured span
  double staged = 0.0;  // fraction of items that got the stage
  unsigned long stride = 0;
  bool degraded = false;
};

// `seconds` of a steady stream; the first `warm` seconds are not measured.
StreamRun stream(double budget, double rate, double base, double full, double seconds,
                 double warm) {
  gear_damping_nodes::LoadGovernor g(budget);
  const double dt = 1.0 / rate;
  double busy = 0.0, t = 100.0;  // any monotonic origin
  long items = 0, staged = 0;
  const long n = static_cast<long>(seconds * rate), n_warm = static_cast<long>(warm * rate);
  for (long i = 0; i < n; ++i) {
    t += dt;
    const bool stage = g.allow();
    const double cost = stage ? full : base;
    g.record(cost, !stage, t);
    if (i >= n_warm) {
      busy += cost;
      ++items;
      staged += stage ? 1 : 0;
    }
  }
  const double span = static_cast<double>(items) * dt;
  return {busy / span, static_cast<double>(staged) / static_cast<double>(items), g.stride(),
          g.degraded()};
}

TEST(LoadGovernor, WholeNodeStaysWithinTheBudgetAndUsesTheRoom) {
  // 2000 segments/s (2 MHz of 1-ms segments): base 0.2 ms (0.4 core), refined 1 ms (2 cores).
  const double budget = 0.7, base_load = 0.4;
  const StreamRun r = stream(budget, 2000.0, 0.2e-3, 1.0e-3, 120.0, 60.0);
  EXPECT_TRUE(r.degraded);
  EXPECT_LE(r.load, budget * 1.001) << "base + stage exceeds the budget";
  // The room above the base is (0.7 - 0.4) = 0.3 core; one stride step less would exceed it, so
  // at least (room - one item's share) is used: extra 1.6 core / stride, stride = ceil(1.6/0.3).
  const double extra = (1.0e-3 - 0.2e-3) * 2000.0;
  const double stride = std::ceil(extra / (budget - base_load));
  EXPECT_EQ(r.stride, static_cast<unsigned long>(stride));
  EXPECT_NEAR(r.load, base_load + extra / stride, 1e-3);
  EXPECT_NEAR(r.staged, 1.0 / stride, 1e-3);
}

TEST(LoadGovernor, NoStageWhenTheBaseAloneFillsTheBudget) {
  // Base 0.4 ms at 2000/s = 0.8 core > 0.7: every item gets the base work only.
  const StreamRun r = stream(0.7, 2000.0, 0.4e-3, 1.0e-3, 60.0, 30.0);
  EXPECT_TRUE(r.degraded);
  EXPECT_EQ(r.staged, 0.0);
  EXPECT_NEAR(r.load, 0.8, 1e-9);
}

TEST(LoadGovernor, LightStreamGetsTheStageOnEveryItem) {
  // 1000/s at 0.3 ms each with the stage = 0.3 core < 0.7.
  const StreamRun r = stream(0.7, 1000.0, 0.1e-3, 0.3e-3, 60.0, 10.0);
  EXPECT_FALSE(r.degraded);
  EXPECT_EQ(r.stride, 1u);
  EXPECT_EQ(r.staged, 1.0);
}

TEST(LoadGovernor, RecoversWhenTheStreamSlowsDown) {
  gear_damping_nodes::LoadGovernor g(0.7);
  double t = 0.0;
  for (int i = 0; i < 200000; ++i) {  // 100 s at 2000/s, stage 1 ms: degraded
    t += 0.5e-3;
    const bool stage = g.allow();
    g.record(stage ? 1.0e-3 : 0.2e-3, !stage, t);
  }
  ASSERT_TRUE(g.degraded());
  for (int i = 0; i < 12000; ++i) {  // then 60 s at 200/s: 0.2 core with the stage
    t += 5e-3;
    const bool stage = g.allow();
    g.record(stage ? 1.0e-3 : 0.2e-3, !stage, t);
  }
  EXPECT_FALSE(g.degraded());
  EXPECT_NEAR(g.load(), 0.2, 0.01);
}

}  // namespace
