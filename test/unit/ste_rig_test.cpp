// Issue 19 (rig part of the STE tests): encoder records (quantised angles, torque noise,
// estimated encoder offsets) through the front end and the joint C + STE identification, scored
// against the simulated truth over seeds. Split from ste_model_test so the two run in parallel.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>

#include "gear_damping_id/quality_flags.hpp"
#include "gear_damping_id/segment_driver.hpp"
#include "gear_damping_id/ste_model.hpp"
#include "id_test_support.hpp"
#include "rig_test_support.hpp"
#include "ste_rig_support.hpp"
#include "ste_test_support.hpp"

using namespace gear_ste_test;

namespace {

namespace gd = gear_damping_id;

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
