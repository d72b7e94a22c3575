// Issue 19 (STE part): the simulator's static transmission error and its joint identification
// with the damping (ste_model.hpp, docs/ste.md), scored against known simulated truth on several
// gears, speeds, STE spectra and seeds.
#include "gear_damping_id/ste_model.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <iostream>

#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_id/segment_driver.hpp"
#include "id_test_support.hpp"
#include "rig_test_support.hpp"

namespace {

using namespace gear_id_test;
using gear_damping_id::SteModelOptions;
using gear_damping_id::SteResult;

// A rig-like STE [m]: three mesh harmonics (profile errors, decaying), run-out of both shafts,
// and an encoder-zero offset. Scaled by `s` and rotated by `phi` to vary the spectrum.
void setSte(SimConfig* c, double s, double phi, gear_sim::SteDamping damping) {
  auto rot = [&](double a, double b, double* x, double* y) {
    *x = s * (a * std::cos(phi) - b * std::sin(phi));
    *y = s * (a * std::sin(phi) + b * std::cos(phi));
  };
  const double mesh[3][2] = {{1.0e-6, -0.4e-6}, {0.3e-6, 0.25e-6}, {-0.12e-6, 0.08e-6}};
  c->ste = {};
  for (auto& m : mesh) {
    double x, y;
    rot(m[0], m[1], &x, &y);
    c->ste.mesh_cos.push_back(x);
    c->ste.mesh_sin.push_back(y);
  }
  double x, y;
  rot(2.0e-6, 0.7e-6, &x, &y);  // pinion run-out
  c->ste.pinion_cos = {x};
  c->ste.pinion_sin = {y};
  rot(-0.8e-6, 1.5e-6, &x, &y);  // gear run-out
  c->ste.gear_cos = {x};
  c->ste.gear_sin = {y};
  c->ste.offset = 3e-6 * s;
  c->ste.damping = damping;
}

SteModelOptions steOptions(const SimConfig& c, int mesh, int shaft) {
  SteModelOptions o;
  o.mesh_orders = mesh;
  o.pinion_orders = o.gear_orders = shaft;
  o.pinion_teeth = c.gears.pinion.teeth;
  o.gear_teeth = c.gears.gear.teeth;
  o.damping = c.ste.damping;
  return o;
}

IdentificationOptions idOptions(Formulation f = Formulation::Known) {
  IdentificationOptions o;
  o.formulation = f;
  o.refine = IdentificationOptions::Refine::Never;
  return o;
}

bool runSte(const SignalTable& t, const SimConfig& c, const IdentificationOptions& o,
            const SteModelOptions& so, IdentificationResult* r, SteResult* s) {
  std::string e;
  const bool ok = gear_damping_id::identifyWithSte(t, gear_damping_id::gearConstants(c.gearModel()),
                                                   o, so, r, s, &e);
  EXPECT_TRUE(ok) << e;
  return ok;
}

// Relative error of each identified harmonic's complex amplitude (offset: of its value).
// Rig records: `offset_shift` [m] is added to the identified offset (the DTE offset the front end
// removed) and `du` [mesh cycles] is the front end's mesh phase minus the simulated one (an
// integer number of mesh cycles from the encoder zeros, plus any mesh-offset error): a term of
// order s of an angle advanced by phi = 2 pi s du / Z has the truth's complex amplitude
// (cos - i sin) rotated by -phi.
double maxSteError(const SteResult& s, const SimConfig& c, double offset_shift = 0.0,
                   double du = 0.0) {
  double worst = 0.0;
  for (const auto& t : s.terms) {
    std::complex<double> truth;
    const size_t k = static_cast<size_t>(t.order) - 1;
    double z = 1.0;  // teeth per revolution of the term's angle (mesh: 1 cycle per tooth)
    if (t.kind == "offset") truth = c.ste.offset;
    if (t.kind == "mesh" && k < c.ste.mesh_cos.size())
      truth = {c.ste.mesh_cos[k], c.ste.mesh_sin[k]};
    if (t.kind == "pinion" && k < c.ste.pinion_cos.size())
      truth = {c.ste.pinion_cos[k], c.ste.pinion_sin[k]}, z = c.gears.pinion.teeth;
    if (t.kind == "gear" && k < c.ste.gear_cos.size())
      truth = {c.ste.gear_cos[k], c.ste.gear_sin[k]}, z = c.gears.gear.teeth;
    std::complex<double> got(t.cos + (t.kind == "offset" ? offset_shift : 0.0), t.sin);
    if (t.kind != "offset") {
      const double phi = 2.0 * M_PI * t.order * du / z;
      truth = std::conj(std::conj(truth) * std::polar(1.0, -phi));
    }
    const double err = std::abs(got - truth) / std::abs(truth);
    worst = std::max(worst, err);
  }
  return worst;
}

struct Case {
  const char* name;
  SimConfig config;
};

std::vector<Case> cases() {
  std::vector<Case> v;
  SimConfig a = table1Config();
  setPiecewiseTruth(&a, 1e-3);
  setSte(&a, 1.0, 0.0, gear_sim::SteDamping::Relative);
  a.simulation.duration = 0.02;  // two gear revolutions: shaft orders resolved
  setPiecewiseTruth(&a, 1e-3);
  v.push_back({"table1 3000 rpm", a});
  SimConfig b = heldOutCase();
  setPiecewiseTruth(&b, 1e-3);
  setSte(&b, 0.6, 1.1, gear_sim::SteDamping::Relative);
  b.simulation.duration = 0.03;
  setPiecewiseTruth(&b, 1e-3);
  v.push_back({"held-out 23/37 2717 rpm", b});
  SimConfig d = heldOutCase();
  d.speed.pinion_rpm = 4100.0;
  setSte(&d, 1.7, -2.0, gear_sim::SteDamping::Dte);
  d.simulation.duration = 0.02;
  setPiecewiseTruth(&d, 1e-3);
  v.push_back({"held-out 4100 rpm, damping on y'", d});
  return v;
}

// A case's configuration over `duration` [s], the piecewise truth re-aligned to 1 ms segments.
SimConfig withDuration(const Case& k, double duration) {
  SimConfig c = k.config;
  c.simulation.duration = duration;
  setPiecewiseTruth(&c, 1e-3);
  return c;
}

// Acceptance: noise-free, known stiffness, 3 mesh harmonics and run-out: C within 0.05 % per
// 1 ms segment, STE coefficients within 0.1 %.
TEST(SteModel, NoiseFreeKnownStiffnessRecoversDampingAndSte) {
  for (const Case& k : cases()) {
    const SignalTable t = simulateOrFail(k.config);
    IdentificationResult r;
    SteResult s;
    ASSERT_TRUE(runSte(t, k.config, idOptions(), steOptions(k.config, 3, 1), &r, &s)) << k.name;
    const std::vector<double> err = segmentErrors(r, t, k.config);
    const double ste_err = maxSteError(s, k.config);
    for (size_t i = 0; i < err.size(); ++i) EXPECT_LT(err[i], 5e-4) << k.name << " segment " << i;
    EXPECT_LT(ste_err, 1e-3) << k.name;
    EXPECT_TRUE(s.separable) << k.name;
    std::cout << "[ measured ] " << k.name << ": max C error " << maxOf(err) << " over "
              << err.size() << " segments; max STE error " << ste_err << "; condition "
              << s.condition << ", max corr " << s.max_correlation << ", iterations "
              << s.iterations << "\n";
  }
}

// The output-error refinement with the STE in its forward model (forced on noise-free data):
// the same bars, for the known and greybox formulations, piecewise and constant damping.
TEST(SteModel, NoiseFreeRefinementKeepsDampingAndSte) {
  for (const Case& k : cases()) {
    const SimConfig c = withDuration(k, 0.01);
    const SignalTable t = simulateOrFail(c);
    for (Formulation f : {Formulation::Known, Formulation::Greybox}) {
      IdentificationOptions o = idOptions(f);
      o.refine = IdentificationOptions::Refine::Always;
      IdentificationResult r;
      SteResult s;
      ASSERT_TRUE(runSte(t, c, o, steOptions(c, 3, 1), &r, &s)) << k.name;
      EXPECT_TRUE(s.refined) << k.name;
      EXPECT_EQ(r.estimator, "output_error_ste") << k.name;
      const double c_err = maxOf(segmentErrors(r, t, c)), ste_err = maxSteError(s, c);
      EXPECT_LT(c_err, 5e-4) << k.name;
      EXPECT_LT(ste_err, 1e-3) << k.name;
      std::cout << "[ measured ] refined " << (f == Formulation::Known ? "known " : "greybox ")
                << k.name << ": max C error " << c_err << ", max STE error " << ste_err
                << ", iterations " << r.iterations << "\n";
    }
  }
}

}  // namespace

namespace {

// With measurement noise (white DTE noise at 40 dB SNR), C within 2x its reported standard error
// over 30 seeds in >= 90 % of the 1 ms segments with the default output-error refinement (the
// STE in its forward model). Measured beside it, not asserted: the same with 0.2 % white
// torque-meter noise (an input error, which the refinement's noise model - white or AR noise on
// the DTE - does not contain; the plain refinement without an STE loses coverage the same way),
// and the integral method alone (window-clustered sandwich standard errors).
double noisyCoverage(IdentificationOptions::Refine refine, double torque_rel, double* median_rel) {
  const std::vector<Case> all = cases();
  long inside = 0, total = 0;
  std::vector<double> rel;
  for (int seed = 1; seed <= 30; ++seed) {
    const Case& k = all[seed % all.size()];
    const SimConfig c = withDuration(k, 0.01);
    SignalTable t = simulateOrFail(c);
    addWhiteNoise(&t.dte, 40.0, 1000 + seed);
    std::mt19937_64 gen(5000 + seed);
    std::normal_distribution<double> nd(0.0, 1.0);
    const double torque_sigma = torque_rel * c.load.mean;
    for (Eigen::Index i = 0; i < t.size(); ++i) t.torque[i] += torque_sigma * nd(gen);
    IdentificationResult r;
    SteResult s;
    IdentificationOptions o = idOptions();
    o.refine = refine;
    EXPECT_TRUE(runSte(t, c, o, steOptions(c, 3, 1), &r, &s));
    for (const auto& e : r.segments) {
      const double truth = trueC(t, c, e.t_start, e.t_end);
      inside += std::abs(e.C - truth) <= 2.0 * e.C_std;
      ++total;
      rel.push_back(std::abs(e.C - truth) / truth);
    }
  }
  *median_rel = median(rel);
  return static_cast<double>(inside) / static_cast<double>(std::max<long>(total, 1));
}

// The STE in the segment pipeline (streamed and live runs): calibrated jointly on the first
// segments until they span a gear revolution (the shaft orders need it: 24-40 of the 50 1 ms
// segments here), then held; the held segments' standard errors include the STE's covariance.
// 40 dB DTE noise, 30 seeds over the three cases, default refinement: C within 2 SE.
TEST(SteModel, HeldSteSegmentsCoverTheTruth) {
  const std::vector<Case> all = cases();
  long inside = 0, total = 0, cal_inside = 0, cal_total = 0, identified = 0;
  std::vector<double> rel;
  std::string why;  // the first reason a segment was not identified
  for (int seed = 1; seed <= 30; ++seed) {
    const Case& k = all[seed % all.size()];
    const SimConfig c = withDuration(k, 0.05);
    SignalTable t = simulateOrFail(c);
    addWhiteNoise(&t.dte, 40.0, 1000 + seed);
    IdentificationOptions o = idOptions();
    o.refine = IdentificationOptions::Refine::Auto;
    const gear_damping_id::SignalView v = gear_damping_id::SignalView::of(t);
    o.window_length =
        gear_damping_id::defaultWindowLength(v, gear_damping_id::gearConstants(c.gearModel()));
    const gear_damping_id::SampleRanges ranges = gear_damping_id::segmentRanges(v, o);
    gear_damping_id::SegmentDriver d(o, gear_damping_id::gearConstants(c.gearModel()));
    ASSERT_EQ(d.setSte(steOptions(c, 3, 1), 3), "");
    // The calibration: at least 3 segments, until the mesh phase spans Z2 cycles.
    size_t n_cal = 0;
    while (n_cal < ranges.size() && (n_cal < 3 || t.mesh_phase[ranges[n_cal - 1].second - 1] -
                                                          t.mesh_phase[ranges[0].first] <
                                                      c.gears.gear.teeth))
      ++n_cal;
    long pending = 0;
    for (const auto& rg : ranges) {
      const auto out = d.add(v, rg.first, rg.second);
      pending += !out.estimate.identifiable &&
                 out.estimate.reason.find("awaiting the STE calibration") != std::string::npos;
    }
    EXPECT_EQ(pending, static_cast<long>(n_cal) - 1) << "the last calibration segment returns "
                                                        "estimates";
    ASSERT_NE(d.steResult(), nullptr);
    const IdentificationResult r = d.finish();
    ASSERT_EQ(r.segments.size(), 50u);
    for (size_t i = 0; i < r.segments.size(); ++i) {
      const auto& e = r.segments[i];
      if (!e.identifiable) {
        if (why.empty()) why = e.reason;
        continue;
      }
      ++identified;
      const double truth = trueC(t, c, e.t_start, e.t_end);
      const bool in = std::abs(e.C - truth) <= 2.0 * e.C_std;
      if (i < n_cal) {
        cal_inside += in;
        ++cal_total;
        continue;
      }
      inside += in;
      ++total;
      rel.push_back(std::abs(e.C - truth) / truth);
    }
  }
  const double cover = static_cast<double>(inside) / static_cast<double>(std::max<long>(total, 1));
  std::cout << "[ measured ] held STE (calibrated over a gear revolution of 50 ms), 40 dB, 30 "
               "seeds: "
            << identified << " of 1500 segments identified; held segments within 2 SE "
            << 100.0 * cover << " % of " << total << " (median |error| " << 100.0 * median(rel)
            << " %); calibration segments " << 100.0 * cal_inside / std::max<long>(cal_total, 1)
            << " % of " << cal_total << "\n";
  EXPECT_EQ(identified, 1500) << why;
  EXPECT_GE(cover, 0.9);
}

TEST(SteModel, NoisyStandardErrorsCoverTheTruth) {
  using R = IdentificationOptions::Refine;
  double med = 0.0, med_tq = 0.0, med_int = 0.0;
  const double refined = noisyCoverage(R::Auto, 0.0, &med);
  const double refined_tq = noisyCoverage(R::Auto, 2e-3, &med_tq);
  const double integral_tq = noisyCoverage(R::Never, 2e-3, &med_int);
  std::cout << "[ measured ] 40 dB DTE noise, 30 seeds x 10 segments, C within 2 SE: refined "
            << 100.0 * refined << " % (median |error| " << 100.0 * med
            << " %); + 0.2 % torque noise: refined " << 100.0 * refined_tq << " % (median "
            << 100.0 * med_tq << " %), integral method alone " << 100.0 * integral_tq
            << " % (median " << 100.0 * med_int << " %)\n";
  EXPECT_GE(refined, 0.9);
}

}  // namespace

namespace {

// Acceptance: ignoring the STE on data that contain it gives a visible bias or flag; modelling
// it removes both.
TEST(SteModel, IgnoringTheSteBiasesOrFlagsModellingItDoesNot) {
  for (const Case& k : cases()) {
    const SimConfig c = withDuration(k, 0.01);
    const SignalTable t = simulateOrFail(c);
    IdentificationOptions o;
    o.formulation = Formulation::Known;
    const IdentificationResult plain = identifyOrFail(t, c, o);
    double plain_err = 0.0;
    long flagged = 0;
    for (const auto& s : plain.segments) {
      flagged += !s.warnings.empty() || !s.identifiable;
      const double truth = trueC(t, c, s.t_start, s.t_end);
      plain_err = std::max(plain_err, s.identifiable ? std::abs(s.C - truth) / truth : 0.0);
    }
    // visible: a bias far beyond the noise-free bar, or flags on the segments
    EXPECT_TRUE(plain_err > 0.05 || flagged == static_cast<long>(plain.segments.size())) << k.name;
    IdentificationResult r;
    SteResult s;
    ASSERT_TRUE(runSte(t, c, idOptions(), steOptions(c, 3, 1), &r, &s));
    const double ste_err = maxOf(segmentErrors(r, t, c));
    long ste_flagged = 0;
    for (const auto& e : r.segments) ste_flagged += !e.warnings.empty();
    EXPECT_LT(ste_err, 5e-4) << k.name;
    EXPECT_EQ(ste_flagged, 0) << k.name;
    EXPECT_TRUE(r.warnings.empty()) << k.name << ": " << gear_damping_id::joinCodes(r.warnings)
                                    << " " << (r.warnings.empty() ? "" : r.warnings[0].text);
    std::cout << "[ measured ] " << k.name << ": STE ignored: max C error " << 100 * plain_err
              << " %, " << flagged << "/" << plain.segments.size()
              << " segments flagged or not identifiable; STE modelled: max C error "
              << 100 * ste_err << " %, " << ste_flagged << " flagged\n";
  }
}

// greybox (stiffness levels unknown too): C, the levels and the STE from the same record, and the
// separability check.
TEST(SteModel, GreyboxIdentifiesDampingStiffnessAndSte) {
  for (const Case& k : cases()) {
    const SimConfig c = withDuration(k, 0.02);
    const SignalTable t = simulateOrFail(c);
    IdentificationResult r;
    SteResult s;
    ASSERT_TRUE(runSte(t, c, idOptions(Formulation::Greybox), steOptions(c, 3, 1), &r, &s));
    const double c_err = maxOf(segmentErrors(r, t, c));
    double k_err = 0.0;
    for (const auto& e : r.segments)
      k_err = std::max({k_err, std::abs(e.k_min - c.mesh.k_min) / c.mesh.k_min,
                        std::abs(e.k_max - c.mesh.k_max) / c.mesh.k_max});
    const double ste_err = maxSteError(s, c);
    std::cout << "[ measured ] greybox " << k.name << ": max C error " << 100 * c_err
              << " %, max k error " << 100 * k_err << " %, max STE error " << 100 * ste_err
              << " %, condition " << s.condition << ", max corr " << s.max_correlation
              << ", separable " << s.separable << ", iterations " << s.iterations << "\n";
    EXPECT_LT(c_err, 1e-3) << k.name;
    EXPECT_LT(k_err, 1e-4) << k.name;
    EXPECT_LT(ste_err, 1e-3) << k.name;
    EXPECT_TRUE(s.separable) << k.name;
  }
}

// A record too short to tell the shaft orders from the offset (a fraction of a gear revolution)
// is flagged ste_not_separable, never reported as clean.
TEST(SteModel, ShortRecordFlagsNotSeparable) {
  SimConfig c = cases()[0].config;
  c.simulation.duration = 0.002;  // 1/10 of a gear revolution
  setPiecewiseTruth(&c, 1e-3);
  const SignalTable t = simulateOrFail(c);
  IdentificationResult r;
  SteResult s;
  ASSERT_TRUE(runSte(t, c, idOptions(), steOptions(c, 3, 2), &r, &s));
  EXPECT_FALSE(s.separable) << "condition " << s.condition << " corr " << s.max_correlation;
  EXPECT_TRUE(
      gear_damping_id::hasCode(r.warnings, gear_damping_id::quality_code::kSteNotSeparable));
}

}  // namespace

namespace {

namespace gd = gear_damping_id;

// A rig record of case `k` (its STE in the simulation) through the encoder front end.
struct RigRun {
  SignalTable table;
  gd::EncoderFrontEndReport report;
  double du = 0.0;  // front-end mesh phase minus the simulated one [mesh cycles]
};
RigRun rigRun(const SimConfig& c, const SignalTable& sim, const gear_sim::EncoderOptions& enc,
              const gd::EncoderFrontEndOptions& fo) {
  RigRun r;
  const SignalTable rig = gear_sim::rigRecord(c, enc, sim);
  std::string e;
  EXPECT_TRUE(gd::encoderToSignalTable(rig, c.gearModel(), fo, &r.table, &r.report, &e)) << e;
  if (r.table.size() > 0) r.du = r.table.mesh_phase[0] - sim.mesh_phase[0];
  return r;
}

// Acceptance, noise-free encoder input (uniform samples, no quantisation), known stiffness, STE
// with 3 mesh harmonics and a run-out of each shaft: C within 0.05 % per 1 ms segment and the STE
// coefficients within 0.1 %, on the three cases (two gear pairs, three speeds, three STE
// spectra, both damping forms) and two encoder-zero pairs each. The mesh offset is given (a
// once-per-revolution pulse); the DTE offset is estimated (it is the STE's order-0 term). The
// estimated mesh offset is reported.
TEST(SteRig, NoiseFreeEncodersRecoverDampingAndSte) {
  for (const Case& k : cases()) {
    const SignalTable sim = simulateOrFail(k.config);
    for (int z = 0; z < 2; ++z) {
      gear_sim::EncoderOptions enc = encoder(0);
      enc.zero1 += 2.1 * z, enc.zero2 -= 0.9 * z;
      gd::EncoderFrontEndOptions fo;
      fo.mesh_offset = expectedMeshOffset(k.config, enc);
      const RigRun rr = rigRun(k.config, sim, enc, fo);
      IdentificationResult r;
      SteResult s;
      ASSERT_TRUE(runSte(rr.table, k.config, idOptions(), steOptions(k.config, 3, 1), &r, &s));
      const std::vector<double> err = segmentErrors(r, sim, k.config);
      // The raw DTE's constant from the encoder zeros is a1 zero1 + a2 zero2; the front end
      // removed y0 = that constant + whatever of the STE offset its force balance absorbed.
      const gd::DteCoefficients dc = gd::dteCoefficients(k.config.gears);
      const double shift = rr.report.dte_offset - (dc.a1 * enc.zero1 + dc.a2 * enc.zero2);
      const double ste_err = maxSteError(s, k.config, shift, rr.du);
      for (size_t i = 0; i < err.size(); ++i)
        EXPECT_LT(err[i], 5e-4) << k.name << " zeros " << z << " segment " << i;
      EXPECT_LT(ste_err, 1e-3) << k.name << " zeros " << z;
      // The mesh offset estimated with the STE modelled. (Ignoring the STE, the plain estimate
      // is 0.027, 0.0034 and 0.036 cycles off on these cases: docs/rig.md.)
      if (z == 0) {
        gd::EncoderFrontEndOptions eo;
        eo.model_ste = true;
        eo.ste = steOptions(k.config, 3, 1);
        const RigRun est = rigRun(k.config, sim, enc, eo);
        double off = std::abs(est.report.mesh_offset - fo.mesh_offset);
        off = std::min(off, 1.0 - off);
        EXPECT_LT(off, 2e-3) << k.name;  // two samples' phase advance (1e-3 cycles each)
        IdentificationResult re;
        SteResult se;
        ASSERT_TRUE(runSte(est.table, k.config, idOptions(), steOptions(k.config, 3, 1), &re, &se));
        const double c_est = maxOf(segmentErrors(re, sim, k.config));
        EXPECT_LT(c_est, 5e-4) << k.name;
        std::cout << "[ measured ] rig " << k.name
                  << ", mesh offset estimated with the STE: " << off << " cycles off; max C error "
                  << c_est << "\n";
      }
      std::cout << "[ measured ] rig " << k.name << " zeros " << z << ": max C error " << maxOf(err)
                << " over " << err.size() << " segments; max STE error " << ste_err << "\n";
    }
  }
}

// Acceptance, quantised encoders (16 and 20 bit) and torque-meter noise (white, 0.1 % of the
// mean load: 0.1 N*m on the 100 N*m Table 1 case, 0.08 N*m on the 80 N*m held-out pair), STE
// modelled (3 mesh harmonics, run-out), offsets estimated, default refinement (output error):
// C within 2x its reported SE in >= 90 % of the reported segments over 30 seeds (the cases
// rotate with the seed; each seed draws new encoder zeros and torque noise). Segments flagged
// below the noise report no C and are counted apart.
struct Coverage {
  long inside = 0, reported = 0, total = 0;
  std::vector<double> z;
};
Coverage steCoverage(long counts, int seeds, bool given_mesh_offset,
                     IdentificationOptions::Refine refine = IdentificationOptions::Refine::Auto) {
  const std::vector<Case> all = cases();
  std::vector<SimConfig> configs;
  std::vector<SignalTable> sims;
  for (const Case& k : all) {
    configs.push_back(withDuration(k, 0.01));
    sims.push_back(simulateOrFail(configs.back()));
  }
  std::mt19937_64 rng(counts + 19);
  std::uniform_real_distribution<double> zero(0.0, 2 * M_PI);
  Coverage cv;
  for (int seed = 1; seed <= seeds; ++seed) {
    const size_t ci = static_cast<size_t>(seed) % all.size();
    const SimConfig& c = configs[ci];
    gear_sim::EncoderOptions enc = encoder(counts, static_cast<unsigned long>(seed));
    enc.zero1 = zero(rng);
    enc.zero2 = zero(rng);
    enc.torque_noise = 1e-3 * c.load.mean;
    gd::EncoderFrontEndOptions fo;
    fo.counts_per_rev1 = fo.counts_per_rev2 = counts;
    if (given_mesh_offset) fo.mesh_offset = expectedMeshOffset(c, enc);
    fo.model_ste = true;
    fo.ste = steOptions(c, 3, 1);
    const RigRun rr = rigRun(c, sims[ci], enc, fo);
    IdentificationOptions o;  // default: refinement when the data are noisy
    o.formulation = Formulation::Known;
    o.refine = refine;
    IdentificationResult r;
    SteResult s;
    if (!runSte(rr.table, c, o, steOptions(c, 3, 1), &r, &s)) continue;
    for (const auto& e : r.segments) {
      ++cv.total;
      if (!e.identifiable) continue;
      const double truth = trueC(sims[ci], c, e.t_start, e.t_end);
      ++cv.reported;
      cv.inside += std::abs(e.C - truth) <= 2.0 * e.C_std;
      cv.z.push_back(std::abs(e.C - truth) / e.C_std);
    }
  }
  std::cout << "[ measured ] STE rig, " << counts << " counts/rev, torque noise 0.1 % of the load, "
            << seeds << " seeds, mesh offset " << (given_mesh_offset ? "given" : "estimated")
            << (refine == IdentificationOptions::Refine::Never ? ", integral method alone" : "")
            << ": " << cv.inside << " of " << cv.reported << " reported segments within 2 SE ("
            << 100.0 * cv.inside / std::max<long>(cv.reported, 1) << " %), " << cv.reported
            << " of " << cv.total << " reported, median |error|/SE " << median(cv.z) << "\n";
  return cv;
}

TEST(SteRig, Encoder20BitCoverage) {
  // (The integral method alone covers 79.7 % here: docs/rig.md. Not re-measured in every run.)
  const Coverage cv = steCoverage(1L << 20, 30, false);
  EXPECT_GE(cv.inside, 0.9 * cv.reported);
  EXPECT_GE(cv.reported, cv.total * 9 / 10);
}

TEST(SteRig, Encoder16BitCoverage) {
  const Coverage cv = steCoverage(1L << 16, 30, false);
  EXPECT_GE(cv.inside, 0.9 * cv.reported);
  // Measured: 245 of 300 reported with the offsets estimated (300 with the mesh offset given);
  // the rest are flagged, not wrong. Guards that level.
  EXPECT_GE(cv.reported, cv.total * 3 / 4);
}

}  // namespace
