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
};

// The affine map of `substeps` RK steps of length h with C = ca + cb*T and F = ff*T at the
// stage loads T[0], T[1], ... (half-step grid) and K constant, or K = Kh[0], Kh[1], ... on the
// same grid when Kh is given. Built by applying the RK step itself to the basis states (no
// forcing) and to the zero state (with forcing).
inline AffineStep affineStep(Integrator method, double h, int substeps, double K, const double* Kh,
                             double ca, double cb, double ff, const double* T) {
  AffineStep a;
  for (int j = 0; j < substeps; ++j) {
    const double t0 = T[2 * j], tm = T[2 * j + 1], t1 = T[2 * j + 2];
    const double K0 = Kh ? Kh[2 * j] : K, Km = Kh ? Kh[2 * j + 1] : K, K1 = Kh ? Kh[2 * j + 2] : K;
    const SdofCoefficients c0{ca + cb * t0, K0, 0.0}, cm{ca + cb * tm, Km, 0.0},
        c1{ca + cb * t1, K1, 0.0};
    const SdofCoefficients f0{c0.C, K0, ff * t0}, fm{cm.C, Km, ff * tm}, f1{c1.C, K1, ff * t1};
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
    a = composeAffine({e1.y, e2.y, e1.v, e2.v, g.y, g.v}, a);
  }
  return a;
}

// Structure-of-arrays of the affine maps of one block (so affineRk4Block vectorises).
struct AffineBlock {
  std::vector<double> m11, m12, m21, m22, g1, g2;
  std::vector<char> split;
  // Scratch: the half-step grids de-interleaved (loads/stiffnesses at the step starts, n + 1,
  // and at the midpoints), so the kernels' loads are unit-stride and the loops vectorise.
  std::vector<double> t_start, t_mid, k_start, k_mid;
  explicit AffineBlock(size_t n)
      : m11(n),
        m12(n),
        m21(n),
        m22(n),
        g1(n),
        g2(n),
        split(n),
        t_start(n + 1),
        t_mid(n),
        k_start(n + 1),
        k_mid(n) {}
  void set(Eigen::Index i, const AffineStep& a) {
    m11[i] = a.m11, m12[i] = a.m12, m21[i] = a.m21, m22[i] = a.m22, g1[i] = a.g1, g2[i] = a.g2;
    split[i] = 0;
  }
};

// x[0], x[2], ..., x[2n] into even[0..n] and x[1], x[3], ..., x[2n-1] into odd[0..n).
void deinterleave(const double* x, Eigen::Index n, double* even, double* odd) {
  for (Eigen::Index i = 0; i < n; ++i) {
    even[i] = x[2 * i];
    odd[i] = x[2 * i + 1];
  }
  even[n] = x[2 * n];
}

// Closed form of affineStep for one RK4 step (derived symbolically from rk4Step and checked
// against it in the tests): with a = h C0, b = h Cm, c = h C1, k = h^2 K and the stage loads,
// the maps of n steps into m11..g2 from the loads at the step starts te[0..n] and midpoints
// tm[0..n). Straight-line code over arrays, so the compiler pipelines/vectorises it. Raw __restrict
// parameters: with pointers taken from the block's vectors inside the function GCC 12 leaves the
// loop scalar.
void affineRk4Kernel(Eigen::Index n, double h, double K, double ca, double cb, double ff,
                     const double* __restrict te, const double* __restrict tm,
                     double* __restrict m11, double* __restrict m12, double* __restrict m21,
                     double* __restrict m22, double* __restrict g1, double* __restrict g2) {
  // Multiplications by reciprocals: x / 6.0 would compile to a real division per term.
  constexpr double k3 = 1.0 / 3.0, k6 = 1.0 / 6.0, k12 = 1.0 / 12.0, k24 = 1.0 / 24.0;
  const double k = h * h * K, hca = h * ca, hcb = h * cb, hff = h * ff, inv_h = 1.0 / h;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double T0 = te[i], Tm = tm[i], T1 = te[i + 1];
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

void affineRk4Block(Eigen::Index n, double h, double K, double ca, double cb, double ff,
                    const double* T, AffineBlock* out, Eigen::Index offset) {
  std::fill(out->split.begin() + offset, out->split.begin() + offset + n, 0);
  deinterleave(T, n, out->t_start.data(), out->t_mid.data());
  affineRk4Kernel(n, h, K, ca, cb, ff, out->t_start.data(), out->t_mid.data(),
                  out->m11.data() + offset, out->m12.data() + offset, out->m21.data() + offset,
                  out->m22.data() + offset, out->g1.data() + offset, out->g2.data() + offset);
}

// affineRk4Kernel with a stiffness that varies over the step: K at the stages, ke[0..n] at the
// step starts and kmid[0..n) at the midpoints. Closed form of one RK4 step (derived
// symbolically from rk4Step in the scaled variables V = h v, a = h C, k = h^2 K, f = h^2 F;
// checked against the stage-wise integrator in the tests), in Horner form.
void affineRk4KernelVaryingK(Eigen::Index n, double h, double ca, double cb, double ff,
                             const double* __restrict te, const double* __restrict tm,
                             const double* __restrict ke, const double* __restrict kmid,
                             double* __restrict m11, double* __restrict m12, double* __restrict m21,
                             double* __restrict m22, double* __restrict g1, double* __restrict g2) {
  const double h2 = h * h, hca = h * ca, hcb = h * cb, h2ff = h2 * ff, inv_h = 1.0 / h;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double T0 = te[i], Tm = tm[i], T1 = te[i + 1];
    const AffineStep s =
        rk4AffineScaled(h, inv_h, hca + hcb * T0, hca + hcb * Tm, hca + hcb * T1, h2 * ke[i],
                        h2 * kmid[i], h2 * ke[i + 1], h2ff * T0, h2ff * Tm, h2ff * T1);
    m11[i] = s.m11, m12[i] = s.m12, m21[i] = s.m21, m22[i] = s.m22, g1[i] = s.g1, g2[i] = s.g2;
  }
}

// affineRk4Block with a stiffness that varies over the step: K at the stages on the half-step
// grid Kh, like T.
void affineRk4BlockVaryingK(Eigen::Index n, double h, const double* Kh, double ca, double cb,
                            double ff, const double* T, AffineBlock* out, Eigen::Index offset) {
  std::fill(out->split.begin() + offset, out->split.begin() + offset + n, 0);
  deinterleave(T, n, out->t_start.data(), out->t_mid.data());
  deinterleave(Kh, n, out->k_start.data(), out->k_mid.data());
  affineRk4KernelVaryingK(n, h, ca, cb, ff, out->t_start.data(), out->t_mid.data(),
                          out->k_start.data(), out->k_mid.data(), out->m11.data() + offset,
                          out->m12.data() + offset, out->m21.data() + offset,
                          out->m22.data() + offset, out->g1.data() + offset,
                          out->g2.data() + offset);
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
  // Stiffness, mesh state and damping of sample n: the values holding from t_n on. The pieces
  // between breakpoints are filled at once below; this is the per-sample definition.
  auto sampleColumns = [&](Eigen::Index n) {
    const double u = o.mesh_phase[n];
    o.stiffness[n] = stiffness.at(u + kPhaseNudge);
    o.mesh_state[n] = stiffness.state(u + kPhaseNudge);
    o.damping[n] = model.damping.at(o.time[n] + 1e-6 * dt, o.torque[n]);
  };

  const int m = so.substeps;
  auto bp = bps.cbegin();
  const auto bp_end = bps.cend();
  auto coeffs = [&model](double t, double t_ref) { return model.sdof(t, t_ref); };

  // Eq. (4) for every stiffness model, load profile and both dynamics. K, the load and the
  // damping law's (a, b) are tabulated between breakpoints on the half-step grid (the load in
  // blocks from fillUniform: phasor recurrence for the sine, no sin() per stage; the stiffness
  // from MeshStiffness::fillPiece: constant, a linear ramp or a rotated Fourier series). Eq. (4)
  // is linear, so one RK step is the affine map s' = M s + g, M and g independent of the state:
  // a first pass computes them for a whole block (independent iterations the CPU pipelines;
  // closed forms of rk4Step for RK4 with one substep, else the very same rkStep applied to the
  // basis states and to the forcing), and the sequential pass is then a 2x2 multiply-add per
  // sample instead of RK4's long dependent chain. Same method, same stages; results agree with
  // the stage-wise RK to rounding. Intervals that contain a breakpoint take the generic split
  // path.
  //
  // Torsional dynamics, eq. (1): the DTE y = R1 th1 - R2 th2 obeys eq. (4) exactly, and RK
  // commutes with the linear change of variables, so the stage-wise RK of the 4-state system
  // gives this y (to rounding). The other combination q = R2 J1 th1 + R1 J2 th2 has
  // q'' = (R2 - R1) T1 (the mesh force cancels): integrated with the same RK steps below, and
  // (th1, th2) recovered from (y, q).
  const bool pc = stiffness.piecewiseConstant();
  constexpr Eigen::Index kBlock = 2048;
  const double h = dt / m;
  const size_t grid = static_cast<size_t>(2 * m * kBlock + 1);
  std::vector<double> T(grid), U(pc ? 0 : grid), Kh(pc ? 0 : grid);
  AffineBlock maps(static_cast<size_t>(kBlock));
  SdofState s{so.initial_dte, so.initial_velocity};
  o.dte[0] = s.y;
  o.dte_velocity[0] = s.v;
  const double ff = model.ff, inv_me = 1.0 / me;
  const double du = model.timing.linear() ? model.timing.meshFrequency(0.0) * 0.5 * h : 0.0;
  // Torsional: q, q' and the reconstruction of (th1, th2).
  const GearPair& g = cfg.gears;
  const double r1 = g.pinion.base_radius, r2 = g.gear.base_radius;
  const double j1 = g.pinion.inertia, j2 = g.gear.inertia;
  const double q_gain = r2 - r1, det = r1 * r1 * j2 + r2 * r2 * j1;
  SdofState q{r2 * j1 * so.initial_dte / r1, r2 * j1 * so.initial_velocity / r1};
  auto qStep = [&](double hs, double g0, double gm, double g1) {
    if (so.integrator == Integrator::RK4) {
      q = {q.y + hs * q.v + hs * hs / 6.0 * (g0 + 2.0 * gm), q.v + hs / 6.0 * (g0 + 4.0 * gm + g1)};
    } else {
      q = {q.y + hs * (q.v + 0.5 * hs * g0), q.v + hs * gm};
    }
  };
  auto writeAngles = [&](Eigen::Index n) {
    o.theta1[n] = (r1 * j2 * o.dte[n] + r2 * q.y) / det;
    o.theta2[n] = (r1 * q.y - r2 * j1 * o.dte[n]) / det;
  };
  if (torsional) writeAngles(0);

  for (Eigen::Index n0 = 0; n0 + 1 < n_samples; n0 += kBlock) {
    const Eigen::Index n1 = std::min(n_samples - 1, n0 + kBlock);
    model.load.fillUniform(o.time[n0], 0.5 * h, 2 * m * (n1 - n0) + 1, T.data());
    // Pass 1: pieces of constant (a, b) and smooth K between breakpoints; affine maps of their
    // steps.
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
      // An STE forcing (docs/ste.md) is evaluated at every stage: every interval takes the
      // generic path, whose coefficients (Model::sdof) carry it. The torsional model's rigid
      // combination q does not see the mesh force, so it needs nothing more.
      if (model.ste) n_end = n;
      if (n_end > n) {
        const double mid = o.time[n] + 0.5 * dt;
        double ca, cb;
        model.damping.coefficients(mid, &ca, &cb);
        for (Eigen::Index i = n; i < n_end; ++i) o.damping[i] = ca + cb * o.torque[i];
        ca *= inv_me;
        cb *= inv_me;
        const Eigen::Index j0 = 2 * m * (n - n0);
        const double* Tp = T.data() + j0;
        double k_phys = 0.0;
        if (pc || stiffness.constantOnPiece(model.timing.phase(mid), &k_phys)) {
          if (pc) k_phys = model.k(mid, mid);
          const double K = k_phys * inv_me;
          const double state = stiffness.state(model.timing.phase(mid));
          for (Eigen::Index i = n; i < n_end; ++i) {
            o.stiffness[i] = k_phys;
            o.mesh_state[i] = state;
          }
          if (so.integrator == Integrator::RK4 && m == 1) {
            affineRk4Block(n_end - n, h, K, ca, cb, ff, Tp, &maps, n - n0);
          } else {
            for (Eigen::Index i = n; i < n_end; ++i)
              maps.set(i - n0, affineStep(so.integrator, h, m, K, nullptr, ca, cb, ff,
                                          Tp + 2 * m * (i - n)));
          }
        } else {
          const Eigen::Index cnt = 2 * m * (n_end - n) + 1;
          const double t_piece = o.time[n0];
          for (Eigen::Index j = 0; j < cnt; ++j)
            U[j] = model.timing.phase(t_piece + static_cast<double>(j0 + j) * (0.5 * h));
          double* Kp = Kh.data() + j0;
          stiffness.fillPiece(model.timing.phase(mid), U.data(), cnt, du, Kp);
          for (Eigen::Index i = n; i < n_end; ++i) {
            o.stiffness[i] = Kp[2 * m * (i - n)];
            o.mesh_state[i] = stiffness.state(o.mesh_phase[i] + kPhaseNudge);
          }
          for (Eigen::Index j = 0; j < cnt; ++j) Kp[j] *= inv_me;
          if (so.integrator == Integrator::RK4 && m == 1) {
            affineRk4BlockVaryingK(n_end - n, h, Kp, ca, cb, ff, Tp, &maps, n - n0);
          } else {
            for (Eigen::Index i = n; i < n_end; ++i)
              maps.set(i - n0, affineStep(so.integrator, h, m, 0.0, Kp + 2 * m * (i - n), ca, cb,
                                          ff, Tp + 2 * m * (i - n)));
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
    const auto bp_block = bp;
    {
      const double* __restrict m11 = maps.m11.data();
      const double* __restrict m12 = maps.m12.data();
      const double* __restrict m21 = maps.m21.data();
      const double* __restrict m22 = maps.m22.data();
      const double* __restrict g1 = maps.g1.data();
      const double* __restrict g2 = maps.g2.data();
      const char* __restrict split = maps.split.data();
      double* __restrict y = o.dte.data() + n0 + 1;
      double* __restrict v = o.dte_velocity.data() + n0 + 1;
      double sy = s.y, sv = s.v;
      for (Eigen::Index j = 0; j < n1 - n0; ++j) {
        if (split[j]) {
          const SdofState a = advanceSdof(coeffs, {sy, sv}, o.time[n0 + j], o.time[n0 + j + 1], m,
                                          bp, bp_end, so.integrator);
          sy = a.y;
          sv = a.v;
        } else {
          const double ny = m11[j] * sy + m12[j] * sv + g1[j];
          sv = m21[j] * sy + m22[j] * sv + g2[j];
          sy = ny;
        }
        y[j] = sy;
        v[j] = sv;
      }
      s = {sy, sv};
    }
    if (torsional) {
      auto bq = bp_block;
      const double* __restrict y = o.dte.data();
      double* __restrict th1 = o.theta1.data();
      double* __restrict th2 = o.theta2.data();
      const double a1 = r1 * j2 / det, b1 = r2 / det, a2 = -r2 * j1 / det, b2 = r1 / det;
      const bool fast = so.integrator == Integrator::RK4 && m == 1;
      const double h6 = h * h / 6.0, hs6 = h / 6.0;
      double qy = q.y, qv = q.v;
      for (Eigen::Index i = n0; i < n1; ++i) {
        const double* Ti = T.data() + 2 * m * (i - n0);
        if (fast && !maps.split[i - n0]) {
          const double g0 = q_gain * Ti[0], gm = q_gain * Ti[1], g1 = q_gain * Ti[2];
          qy = qy + h * qv + h6 * (g0 + 2.0 * gm);
          qv = qv + hs6 * (g0 + 4.0 * gm + g1);
        } else {
          q = {qy, qv};
          if (maps.split[i - n0]) {
            forEachStep(o.time[i], o.time[i + 1], m, bq, bp_end,
                        [&](double a, double e, double md) {
                          qStep(e - a, q_gain * model.load.at(a), q_gain * model.load.at(md),
                                q_gain * model.load.at(e));
                        });
          } else {
            for (int k = 0; k < m; ++k)
              qStep(h, q_gain * Ti[2 * k], q_gain * Ti[2 * k + 1], q_gain * Ti[2 * k + 2]);
          }
          qy = q.y;
          qv = q.v;
        }
        th1[i + 1] = a1 * y[i + 1] + b1 * qy;
        th2[i + 1] = a2 * y[i + 1] + b2 * qy;
      }
      q = {qy, qv};
    }
    while (bp != bp_end && *bp <= o.time[n1]) ++bp;
  }
  sampleColumns(n_samples - 1);

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
