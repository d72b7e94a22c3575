#include "gear_sim/gear_pair.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace {

// The paper (and docs/method.md §3) quote Me ~ 0.0813 kg and a natural frequency ~ 10 kHz for
// Table 1; those are rounded figures, so they bound the exact formula to their last digit.
constexpr double kPaperMeRounding = 0.0001;  // [kg] half a unit in the 4th decimal, with margin

TEST(GearPair, Table1EquivalentMassMatchesClosedForm) {
  const gear_sim::GearPair p;  // defaults are Table 1
  const double i1 = 0.00026, i2 = 0.0045, r1 = 0.05, r2 = 0.11;
  EXPECT_DOUBLE_EQ(p.equivalentMass(), i1 * i2 / (i1 * r2 * r2 + i2 * r1 * r1));
  EXPECT_NEAR(p.equivalentMass(), 0.0813, kPaperMeRounding);
}

TEST(GearPair, Table1NaturalFrequencyIsAboutTenKilohertz) {
  const gear_sim::GearPair p;
  const double k_mean = 0.6 * 4e8 + 0.4 * 2e8;  // contact ratio 1.6: k_max for 60 % of Te
  const double f0 = std::sqrt(k_mean / p.equivalentMass()) / (2 * M_PI);
  EXPECT_GT(f0, 9.5e3);
  EXPECT_LT(f0, 10.5e3);
}

TEST(GearPair, ForceFactorIsSumOfRadiusOverInertia) {
  gear_sim::GearPair p;
  p.pinion = {10, 2.0, 0.5};
  p.gear = {30, 4.0, 1.0};
  EXPECT_DOUBLE_EQ(p.forceFactor(), 0.5 / 2.0 + 1.0 / 4.0);
}

TEST(GearPair, NonPositiveInertiaIsRejectedNamingTheField) {
  gear_sim::GearPair p;
  p.gear.inertia = -1.0;
  const std::string e = p.check().message();
  EXPECT_NE(e.find("gear.inertia"), std::string::npos) << e;
  p = gear_sim::GearPair{};
  p.pinion.base_radius = 0.0;
  EXPECT_NE(p.check().message().find("pinion.base_radius"), std::string::npos);
  p = gear_sim::GearPair{};
  p.pinion.teeth = 0;
  EXPECT_NE(p.check().message().find("pinion.teeth"), std::string::npos);
  EXPECT_TRUE(gear_sim::GearPair{}.check().message().empty());
}

}  // namespace
