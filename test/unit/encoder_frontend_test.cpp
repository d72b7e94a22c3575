// Encoder front end (docs/rig.md): from simulated shaft encoders to the damping, against the
// simulation's truth. Issue 19 acceptance for the measurement chain:
//  - noise-free uniform encoder input, known stiffness: C within 0.05 % per 1 ms segment, with
//    the mesh offset and the DTE offset estimated from the data;
//  - 16-bit and 20-bit quantised encoders + torque noise (0.1 N*m, 0.1 % of the 100 N*m mean):
//    C within 2x its reported SE in >= 90 % of the segments over 30 seeds;
//  - edge times at 5000 counts/rev give the same C as uniform input within the SE;
//  - records that are not a gear pair are refused with the reason.
#include "gear_damping_id/encoder_frontend.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "gear_sim/encoders.hpp"
#include "gear_sim/rig_csv.hpp"
#include "id_test_support.hpp"
#include "rig_test_support.hpp"
#include "scratch_dir.hpp"
#include "status_support.hpp"

namespace {

using namespace gear_id_test;
namespace gd = gear_damping_id;

struct Chain {
  SignalTable table;
  gd::EncoderFrontEndReport report;
};

Chain frontEnd(const SignalTable& rig, const SimConfig& c, gd::EncoderFrontEndOptions o = {}) {
  Chain ch;
  std::string e;
  EXPECT_TRUE(
      gear_test::ok(gd::encoderToSignalTable(rig, c.gearModel(), o, &ch.table, &ch.report), &e))
      << e;
  return ch;
}

class EncoderChain : public PiecewiseDefaultCase {};

TEST_F(EncoderChain, NoiseFreeUniformGivesCWithinBar) {
  const SimConfig& c = *config_;
  const SignalTable rig = gear_sim::rigRecord(c, encoder(0), *clean_);
  const Chain ch = frontEnd(rig, c);
  // The DTE, the mesh phase and the stiffness are recovered.
  // The switches of this case fall on samples: offsets within one sample's mesh-phase advance
  // (1e-3 cycles) give the same quadrature, so the estimate is determined to that.
  EXPECT_NEAR(ch.report.mesh_offset, expectedMeshOffset(c, encoder(0)), 1.1e-3);
  double dmax = 0.0;
  for (Eigen::Index i = 0; i < rig.size(); ++i)
    dmax = std::max(dmax, std::abs(ch.table.dte[i] - clean_->dte[i]));
  EXPECT_LT(dmax, 1e-3 * clean_->dte.cwiseAbs().maxCoeff()) << "DTE differs by " << dmax << " m";
  IdentificationOptions o;
  const IdentificationResult r = identifyOrFail(ch.table, c, o);
  const auto err = segmentErrors(r, *clean_, c);
  ASSERT_EQ(err.size(), 10u);
  std::printf(
      "noise-free uniform: max |C error| %.3g %% (mesh offset %.3g, dte offset %.3g m, "
      "max DTE difference %.3g m)\n",
      100 * maxOf(err), ch.report.mesh_offset, ch.report.dte_offset, dmax);
  EXPECT_LT(maxOf(err), 5e-4);
}

TEST_F(EncoderChain, GivenOffsetsGiveTheSameResult) {
  const SimConfig& c = *config_;
  const SignalTable rig = gear_sim::rigRecord(c, encoder(0), *clean_);
  gd::EncoderFrontEndOptions o;
  o.mesh_offset = expectedMeshOffset(c, encoder(0));
  const Chain ch = frontEnd(rig, c, o);
  EXPECT_FALSE(ch.report.mesh_offset_estimated);
  const auto err = segmentErrors(identifyOrFail(ch.table, c, {}), *clean_, c);
  std::printf("given offsets: max |C error| %.3g %%\n", 100 * maxOf(err));
  EXPECT_LT(maxOf(err), 5e-4);
}

TEST_F(EncoderChain, RefusesWhatIsNotAGearPair) {
  const SimConfig& c = *config_;
  SignalTable rig = gear_sim::rigRecord(c, encoder(0), *clean_);
  SignalTable out;
  gd::EncoderFrontEndReport rep;
  std::string e;
  // Wrong ratio (a 2.2 reduction, as the Table 1 radii would suggest).
  SignalTable wrong = rig;
  wrong.theta2 *= 2.0 / 2.2;
  EXPECT_FALSE(gear_test::ok(gd::encoderToSignalTable(wrong, c.gearModel(), {}, &out, &rep), &e));
  EXPECT_NE(e.find("ratio"), std::string::npos) << e;
  // A reversal of the gear shaft halfway.
  SignalTable rev = rig;
  const Eigen::Index h = rig.size() / 2;
  for (Eigen::Index i = h; i < rig.size(); ++i) rev.theta2[i] = 2 * rig.theta2[h] - rig.theta2[i];
  e.clear();
  EXPECT_FALSE(gear_test::ok(gd::encoderToSignalTable(rev, c.gearModel(), {}, &out, &rep), &e));
  EXPECT_NE(e.find("backwards"), std::string::npos) << e;
  // An encoder counting against the rotation.
  SignalTable neg = rig;
  neg.theta1 = -rig.theta1;
  e.clear();
  EXPECT_FALSE(gear_test::ok(gd::encoderToSignalTable(neg, c.gearModel(), {}, &out, &rep), &e));
  EXPECT_NE(e.find("not a gear-pair record"), std::string::npos) << e;
  // Standing shafts.
  SignalTable still = rig;
  still.theta1.setConstant(1.0);
  still.theta2.setConstant(2.0);
  e.clear();
  EXPECT_FALSE(gear_test::ok(gd::encoderToSignalTable(still, c.gearModel(), {}, &out, &rep), &e));
  EXPECT_NE(e.find("rotate"), std::string::npos) << e;
}

TEST_F(EncoderChain, StreamingEqualsOffline) {
  const SimConfig& c = *config_;
  const SignalTable rig = gear_sim::rigRecord(c, encoder(1 << 20), *clean_);
  gd::EncoderFrontEndOptions o;
  o.mesh_offset = expectedMeshOffset(c, encoder(0));
  o.dte_offset = 1e-6;
  const Chain off = frontEnd(rig, c, o);
  o.calibration_samples = 500;
  gd::EncoderFrontEnd fe(c.gearModel(), o);
  std::string e;
  Eigen::VectorXd dte(rig.size());
  Eigen::Index got = 0;
  for (Eigen::Index s = 0; s < rig.size(); s += 777) {
    const Eigen::Index n = std::min<Eigen::Index>(777, rig.size() - s);
    ASSERT_TRUE(
        gear_test::ok(fe.push(1e6, static_cast<std::uint64_t>(s), rig.theta1.data() + s,
                              rig.theta2.data() + s, rig.torque.data() + s, static_cast<size_t>(n)),
                      &e))
        << e;
    SignalTable t;
    std::uint64_t first;
    while (fe.pop(&t, &first)) {
      ASSERT_EQ(static_cast<Eigen::Index>(first), got);
      dte.segment(got, t.size()) = t.dte;
      got += t.size();
    }
  }
  ASSERT_TRUE(gear_test::ok(fe.finish(), &e)) << e;
  SignalTable t;
  std::uint64_t first;
  while (fe.pop(&t, &first)) dte.segment(got, t.size()) = t.dte, got += t.size();
  ASSERT_EQ(got, rig.size());
  EXPECT_LT((dte - off.table.dte).cwiseAbs().maxCoeff(), 1e-15);
}

// Quantised encoders and torque noise: the reported SE must cover the error. Per seed: random
// encoder zeros (so the quantisation pattern differs) and torque noise; offsets estimated.
void coverage(long counts, int seeds, double torque_noise, double min_reported) {
  SimConfig c = table1Config();
  setPiecewiseTruth(&c, 1e-3);
  const SignalTable sim = simulateOrFail(c);
  std::mt19937_64 rng(counts);
  std::uniform_real_distribution<double> zero(0.0, 2 * M_PI);
  long inside = 0, total = 0;
  std::vector<double> z;
  double mesh_err = 0.0;
  for (int seed = 1; seed <= seeds; ++seed) {
    gear_sim::EncoderOptions enc = encoder(counts, static_cast<unsigned long>(seed));
    enc.zero1 = zero(rng);
    enc.zero2 = zero(rng);
    enc.torque_noise = torque_noise;
    const SignalTable rig = gear_sim::rigRecord(c, enc, sim);
    gd::EncoderFrontEndOptions o;
    o.counts_per_rev1 = o.counts_per_rev2 = counts;
    const Chain ch = frontEnd(rig, c, o);
    double du = std::abs(ch.report.mesh_offset - expectedMeshOffset(c, enc));
    mesh_err = std::max(mesh_err, std::min(du, 1.0 - du));
    const IdentificationResult r = identifyOrFail(ch.table, c, {});
    for (const auto& s : r.segments) {
      const double truth = trueC(sim, c, s.t_start, s.t_end);
      ++total;
      if (!s.identifiable) continue;
      z.push_back((s.C - truth) / s.C_std);
      if (std::abs(s.C - truth) <= 2.0 * s.C_std) ++inside;
    }
  }
  std::vector<double> az;
  for (double v : z) az.push_back(std::abs(v));
  // Coverage of the reported numbers: a segment flagged not identifiable (below the noise)
  // reports no C and no SE.
  const double frac = static_cast<double>(inside) / static_cast<double>(z.size());
  std::printf(
      "%ld counts/rev, torque noise %.3g N*m, %d seeds: %ld of %ld segments within 2 SE "
      "(%.1f %% of the %zu reported), median |error|/SE %.2f, max mesh offset error %.2g cycles, "
      "DTE "
      "quantisation noise %.3g m\n",
      counts, torque_noise, seeds, inside, total, 100.0 * frac, z.size(), median(az), mesh_err,
      gd::quantisationNoiseStd(c.gears, counts, counts));
  EXPECT_GE(frac, 0.9);
  EXPECT_GE(z.size(), min_reported * static_cast<double>(total));
}

// 16 bit: the DTE quantisation noise (3.2 um) exceeds the DTE's variation; about half of the
// segments are honestly flagged not identifiable (below noise).
TEST(EncoderNoise, Encoder16BitCoverage) { coverage(1L << 16, 30, 0.1, 0.3); }
TEST(EncoderNoise, Encoder20BitCoverage) { coverage(1L << 20, 30, 0.1, 0.95); }

// Edge times at 5000 counts/rev (exact, and on an 80 MHz counter clock) against uniform input.
TEST_F(EncoderChain, EdgeTimesGiveTheUniformC) {
  const SimConfig& c = *config_;
  const gear_sim::EncoderOptions enc = encoder(0);
  IdentificationOptions io;  // the same segments for both (the edge grid starts a few us later)
  io.t_start = 1e-4;
  io.t_end = 9.9e-3;
  const IdentificationResult uni =
      identifyOrFail(frontEnd(gear_sim::rigRecord(c, enc, *clean_), c).table, c, io);
  for (double clock : {0.0, 80e6}) {
    gear_sim::EncoderOptions e = enc;
    e.edge_clock = clock;
    const auto e1 = gear_sim::encoderEdges(c, e, *clean_, 1, 5000);
    const auto e2 = gear_sim::encoderEdges(c, e, *clean_, 2, 5000);
    ASSERT_GT(e1.size(), 100u);
    SignalTable rig;
    std::string res, err;
    ASSERT_TRUE(gear_test::ok(gd::edgesToRigTable(e1, 5000, e2, 5000, *clean_, &rig, &res), &err))
        << err;
    gd::EncoderFrontEndOptions o;
    const IdentificationResult r = identifyOrFail(frontEnd(rig, c, o).table, c, io);
    // Compare the segments that start at the same time (the edge grid starts a few us later).
    int compared = 0, within = 0;
    double worst = 0.0;
    for (const auto& s : r.segments)
      for (const auto& u : uni.segments)
        if (std::abs(s.t_end - u.t_end) < 2e-6 && s.identifiable) {
          ++compared;
          const double z = std::abs(s.C - u.C) / s.C_std;
          worst = std::max(worst, std::abs(s.C - u.C) / u.C);
          if (z <= 2.0) ++within;
        }
    std::printf(
        "edge times, 5000 counts/rev, clock %g Hz: %d of %d segments within 2 SE of the "
        "uniform C (largest difference %.3g %%)\n",
        clock, within, compared, 100 * worst);
    EXPECT_GE(compared, 8);
    EXPECT_GE(within, compared - 1);
  }
}

TEST(EncoderNoise, QuantisationModelMatchesTheMeasuredNoise) {
  SimConfig c = table1Config();
  c.simulation.duration = 0.002;
  const SignalTable sim = simulateOrFail(c);
  for (long counts : {1L << 16, 1L << 20}) {
    const SignalTable exact = gear_sim::rigRecord(c, encoder(0), sim);
    const SignalTable quant = gear_sim::rigRecord(c, encoder(counts), sim);
    gd::EncoderFrontEndOptions o;
    o.mesh_offset = 0.0;
    o.dte_offset = 0.0;
    o.counts_per_rev1 = o.counts_per_rev2 = counts;
    const Chain a = frontEnd(exact, c, o), b = frontEnd(quant, c, o);
    const Eigen::VectorXd d = b.table.dte - a.table.dte;
    const double sd = std::sqrt((d.array() - d.mean()).square().mean());
    std::printf("%ld counts/rev: DTE quantisation noise measured %.3g m, model %.3g m\n", counts,
                sd, b.report.quantisation_noise_std);
    EXPECT_NEAR(sd, b.report.quantisation_noise_std, 0.1 * b.report.quantisation_noise_std);
  }
}

}  // namespace

namespace {

std::string writeTemp(const std::string& name, const std::string& text) {
  const std::string path =
      (gear_test::processScratch("encoder_frontend_test") / ("rigfront_" + name)).string();
  std::FILE* f = std::fopen(path.c_str(), "w");
  std::fputs(text.c_str(), f);
  std::fclose(f);
  return path;
}

// Regression tests of the rig input path (fuzz/fuzz_rig.cpp covers it with libFuzzer): every
// hostile file is refused with a message naming the reason, never a crash or a number.
TEST(RigInputs, HostileFilesAreRefusedWithReasons) {
  gear_sim::SignalTable t, out;
  std::string e;
  EXPECT_FALSE(gear_test::ok(
      gear_sim::readRigCsv(writeTemp("dte.csv", "time,dte,theta1,theta2\n0,0,0,0\n1,0,1,1\n"), &t),
      &e));
  EXPECT_NE(e.find("not a rig record"), std::string::npos) << e;
  EXPECT_FALSE(gear_test::ok(
      gear_sim::readRigCsv(writeTemp("nan.csv", "time,theta1,theta2\n0,nan,0\n1,1,1\n"), &t), &e));
  EXPECT_FALSE(e.empty());
  EXPECT_FALSE(gear_test::ok(
      gear_sim::readRigCsv(writeTemp("time.csv", "time,theta1,theta2\n1,0,0\n0,1,1\n"), &t), &e));
  EXPECT_FALSE(e.empty());
  // Too short for the front end; a missing torque with offsets to estimate.
  ASSERT_TRUE(gear_test::ok(
      gear_sim::readRigCsv(
          writeTemp("short.csv", "time,theta1,theta2\n0,0,0\n1e-6,1e-3,5e-4\n2e-6,2e-3,1e-3\n"),
          &t),
      &e))
      << e;
  gear_sim::GearModel model;
  EXPECT_FALSE(gear_test::ok(gd::encoderToSignalTable(t, model, {}, &out, nullptr), &e));
  EXPECT_NE(e.find("16"), std::string::npos) << e;
  // Edge files: decreasing, a gap, too few edges, the grid outside.
  std::vector<double> edges;
  EXPECT_FALSE(gear_test::ok(
      gear_sim::readEdgeCsv(writeTemp("e1.csv", "time\n0\n2e-6\n1e-6\n"), &edges), &e));
  Eigen::VectorXd theta;
  EXPECT_FALSE(gear_test::ok(
      gd::edgeTimesToAngles({0, 1, 2}, 100, Eigen::VectorXd::LinSpaced(3, 0, 2), &theta), &e));
  EXPECT_NE(e.find("4 edges"), std::string::npos) << e;
  std::vector<double> gap;
  for (int k = 0; k < 40; ++k) gap.push_back(k);
  gap.push_back(5000.0);  // 125x the mean interval: a standstill or lost edges
  EXPECT_FALSE(gear_test::ok(
      gd::edgeTimesToAngles(gap, 100, Eigen::VectorXd::LinSpaced(3, 0, 2), &theta), &e));
  EXPECT_NE(e.find("gap"), std::string::npos) << e;
  EXPECT_FALSE(gear_test::ok(
      gd::edgeTimesToAngles({0, 1, 2, 3, 4}, 100, Eigen::VectorXd::LinSpaced(3, -1, 2), &theta),
      &e));
  EXPECT_NE(e.find("outside"), std::string::npos) << e;
  EXPECT_FALSE(gear_test::ok(
      gd::edgeTimesToAngles({0, 1, 2, 3}, 0, Eigen::VectorXd::LinSpaced(3, 0, 2), &theta), &e));
  // Cubic edges reproduce a cubic rotation exactly.
  std::vector<double> cubic;
  for (int k = 0; k < 50; ++k) cubic.push_back(0.01 * k + 1e-5 * k * k);
  ASSERT_TRUE(gear_test::ok(
      gd::edgeTimesToAngles(cubic, 1000, Eigen::VectorXd::LinSpaced(7, 0.0, 0.4), &theta), &e))
      << e;
  // Streaming: a sample index that goes back is refused.
  gd::EncoderFrontEndOptions o;
  o.mesh_offset = 0.0, o.dte_offset = 0.0, o.calibration_samples = 16;
  gd::EncoderFrontEnd fe(model, o);
  std::vector<double> a(20), b(20);
  for (int i = 0; i < 20; ++i) a[i] = 1e-3 * i, b[i] = 5e-4 * i;
  ASSERT_TRUE(gear_test::ok(fe.push(1e6, 0, a.data(), b.data(), nullptr, 20), &e)) << e;
  EXPECT_FALSE(gear_test::ok(fe.push(1e6, 5, a.data(), b.data(), nullptr, 20), &e));
  EXPECT_NE(e.find("not after"), std::string::npos) << e;
  EXPECT_FALSE(gear_test::ok(fe.push(2e6, 100, a.data(), b.data(), nullptr, 20), &e));
  EXPECT_NE(e.find("rate changed"), std::string::npos) << e;
}

}  // namespace
