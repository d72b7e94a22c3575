// Shared by ste_model_test and ste_rig_test: a rig-like STE set on simulator configurations,
// the option sets, and the identification and scoring helpers of the STE tests.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <vector>

#include "gear_damping_id/ste_model.hpp"
#include "id_test_support.hpp"
#include "status_support.hpp"

namespace gear_ste_test {

using namespace gear_id_test;
using gear_damping_id::SteModelOptions;
using gear_damping_id::SteResult;

// A rig-like STE [m]: three mesh harmonics (profile errors, decaying), run-out of both shafts,
// and an encoder-zero offset. Scaled by `s` and rotated by `phi` to vary the spectrum.
inline void setSte(SimConfig* c, double s, double phi, gear_sim::SteDamping damping) {
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

inline SteModelOptions steOptions(const SimConfig& c, int mesh, int shaft) {
  SteModelOptions o;
  o.mesh_orders = mesh;
  o.pinion_orders = o.gear_orders = shaft;
  o.pinion_teeth = c.gears.pinion.teeth;
  o.gear_teeth = c.gears.gear.teeth;
  o.damping = c.ste.damping;
  return o;
}

inline IdentificationOptions idOptions(Formulation f = Formulation::Known) {
  IdentificationOptions o;
  o.formulation = f;
  o.refine = IdentificationOptions::Refine::Never;
  return o;
}

inline bool runSte(const SignalTable& t, const SimConfig& c, const IdentificationOptions& o,
                   const SteModelOptions& so, IdentificationResult* r, SteResult* s) {
  std::string e;
  const bool ok = gear_test::ok(gear_damping_id::identifyWithSte(
                                    t, gear_damping_id::gearConstants(c.gearModel()), o, so, r, s),
                                &e);
  EXPECT_TRUE(ok) << e;
  return ok;
}

// Relative error of each identified harmonic's complex amplitude (offset: of its value).
// Rig records: `offset_shift` [m] is added to the identified offset (the DTE offset the front end
// removed) and `du` [mesh cycles] is the front end's mesh phase minus the simulated one (an
// integer number of mesh cycles from the encoder zeros, plus any mesh-offset error): a term of
// order s of an angle advanced by phi = 2 pi s du / Z has the truth's complex amplitude
// (cos - i sin) rotated by -phi.
inline double maxSteError(const SteResult& s, const SimConfig& c, double offset_shift = 0.0,
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

inline std::vector<Case> cases() {
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
inline SimConfig withDuration(const Case& k, double duration) {
  SimConfig c = k.config;
  c.simulation.duration = duration;
  setPiecewiseTruth(&c, 1e-3);
  return c;
}

// Acceptance: noise-free, known stiffness, 3 mesh harmonics and run-out: C within 0.05 % per

}  // namespace gear_ste_test
