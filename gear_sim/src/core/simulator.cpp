#include "gear_sim/simulator.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "gear_sim/models.hpp"

namespace gear_sim {

double naturalFrequencyHz(const GearPair& gears, const MeshOptions& mesh) {
  return std::sqrt(MeshStiffness(mesh).mean() / gears.equivalentMass()) / (2.0 * M_PI);
}

double addNoise(Eigen::VectorXd* y, double snr_db, unsigned long seed) {
  if (!std::isfinite(snr_db) || y->size() == 0) return 0.0;
  const double mean = y->mean();
  const double std_y = std::sqrt((y->array() - mean).square().mean());
  const double sigma = std_y / std::pow(10.0, snr_db / 20.0);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, sigma);
  for (Eigen::Index i = 0; i < y->size(); ++i) (*y)[i] += n(rng);
  return sigma;
}

namespace {

// A sampled value "holds from that sample's instant on": look it up just after the instant, so
// a switch that falls on a sample (to rounding) is seen there. 1e-9 mesh cycles is ~1 ps.
constexpr double kPhaseNudge = 1e-9;  // [mesh cycles]

void resize(Eigen::VectorXd& v, Eigen::Index n) {
  if (v.size() != n) v.resize(n);
}

// Physical model evaluated at (t, t_ref): everything the integrators need.
struct Model {
  MeshStiffness stiffness;
  MeshTiming timing;
  LoadTorque load;
  DampingLaw damping;
  double me, ff;

  double k(double t, double t_ref) const {
    return stiffness.at(timing.phase(t), timing.phase(t_ref));
  }
  SdofCoefficients sdof(double t, double t_ref) const {
    const double t1 = load.at(t);
    return {damping.at(t_ref, t1) / me, k(t, t_ref) / me, ff * t1};
  }
};

// Two-DOF torsional model, eq. (1): state (theta1, theta2, omega1, omega2).
struct Torsional {
  double th1, th2, w1, w2;
};

Torsional torsionalRate(const Torsional& s, double c, double k, double t1, const GearPair& g) {
  const double r1 = g.pinion.base_radius, r2 = g.gear.base_radius;
  const double f = c * (r1 * s.w1 - r2 * s.w2) + k * (r1 * s.th1 - r2 * s.th2);  // mesh force [N]
  return {s.w1, s.w2, (t1 - r1 * f) / g.pinion.inertia, (-t1 + r2 * f) / g.gear.inertia};
}

Torsional axpy(const Torsional& s, double h, const Torsional& d) {
  return {s.th1 + h * d.th1, s.th2 + h * d.th2, s.w1 + h * d.w1, s.w2 + h * d.w2};
}

}  // namespace

bool simulate(const SimConfig& cfg, SignalTable* out, std::string* error) {
  if (std::string e = cfg.validate(); !e.empty()) {
    if (error) *error = e;
    return false;
  }
  const SimulationOptions& so = cfg.simulation;
  const Eigen::Index n_samples = std::llround(so.duration * so.sample_rate);
  const double fs = so.sample_rate, dt = 1.0 / fs;
  const double t_last = static_cast<double>(n_samples - 1) / fs;

  LoadTorque load(cfg.load);
  const double t1_mean = load.mean(so.duration);
  if (cfg.damping.model == DampingModel::LoadDependent && !(std::abs(t1_mean) > 0.0)) {
    if (error)
      *error = "damping.model = load_dependent: needs a non-zero time-mean load (load.* gives 0)";
    return false;
  }
  const MeshStiffness stiffness(cfg.mesh);
  const double me = cfg.gears.equivalentMass();
  const Model model{
      stiffness, MeshTiming(cfg.speed, cfg.gears.pinion.teeth, cfg.mesh.initial_phase),
      load,      DampingLaw(cfg.damping, stiffness.mean(), me, t1_mean),
      me,        cfg.gears.forceFactor()};

  // Every instant where a coefficient jumps or kinks: stiffness switches (from the mesh
  // phase's closed-form inverse), load kinks/steps, damping segment starts.
  std::vector<double> bps = model.load.breakpoints(t_last);
  for (double t : model.damping.breakpoints(t_last)) bps.push_back(t);
  const double u_first = model.timing.phase(0.0), u_last = model.timing.phase(t_last);
  if (!stiffness.cycleBreakpoints().empty()) {
    for (double cycle = std::floor(u_first); cycle <= std::ceil(u_last); cycle += 1.0)
      for (double b : stiffness.cycleBreakpoints()) {
        const double u = cycle + b;
        if (u > u_first && u < u_last) bps.push_back(model.timing.timeOfPhase(u));
      }
  }
  std::sort(bps.begin(), bps.end());

  SignalTable& o = *out;
  for (Eigen::VectorXd* c : {&o.time, &o.dte, &o.dte_velocity, &o.stiffness, &o.torque,
                             &o.mesh_state, &o.mesh_phase, &o.damping})
    resize(*c, n_samples);
  const bool torsional = so.dynamics == DynamicsModel::Torsional;
  if (torsional) {
    resize(o.theta1, n_samples);
    resize(o.theta2, n_samples);
  } else {
    o.theta1.resize(0);
    o.theta2.resize(0);
  }

  // Sampled columns (value holding from each sample's instant on).
  model.load.fillUniform(0.0, dt, n_samples, o.torque.data());
  for (Eigen::Index n = 0; n < n_samples; ++n) {
    const double t = static_cast<double>(n) / fs;
    const double u = model.timing.phase(t);
    o.time[n] = t;
    o.mesh_phase[n] = u;
    o.stiffness[n] = stiffness.at(u + kPhaseNudge);
    o.mesh_state[n] = stiffness.state(u + kPhaseNudge);
    o.damping[n] = model.damping.at(t + 1e-6 * dt, o.torque[n]);
  }

  const int m = so.substeps;
  auto bp = bps.cbegin();
  const auto bp_end = bps.cend();
  auto coeffs = [&model](double t, double t_ref) { return model.sdof(t, t_ref); };

  if (torsional) {
    const GearPair& g = cfg.gears;
    // y(0) = R1 theta1 - R2 theta2, y'(0) likewise: put the initial DTE on the pinion.
    Torsional s{so.initial_dte / g.pinion.base_radius, 0.0,
                so.initial_velocity / g.pinion.base_radius, 0.0};
    auto write = [&](Eigen::Index n) {
      o.theta1[n] = s.th1;
      o.theta2[n] = s.th2;
      o.dte[n] = g.pinion.base_radius * s.th1 - g.gear.base_radius * s.th2;
      o.dte_velocity[n] = g.pinion.base_radius * s.w1 - g.gear.base_radius * s.w2;
    };
    write(0);
    for (Eigen::Index n = 0; n + 1 < n_samples; ++n) {
      forEachStep(o.time[n], o.time[n + 1], m, bp, bp_end, [&](double a, double e, double mid) {
        const double h = e - a;
        auto rate = [&](const Torsional& x, double t) {
          const double t1 = model.load.at(t);
          return torsionalRate(x, model.damping.at(mid, t1), model.k(t, mid), t1, g);
        };
        if (so.integrator == Integrator::RK4) {
          const Torsional k1 = rate(s, a), k2 = rate(axpy(s, 0.5 * h, k1), mid),
                          k3 = rate(axpy(s, 0.5 * h, k2), mid), k4 = rate(axpy(s, h, k3), e);
          s = {s.th1 + h / 6 * (k1.th1 + 2 * k2.th1 + 2 * k3.th1 + k4.th1),
               s.th2 + h / 6 * (k1.th2 + 2 * k2.th2 + 2 * k3.th2 + k4.th2),
               s.w1 + h / 6 * (k1.w1 + 2 * k2.w1 + 2 * k3.w1 + k4.w1),
               s.w2 + h / 6 * (k1.w2 + 2 * k2.w2 + 2 * k3.w2 + k4.w2)};
        } else {
          const Torsional k1 = rate(s, a), k2 = rate(axpy(s, 0.5 * h, k1), mid);
          s = axpy(s, h, k2);
        }
      });
      write(n + 1);
    }
  } else if (!stiffness.piecewiseConstant()) {
    // Smooth or kinked stiffness: the generic driver evaluates K at every stage.
    std::string e =
        integrateSdof(coeffs, bps, 0.0, dt, n_samples, {so.initial_dte, so.initial_velocity},
                      so.integrator, m, o.dte.data(), o.dte_velocity.data());
    if (!e.empty()) {
      if (error) *error = e;
      return false;
    }
  } else {
    // Fast path (the default case): K, and the damping law's (a, b), are constant between
    // breakpoints; the load on the half-step grid comes in blocks from fillUniform (phasor
    // recurrence for the sine, no sin() per stage). Intervals containing a breakpoint take
    // the generic split path.
    constexpr Eigen::Index kBlock = 2048;
    const double h = dt / m;
    std::vector<double> T(static_cast<size_t>(2 * m * kBlock + 1));
    SdofState s{so.initial_dte, so.initial_velocity};
    o.dte[0] = s.y;
    o.dte_velocity[0] = s.v;
    bool dirty = true;
    double K = 0.0, ca = 0.0, cb = 0.0;
    const double ff = model.ff, inv_me = 1.0 / me;
    for (Eigen::Index n0 = 0; n0 + 1 < n_samples; n0 += kBlock) {
      const Eigen::Index n1 = std::min(n_samples - 1, n0 + kBlock);
      model.load.fillUniform(o.time[n0], 0.5 * h, 2 * m * (n1 - n0) + 1, T.data());
      for (Eigen::Index n = n0; n < n1; ++n) {
        const double ta = o.time[n], tb = o.time[n + 1];
        while (bp != bp_end && *bp <= ta) {
          ++bp;
          dirty = true;
        }
        if (bp != bp_end && *bp < tb) {
          s = advanceSdof(coeffs, s, ta, tb, m, bp, bp_end, so.integrator);
          dirty = true;
        } else {
          if (dirty) {
            const double mid = ta + 0.5 * dt;
            K = model.k(mid, mid) * inv_me;
            model.damping.coefficients(mid, &ca, &cb);
            ca *= inv_me;
            cb *= inv_me;
            dirty = false;
          }
          const double* Tn = T.data() + 2 * m * (n - n0);
          for (int j = 0; j < m; ++j) {
            const double t0 = Tn[2 * j], tm = Tn[2 * j + 1], t1 = Tn[2 * j + 2];
            const SdofCoefficients c0{ca + cb * t0, K, ff * t0}, cm{ca + cb * tm, K, ff * tm};
            if (so.integrator == Integrator::RK4) {
              s = rk4Step(s, h, c0, cm, {ca + cb * t1, K, ff * t1});
            } else {
              s = rk2Step(s, h, c0, cm);
            }
          }
        }
        o.dte[n + 1] = s.y;
        o.dte_velocity[n + 1] = s.v;
      }
    }
  }

  if (std::isfinite(so.noise_snr_db)) addNoise(&o.dte, so.noise_snr_db, so.seed);
  return true;
}

}  // namespace gear_sim
