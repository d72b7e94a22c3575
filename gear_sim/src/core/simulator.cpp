#include "gear_sim/simulator.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "gear_sim/message_text.hpp"
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
// [m] A DTE beyond a metre is a diverged integration, not a gear (they deflect micrometres).
constexpr double kMaxFiniteDte = 1.0;

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
  const StaticTransmissionError* ste = nullptr;  // docs/ste.md; null or inactive: none
  bool ste_relative = true;                      // damping on y' - e' (else on y')

  double k(double t, double t_ref) const {
    return stiffness.at(timing.phase(t), timing.phase(t_ref));
  }
  SdofCoefficients sdof(double t, double t_ref) const {
    const double t1 = load.at(t);
    SdofCoefficients c{damping.at(t_ref, t1) / me, k(t, t_ref) / me, ff * t1};
    if (ste) c.F += steForcing(t, c.C, c.K);
    return c;
  }
  // The STE as a known forcing of eq. (4): K e + C e' (relative damping) or K e.
  double steForcing(double t, double C, double K) const {
    const double u = timing.phase(t);
    double f = K * ste->value(u);
    if (ste_relative) f += C * ste->derivative(u) * timing.meshFrequency(t);
    return f;
  }
  // The STE's displacement and rate [m, m/s] at t (torsional model).
  void steAt(double t, double* e, double* e_dot) const {
    *e = *e_dot = 0.0;
    if (!ste) return;
    const double u = timing.phase(t);
    *e = ste->value(u);
    if (ste_relative) *e_dot = ste->derivative(u) * timing.meshFrequency(t);
  }
};

// Two-DOF torsional model, eq. (1): state (theta1, theta2, omega1, omega2).
struct Torsional {
  double th1, th2, w1, w2;
};

Torsional torsionalRate(const Torsional& s, double c, double k, double t1, const GearPair& g,
                        double e = 0.0, double e_dot = 0.0) {
  const double r1 = g.pinion.base_radius, r2 = g.gear.base_radius;
  // mesh force [N]; e, e_dot: the static transmission error and its rate (docs/ste.md)
  const double f = c * (r1 * s.w1 - r2 * s.w2 - e_dot) + k * (r1 * s.th1 - r2 * s.th2 - e);
  return {s.w1, s.w2, (t1 - r1 * f) / g.pinion.inertia, (-t1 + r2 * f) / g.gear.inertia};
}

Torsional axpy(const Torsional& s, double h, const Torsional& d) {
  return {s.th1 + h * d.th1, s.th2 + h * d.th2, s.w1 + h * d.w1, s.w2 + h * d.w2};
}

// One output interval of the linear eq. (4) as an affine map of the state:
// (y, v)' = [m11 m12; m21 m22] (y, v) + (g1, g2). `split` marks an interval that contains a
// breakpoint (integrated by the generic driver instead).
struct AffineStep {
  double m11 = 1, m12 = 0, m21 = 0, m22 = 1, g1 = 0, g2 = 0;
};

// The affine map of `substeps` RK steps of length h with K constant, C = ca + cb*T and
// F = ff*T at the stage loads T[0], T[1], ... (half-step grid). Built by applying the RK step
// itself to the basis states (no forcing) and to the zero state (with forcing).
inline AffineStep affineStep(Integrator method, double h, int substeps, double K, double ca,
                             double cb, double ff, const double* T) {
  AffineStep a;
  for (int j = 0; j < substeps; ++j) {
    const double t0 = T[2 * j], tm = T[2 * j + 1], t1 = T[2 * j + 2];
    const SdofCoefficients c0{ca + cb * t0, K, 0.0}, cm{ca + cb * tm, K, 0.0},
        c1{ca + cb * t1, K, 0.0};
    const SdofCoefficients f0{c0.C, K, ff * t0}, fm{cm.C, K, ff * tm}, f1{c1.C, K, ff * t1};
    SdofState e1, e2, g;
    if (method == Integrator::RK4) {
      e1 = rk4Step({1.0, 0.0}, h, c0, cm, c1);
      e2 = rk4Step({0.0, 1.0}, h, c0, cm, c1);
      g = rk4Step({0.0, 0.0}, h, f0, fm, f1);
    } else {
      e1 = rk2Step({1.0, 0.0}, h, c0, cm);
      e2 = rk2Step({0.0, 1.0}, h, c0, cm);
      g = rk2Step({0.0, 0.0}, h, f0, fm);
    }
    // Compose with what came before: new = E (old), E = [e1 e2], plus g.
    const AffineStep p = a;
    a.m11 = e1.y * p.m11 + e2.y * p.m21;
    a.m12 = e1.y * p.m12 + e2.y * p.m22;
    a.m21 = e1.v * p.m11 + e2.v * p.m21;
    a.m22 = e1.v * p.m12 + e2.v * p.m22;
    a.g1 = e1.y * p.g1 + e2.y * p.g2 + g.y;
    a.g2 = e1.v * p.g1 + e2.v * p.g2 + g.v;
  }
  return a;
}

// Closed form of affineStep for one RK4 step (derived symbolically from rk4Step and checked
// against it in the tests through the fast-path/generic agreement): with a = h C0, b = h Cm,
// c = h C1, k = h^2 K and the stage loads, for i in [0, n). Straight-line code over arrays, so
// the compiler pipelines/vectorises it. T holds the loads on the half-step grid (T[2i], T[2i+1],
// T[2i+2] for step i).
// Structure-of-arrays of the affine maps of one block (so affineRk4Block vectorises).
struct AffineBlock {
  std::vector<double> m11, m12, m21, m22, g1, g2;
  std::vector<char> split;
  explicit AffineBlock(size_t n) : m11(n), m12(n), m21(n), m22(n), g1(n), g2(n), split(n) {}
  void set(Eigen::Index i, const AffineStep& a) {
    m11[i] = a.m11, m12[i] = a.m12, m21[i] = a.m21, m22[i] = a.m22, g1[i] = a.g1, g2[i] = a.g2;
    split[i] = 0;
  }
};

void affineRk4Block(Eigen::Index n, double h, double K, double ca, double cb, double ff,
                    const double* T, AffineBlock* out, Eigen::Index offset) {
  double* __restrict m11 = out->m11.data() + offset;
  double* __restrict m12 = out->m12.data() + offset;
  double* __restrict m21 = out->m21.data() + offset;
  double* __restrict m22 = out->m22.data() + offset;
  double* __restrict g1 = out->g1.data() + offset;
  double* __restrict g2 = out->g2.data() + offset;
  std::fill(out->split.begin() + offset, out->split.begin() + offset + n, 0);
  // Multiplications by reciprocals: x / 6.0 would compile to a real division per term.
  constexpr double k3 = 1.0 / 3.0, k6 = 1.0 / 6.0, k12 = 1.0 / 12.0, k24 = 1.0 / 24.0;
  const double k = h * h * K, hca = h * ca, hcb = h * cb, hff = h * ff, inv_h = 1.0 / h;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double T0 = T[2 * i], Tm = T[2 * i + 1], T1 = T[2 * i + 2];
    const double a = hca + hcb * T0, b = hca + hcb * Tm, c = hca + hcb * T1;
    const double f0 = hff * T0, fm = hff * Tm, f1 = hff * T1;  // h F at the stages
    const double b2 = b * b;
    m11[i] = 1.0 + k * (-0.5 + b * k6 + (k - b2) * k24);
    m12[i] =
        h * (1.0 - a * k6 - b * k3 + (a * b + b2) * k12 - k * k6 + (k * (a + b) - a * b2) * k24);
    m21[i] =
        inv_h * k *
        (-1.0 + (c + 2.0 * b) * k6 + (2.0 * k - c * b - b2) * k12 + (c * b2 - k * (c + b)) * k24);
    m22[i] = 1.0 - (a + c) * k6 - 2.0 * b * k3 + (a * b + c * b + b2) * k6 - k / 2.0 -
             (a + c) * b2 * k12 + (a + c) * k * k12 + b * k * k6 +
             (a * c * b2 - a * c * k - a * b * k - c * b * k + k * k) * k24;
    g1[i] = h * (f0 * k6 + fm * k3 - b * (f0 + fm) * k12 + (b2 - k) * f0 * k24);
    g2[i] = (f0 + f1) * k6 + 2.0 * fm * k3 - (c * fm + b * f0 + b * fm) * k6 +
            (c * b * fm + b2 * f0 - k * f0 - k * fm) * k12 + (k * (c + b) - c * b2) * f0 * k24;
  }
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
  Model model{stiffness, MeshTiming(cfg.speed, cfg.gears.pinion.teeth, cfg.mesh.initial_phase),
              load,      DampingLaw(cfg.damping, stiffness.mean(), me, t1_mean),
              me,        cfg.gears.forceFactor()};
  const StaticTransmissionError ste(cfg.ste, cfg.gears.pinion.teeth, cfg.gears.gear.teeth);
  if (ste.active()) {
    model.ste = &ste;
    model.ste_relative = cfg.ste.damping == SteDamping::Relative;
  }

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
    o.time[n] = static_cast<double>(n) / fs;
    o.mesh_phase[n] = model.timing.phase(o.time[n]);
  }
  // Stiffness, mesh state and damping of sample n: the values holding from t_n on. The fast
  // path fills whole pieces between breakpoints at once; this is the per-sample definition.
  auto sampleColumns = [&](Eigen::Index n) {
    const double u = o.mesh_phase[n];
    o.stiffness[n] = stiffness.at(u + kPhaseNudge);
    o.mesh_state[n] = stiffness.state(u + kPhaseNudge);
    o.damping[n] = model.damping.at(o.time[n] + 1e-6 * dt, o.torque[n]);
  };
  const bool fast_path = !torsional && stiffness.piecewiseConstant() && !model.ste;
  if (!fast_path)
    for (Eigen::Index n = 0; n < n_samples; ++n) sampleColumns(n);

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
          double e, e_dot;
          model.steAt(t, &e, &e_dot);
          return torsionalRate(x, model.damping.at(mid, t1), model.k(t, mid), t1, g, e, e_dot);
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
  } else if (!stiffness.piecewiseConstant() || model.ste) {
    // Smooth or kinked stiffness, or an STE forcing: the generic driver evaluates K (and the
    // STE) at every stage.
    std::string e =
        integrateSdof(coeffs, bps, 0.0, dt, n_samples, {so.initial_dte, so.initial_velocity},
                      so.integrator, m, o.dte.data(), o.dte_velocity.data());
    if (!e.empty()) {
      if (error) *error = e;
      return false;
    }
  } else {
    // Fast path (the default case). K and the damping law's (a, b) are constant between
    // breakpoints and the load on the half-step grid comes in blocks from fillUniform (phasor
    // recurrence for the sine: no sin() per stage). Eq. (4) is linear, so one RK step is the
    // affine map s' = M s + g, M and g independent of the state: a first pass computes them for
    // a whole block by applying the very same rkStep to the basis states and to the forcing
    // (independent iterations the CPU pipelines), and the sequential pass is then a 2x2
    // multiply-add per sample instead of RK4's long dependent chain. Same method, same
    // stages; results agree with the stage-wise RK to rounding. Intervals that contain a
    // breakpoint take the generic split path.
    constexpr Eigen::Index kBlock = 2048;
    const double h = dt / m;
    std::vector<double> T(static_cast<size_t>(2 * m * kBlock + 1));
    AffineBlock maps(static_cast<size_t>(kBlock));
    SdofState s{so.initial_dte, so.initial_velocity};
    o.dte[0] = s.y;
    o.dte_velocity[0] = s.v;
    const double ff = model.ff, inv_me = 1.0 / me;
    for (Eigen::Index n0 = 0; n0 + 1 < n_samples; n0 += kBlock) {
      const Eigen::Index n1 = std::min(n_samples - 1, n0 + kBlock);
      model.load.fillUniform(o.time[n0], 0.5 * h, 2 * m * (n1 - n0) + 1, T.data());
      // Pass 1: pieces of constant (K, a, b) between breakpoints; affine maps of their steps.
      auto bp_scan = bp;
      Eigen::Index n = n0;
      while (n < n1) {
        while (bp_scan != bp_end && *bp_scan <= o.time[n]) ++bp_scan;
        // Intervals [n, n_end) contain no breakpoint; interval n_end (if < n1) contains one.
        Eigen::Index n_end = n1;
        if (bp_scan != bp_end && *bp_scan < o.time[n1]) {
          n_end = std::max(n, static_cast<Eigen::Index>(std::floor(*bp_scan * fs)));
          while (n_end > n && o.time[n_end] >= *bp_scan) --n_end;
          while (n_end + 1 <= n1 && o.time[n_end + 1] < *bp_scan) ++n_end;
          // now t[n_end] < bp < t[n_end + 1] or bp == t[n_end + 1] handled by the <= above
        }
        if (n_end > n) {
          const double mid = o.time[n] + 0.5 * dt;
          const double k_phys = model.k(mid, mid), K = k_phys * inv_me;
          const double state = stiffness.state(model.timing.phase(mid));
          double ca, cb;
          model.damping.coefficients(mid, &ca, &cb);
          for (Eigen::Index i = n; i < n_end; ++i) {
            o.stiffness[i] = k_phys;
            o.mesh_state[i] = state;
            o.damping[i] = ca + cb * o.torque[i];
          }
          ca *= inv_me;
          cb *= inv_me;
          if (so.integrator == Integrator::RK4 && m == 1) {
            affineRk4Block(n_end - n, h, K, ca, cb, ff, T.data() + 2 * (n - n0), &maps, n - n0);
          } else {
            for (Eigen::Index i = n; i < n_end; ++i) {
              const double* Ti = T.data() + 2 * m * (i - n0);
              maps.set(i - n0, affineStep(so.integrator, h, m, K, ca, cb, ff, Ti));
            }
          }
        }
        if (n_end < n1) {
          maps.split[n_end - n0] = 1;
          sampleColumns(n_end);
        }
        n = n_end + 1;
      }
      // Pass 2: the sequential recurrence.
      for (Eigen::Index i = n0; i < n1; ++i) {
        const Eigen::Index j = i - n0;
        if (maps.split[j]) {
          s = advanceSdof(coeffs, s, o.time[i], o.time[i + 1], m, bp, bp_end, so.integrator);
        } else {
          s = {maps.m11[j] * s.y + maps.m12[j] * s.v + maps.g1[j],
               maps.m21[j] * s.y + maps.m22[j] * s.v + maps.g2[j]};
        }
        o.dte[i + 1] = s.y;
        o.dte_velocity[i + 1] = s.v;
      }
      while (bp != bp_end && *bp <= o.time[n1]) ++bp;
    }
    sampleColumns(n_samples - 1);
  }

  // An unstable integration (a damping or stiffness far beyond the step's stability region)
  // ends in Inf/NaN: refused, never written as a record.
  for (Eigen::Index n = 0; n < n_samples; ++n)
    if (!std::isfinite(o.dte[n]) || !std::isfinite(o.dte_velocity[n]) ||
        !(std::abs(o.dte[n]) <= kMaxFiniteDte)) {
      if (error)
        *error = "the integration diverged at t = " + formatNumber(o.time[n]) +
                 " s (|dte| beyond 1 m or not finite): the time step 1/(simulation.sample_rate "
                 "x simulation.substeps) is too long for this damping and stiffness; raise "
                 "simulation.substeps or simulation.sample_rate";
      return false;
    }
  if (std::isfinite(so.noise_snr_db)) addNoise(&o.dte, so.noise_snr_db, so.seed);
  return true;
}

}  // namespace gear_sim
