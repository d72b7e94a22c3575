#include "gear_sim/simulator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <vector>

#include "gear_sim/message_text.hpp"
#include "gear_sim/models.hpp"
#include "gear_sim/sdof_integrator.hpp"
#include "gear_sim/simd_clones.hpp"

namespace gear_sim {

double naturalFrequencyHz(const GearPair& gears, const MeshOptions& mesh) {
  return std::sqrt(MeshStiffness(mesh).mean() / gears.equivalentMass()) / (2.0 * M_PI);
}

namespace {

// RK4 steps of parametricGrowthRate's cycle at most: 2 ms, 6 ms with 100 Fourier harmonics
// (the stiffness on each smooth piece's grid from MeshStiffness::fillPiece, whose Fourier series
// rotates exact anchors instead of a cos/sin per harmonic and stage); beyond, the rate is not
// computed (NaN). Before 2026-11-28's second session the bound was 1e7 steps per piece with a
// cos/sin per harmonic and stage, and a hostile test made analyze --wavelet take 64 s and
// wavelet_node 24 s per window on Fourier stiffnesses at a 1 Hz mesh frequency. The bound is
// reached at mesh frequencies below 1/76 of the natural frequency at the stiffness maximum for a
// Fourier stiffness (all smooth), below 1/760 for a trapezoid with 5 % ramps: parametric
// resonances of order above ~150, whose regions are narrower than any speed is steady.
constexpr double kMaxFloquetSteps = 6e4;

}  // namespace

double parametricGrowthRate(const GearPair& gears, const MeshOptions& mesh, double f_mesh) {
  const double me = gears.equivalentMass();
  if (!(f_mesh > 0.0) || !std::isfinite(f_mesh) || !(me > 0.0) || !std::isfinite(me))
    return std::numeric_limits<double>::quiet_NaN();
  if (mesh.model == StiffnessModel::Fourier &&
      std::all_of(mesh.fourier_cos.begin(), mesh.fourier_cos.end(),
                  [](double a) { return a == 0.0; }) &&
      std::all_of(mesh.fourier_sin.begin(), mesh.fourier_sin.end(),
                  [](double b) { return b == 0.0; }))
    return 0.0;                  // a constant stiffness: no parametric excitation
  double work = 0.0;             // RK4 steps so far
  std::vector<double> grid, kg;  // a smooth piece's phases (half steps) and stiffness there
  RotationTable rotations;
  const MeshStiffness k(mesh);
  std::vector<double> edges = k.cycleBreakpoints();
  edges.push_back(1.0);
  Eigen::Matrix2d Phi = Eigen::Matrix2d::Identity();  // columns: (y, v) of two solutions
  double u0 = 0.0;
  for (const double u1 : edges) {
    if (!(u1 > u0)) continue;
    const double um = 0.5 * (u0 + u1), dt = (u1 - u0) / f_mesh;
    double kc = 0.0;
    if (k.constantOnPiece(um, &kc)) {
      const double w = std::sqrt(std::max(kc, 0.0) / me);
      const double c = std::cos(w * dt), s = std::sin(w * dt);
      Eigen::Matrix2d M;
      M << c, w > 0.0 ? s / w : dt, -w * s, c;
      Phi = (M * Phi).eval();
    } else {
      // RK4 (rk4Step, C = F = 0) of both columns of Phi at w_max h <= 0.01.
      const double w_max =
          std::sqrt(std::max({k.at(u0, um), k.at(um, um), k.at(u1, um), 0.0}) / me) *
          1.25;  // (a margin for the piece's maximum)
      const double want = std::max(4.0, std::ceil(w_max * dt / 0.01));
      work += want;
      if (!(work <= kMaxFloquetSteps)) return std::numeric_limits<double>::quiet_NaN();
      const long steps = static_cast<long>(want);
      const double h = dt / static_cast<double>(steps), du = (u1 - u0) / static_cast<double>(steps);
      // k at the step ends and midpoints: a uniform grid of half steps.
      grid.resize(static_cast<size_t>(2 * steps + 1));
      kg.resize(grid.size());
      for (size_t i = 0; i < grid.size(); ++i) grid[i] = u0 + 0.5 * du * static_cast<double>(i);
      k.fillPiece(um, grid.data(), static_cast<long>(grid.size()), 0.5 * du, kg.data(), &rotations);
      for (long j = 0; j < steps; ++j) {
        const size_t g = static_cast<size_t>(2 * j);
        const SdofCoefficients c0{0.0, kg[g] / me, 0.0}, cm{0.0, kg[g + 1] / me, 0.0},
            c1{0.0, kg[g + 2] / me, 0.0};
        for (int col = 0; col < 2; ++col) {
          const SdofState x = rk4Step({Phi(0, col), Phi(1, col)}, h, c0, cm, c1);
          Phi(0, col) = x.y, Phi(1, col) = x.v;
        }
      }
    }
    u0 = u1;
  }
  const double half_trace = 0.5 * std::abs(Phi.trace());
  if (!std::isfinite(half_trace)) return std::numeric_limits<double>::quiet_NaN();
  return half_trace > 1.0 ? std::acosh(half_trace) * f_mesh : 0.0;
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
    if (method == Integrator::Rk4) {
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

// The block passes below (deinterleave, the kernels, phaseGrid, stiffnessColumns) have AVX2
// clones (GEAR_AVX2_CLONES: wider vectors and a rounding instruction for floor, no FMA): lane by
// lane the same operations, so the same bits as the baseline build.

// x[0], x[2], ..., x[2n] into even[0..n] and x[1], x[3], ..., x[2n-1] into odd[0..n).
GEAR_AVX2_CLONES void deinterleave(const double* x, Eigen::Index n, double* even, double* odd) {
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
GEAR_AVX2_CLONES void affineRk4Kernel(Eigen::Index n, double h, double K, double ca, double cb,
                                      double ff, const double* __restrict te,
                                      const double* __restrict tm, double* __restrict m11,
                                      double* __restrict m12, double* __restrict m21,
                                      double* __restrict m22, double* __restrict g1,
                                      double* __restrict g2) {
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
GEAR_AVX2_CLONES void affineRk4KernelVaryingK(
    Eigen::Index n, double h, double ca, double cb, double ff, const double* __restrict te,
    const double* __restrict tm, const double* __restrict ke, const double* __restrict kmid,
    double* __restrict m11, double* __restrict m12, double* __restrict m21, double* __restrict m22,
    double* __restrict g1, double* __restrict g2) {
  const double h2 = h * h, hca = h * ca, hcb = h * cb, h2ff = h2 * ff, inv_h = 1.0 / h;
  for (Eigen::Index i = 0; i < n; ++i) {
    const double T0 = te[i], Tm = tm[i], T1 = te[i + 1];
    const AffineStep s =
        rk4AffineScaled(h, inv_h, hca + hcb * T0, hca + hcb * Tm, hca + hcb * T1, h2 * ke[i],
                        h2 * kmid[i], h2 * ke[i + 1], h2ff * T0, h2ff * Tm, h2ff * T1);
    m11[i] = s.m11, m12[i] = s.m12, m21[i] = s.m21, m22[i] = s.m22, g1[i] = s.g1, g2[i] = s.g2;
  }
}

// affineRk4Block with a stiffness that varies over the step: K = scale * kh at the stages, kh on
// the half-step grid like T.
void affineRk4BlockVaryingK(Eigen::Index n, double h, const double* kh, double scale, double ca,
                            double cb, double ff, const double* T, AffineBlock* out,
                            Eigen::Index offset) {
  std::fill(out->split.begin() + offset, out->split.begin() + offset + n, 0);
  deinterleave(T, n, out->t_start.data(), out->t_mid.data());
  double* __restrict ks = out->k_start.data();
  double* __restrict km = out->k_mid.data();
  for (Eigen::Index i = 0; i < n; ++i) {
    ks[i] = kh[2 * i] * scale;
    km[i] = kh[2 * i + 1] * scale;
  }
  ks[n] = kh[2 * n] * scale;
  affineRk4KernelVaryingK(n, h, ca, cb, ff, out->t_start.data(), out->t_mid.data(),
                          out->k_start.data(), out->k_mid.data(), out->m11.data() + offset,
                          out->m12.data() + offset, out->m21.data() + offset,
                          out->m22.data() + offset, out->g1.data() + offset,
                          out->g2.data() + offset);
}

// U[j] = timing.phase(t0 + (j0 + j) * hh) for j < cnt: the phases of a smooth piece's half-step
// grid.
GEAR_AVX2_CLONES void phaseGrid(const MeshTiming& timing, double t0, Eigen::Index j0, double hh,
                                Eigen::Index cnt, double* __restrict U) {
  for (Eigen::Index j = 0; j < cnt; ++j) U[j] = timing.phase(t0 + static_cast<double>(j0 + j) * hh);
}

// The stiffness and mesh-state columns of samples [0, n) of a smooth piece: k[i] = kh[stride i]
// (the piece's half-step grid), state[i] = the mesh state at phase u[i] nudged by kPhaseNudge.
GEAR_AVX2_CLONES void stiffnessColumns(const MeshStiffness& stiffness, const double* __restrict kh,
                                       int stride, const double* __restrict u, Eigen::Index n,
                                       double* __restrict k, double* __restrict state) {
  for (Eigen::Index i = 0; i < n; ++i) {
    k[i] = kh[stride * i];
    state[i] = stiffness.state(u[i] + kPhaseNudge);
  }
}

// The 2x2 multiply-add of the block's intervals [j0, j1) (none split) from state s, writing the
// states after each into y[j], v[j]. A free function over raw arrays so that the state stays in
// registers: inlined into the loop that also calls the split path, GCC kept it on the stack, a
// store and a load on the dependency chain of every sample.
SdofState affineRun(const AffineBlock& m, Eigen::Index j0, Eigen::Index j1, SdofState s,
                    double* __restrict y, double* __restrict v) {
  const double* __restrict m11 = m.m11.data();
  const double* __restrict m12 = m.m12.data();
  const double* __restrict m21 = m.m21.data();
  const double* __restrict m22 = m.m22.data();
  const double* __restrict g1 = m.g1.data();
  const double* __restrict g2 = m.g2.data();
  double sy = s.y, sv = s.v;
  for (Eigen::Index j = j0; j < j1; ++j) {
    const double ny = m11[j] * sy + m12[j] * sv + g1[j];
    sv = m21[j] * sy + m22[j] * sv + g2[j];
    sy = ny;
    y[j] = sy;
    v[j] = sv;
  }
  return {sy, sv};
}

// One simulate() run of a validated configuration: the model, its breakpoints, the output table
// and the integration state carried from block to block. simulate() is a short loop over its
// named steps.
//
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
class Simulation {
 public:
  static constexpr Eigen::Index kBlock = 2048;

  Simulation(const SimConfig& cfg, SignalTable* out)
      : cfg_(cfg),
        so_(cfg.simulation),
        o_(*out),
        n_samples_(std::llround(so_.duration * so_.sample_rate)),
        fs_(so_.sample_rate),
        dt_(1.0 / fs_),
        t_last_(static_cast<double>(n_samples_ - 1) / fs_),
        stiffness_(cfg.mesh),
        ste_(cfg.ste, cfg.gears.pinion.teeth, cfg.gears.gear.teeth),
        m_(so_.substeps),
        h_(dt_ / m_),
        pc_(stiffness_.piecewiseConstant()),
        fast_(so_.integrator == Integrator::Rk4 && m_ == 1),
        torsional_(so_.dynamics == DynamicsModel::Torsional),
        maps_(static_cast<size_t>(kBlock)) {}

  Eigen::Index samples() const { return n_samples_; }

  /// The model (false: the damping law cannot be built for this load), its breakpoints, the
  /// output columns and the initial state.
  Status setUp() {
    if (Status s = buildModel(); !s.ok()) return s;
    collectBreakpoints();
    allocateColumns();
    fillSampledColumns();
    initialState();
    return {};
  }

  /// Samples n0 + 1 .. n1 (n1 - n0 <= kBlock).
  void integrateBlock(Eigen::Index n0, Eigen::Index n1) {
    model_->load.fillUniform(o_.time[n0], 0.5 * h_, 2 * m_ * (n1 - n0) + 1, T_.data(), &rotation_);
    affineMaps(n0, n1);
    const auto bp_block = bp_;
    recurrence(n0, n1);
    if (first_bad_ < 0) checkBlock(n0 + 1, n1 + 1);
    if (torsional_) rigidCombination(n0, n1, bp_block);
    while (bp_ != bps_.cend() && *bp_ <= o_.time[n1]) ++bp_;
  }

  /// The last sample's columns, the divergence check and the measurement noise.
  Status finish() {
    sampleColumns(n_samples_ - 1);
    if (Status s = checkFinite(); !s.ok()) return s;
    if (std::isfinite(so_.noise_snr_db)) addNoise(&o_.dte, so_.noise_snr_db, so_.seed);
    return {};
  }

 private:
  Status buildModel() {
    LoadTorque load(cfg_.load);
    const double t1_mean = load.mean(so_.duration);
    if (cfg_.damping.model == DampingProfile::LoadDependent && !(std::abs(t1_mean) > 0.0))
      return Status::invalidArgument(
          "damping.model = load_dependent: needs a non-zero time-mean load (load.* gives 0)",
          "damping.model");
    const double me = cfg_.gears.equivalentMass();
    model_.emplace(Model{
        stiffness_, MeshTiming(cfg_.speed, cfg_.gears.pinion.teeth, cfg_.mesh.initial_phase), load,
        DampingLaw(cfg_.damping, stiffness_.mean(), me, t1_mean), me, cfg_.gears.forceFactor()});
    if (ste_.active()) {
      model_->ste = &ste_;
      model_->ste_relative = cfg_.ste.damping == SteDamping::Relative;
    }
    return {};
  }

  // Every instant where a coefficient jumps or kinks: stiffness switches (from the mesh
  // phase's closed-form inverse), load kinks/steps, damping segment starts.
  void collectBreakpoints() {
    const Model& model = *model_;
    bps_ = model.load.breakpoints(t_last_);
    for (double t : model.damping.breakpoints(t_last_)) bps_.push_back(t);
    const double u_first = model.timing.phase(0.0), u_last = model.timing.phase(t_last_);
    if (!stiffness_.cycleBreakpoints().empty()) {
      for (double cycle = std::floor(u_first); cycle <= std::ceil(u_last); cycle += 1.0)
        for (double b : stiffness_.cycleBreakpoints()) {
          const double u = cycle + b;
          if (u > u_first && u < u_last) bps_.push_back(model.timing.timeOfPhase(u));
        }
    }
    std::sort(bps_.begin(), bps_.end());
    bp_ = bps_.cbegin();
  }

  void allocateColumns() {
    for (Eigen::VectorXd* c : {&o_.time, &o_.dte, &o_.dte_velocity, &o_.stiffness, &o_.torque,
                               &o_.mesh_state, &o_.mesh_phase, &o_.damping})
      resize(*c, n_samples_);
    if (torsional_) {
      resize(o_.theta1, n_samples_);
      resize(o_.theta2, n_samples_);
    } else {
      o_.theta1.resize(0);
      o_.theta2.resize(0);
    }
    const size_t grid = static_cast<size_t>(2 * m_ * kBlock + 1);
    T_.resize(grid);
    U_.resize(pc_ ? 0 : grid);
    Kh_.resize(pc_ ? 0 : grid);
  }

  // Sampled columns (value holding from each sample's instant on). Loops over raw restrict
  // pointers, so they vectorise.
  void fillSampledColumns() {
    model_->load.fillUniform(0.0, dt_, n_samples_, o_.torque.data());
    double* __restrict t = o_.time.data();
    double* __restrict u = o_.mesh_phase.data();
    const double fs = fs_;
    for (Eigen::Index n = 0; n < n_samples_; ++n) t[n] = static_cast<double>(n) / fs;
    const MeshTiming& timing = model_->timing;
    for (Eigen::Index n = 0; n < n_samples_; ++n) u[n] = timing.phase(t[n]);
  }

  // Stiffness, mesh state and damping of sample n: the values holding from t_n on. The pieces
  // between breakpoints are filled at once in affineMaps; this is the per-sample definition.
  void sampleColumns(Eigen::Index n) {
    const double u = o_.mesh_phase[n];
    o_.stiffness[n] = stiffness_.at(u + kPhaseNudge);
    o_.mesh_state[n] = stiffness_.state(u + kPhaseNudge);
    o_.damping[n] = model_->damping.at(o_.time[n] + 1e-6 * dt_, o_.torque[n]);
  }

  void initialState() {
    const Model& model = *model_;
    s_ = {so_.initial_dte, so_.initial_velocity};
    o_.dte[0] = s_.y;
    o_.dte_velocity[0] = s_.v;
    ff_ = model.ff;
    inv_me_ = 1.0 / model.me;
    du_ = model.timing.linear() ? model.timing.meshFrequency(0.0) * 0.5 * h_ : 0.0;
    // Torsional: q, q' and the reconstruction of (th1, th2).
    const GearPair& g = cfg_.gears;
    r1_ = g.pinion.base_radius, r2_ = g.gear.base_radius;
    j1_ = g.pinion.inertia, j2_ = g.gear.inertia;
    q_gain_ = r2_ - r1_, det_ = r1_ * r1_ * j2_ + r2_ * r2_ * j1_;
    q_ = {r2_ * j1_ * so_.initial_dte / r1_, r2_ * j1_ * so_.initial_velocity / r1_};
    if (torsional_) {
      o_.theta1[0] = (r1_ * j2_ * o_.dte[0] + r2_ * q_.y) / det_;
      o_.theta2[0] = (r1_ * q_.y - r2_ * j1_ * o_.dte[0]) / det_;
    }
  }

  // Pass 1: pieces of constant (a, b) and smooth K between breakpoints; affine maps of their
  // steps. An interval holding a breakpoint is marked split (integrated stage-wise in pass 2).
  void affineMaps(Eigen::Index n0, Eigen::Index n1) {
    auto bp_scan = bp_;
    const auto bp_end = bps_.cend();
    Eigen::Index n = n0;
    while (n < n1) {
      while (bp_scan != bp_end && *bp_scan <= o_.time[n]) ++bp_scan;
      // Intervals [n, n_end) contain no breakpoint; interval n_end (if < n1) contains one.
      Eigen::Index n_end = n1;
      if (bp_scan != bp_end && *bp_scan < o_.time[n1]) {
        n_end = std::max(n, static_cast<Eigen::Index>(std::floor(*bp_scan * fs_)));
        while (n_end > n && o_.time[n_end] >= *bp_scan) --n_end;
        while (n_end + 1 <= n1 && o_.time[n_end + 1] < *bp_scan) ++n_end;
        // now t[n_end] < bp < t[n_end + 1] or bp == t[n_end + 1] handled by the <= above
      }
      // An STE forcing (docs/ste.md) is evaluated at every stage: every interval takes the
      // generic path, whose coefficients (Model::sdof) carry it. The torsional model's rigid
      // combination q does not see the mesh force, so it needs nothing more.
      if (model_->ste) n_end = n;
      if (n_end > n) smoothPiece(n0, n, n_end);
      if (n_end < n1) {
        maps_.split[n_end - n0] = 1;
        sampleColumns(n_end);
      }
      n = n_end + 1;
    }
  }

  // Affine maps of the intervals [n, n_end) of block n0, which hold no breakpoint, and their
  // stiffness, mesh state and damping columns.
  void smoothPiece(Eigen::Index n0, Eigen::Index n, Eigen::Index n_end) {
    const Model& model = *model_;
    const double mid = o_.time[n] + 0.5 * dt_;
    double ca, cb;
    model.damping.coefficients(mid, &ca, &cb);
    for (Eigen::Index i = n; i < n_end; ++i) o_.damping[i] = ca + cb * o_.torque[i];
    ca *= inv_me_;
    cb *= inv_me_;
    const Eigen::Index j0 = 2 * m_ * (n - n0);
    const double* Tp = T_.data() + j0;
    double k_phys = 0.0;
    if (pc_ || stiffness_.constantOnPiece(model.timing.phase(mid), &k_phys)) {
      if (pc_) k_phys = model.k(mid, mid);
      const double K = k_phys * inv_me_;
      const double state = stiffness_.state(model.timing.phase(mid));
      for (Eigen::Index i = n; i < n_end; ++i) {
        o_.stiffness[i] = k_phys;
        o_.mesh_state[i] = state;
      }
      if (fast_) {
        affineRk4Block(n_end - n, h_, K, ca, cb, ff_, Tp, &maps_, n - n0);
      } else {
        for (Eigen::Index i = n; i < n_end; ++i)
          maps_.set(i - n0, affineStep(so_.integrator, h_, m_, K, nullptr, ca, cb, ff_,
                                       Tp + 2 * m_ * (i - n)));
      }
      return;
    }
    const Eigen::Index cnt = 2 * m_ * (n_end - n) + 1;
    const double t_piece = o_.time[n0], hh = 0.5 * h_;
    const MeshTiming& timing = model.timing;
    double* __restrict U = U_.data();
    phaseGrid(timing, t_piece, j0, hh, cnt, U);
    double* __restrict Kp = Kh_.data() + j0;
    stiffness_.fillPiece(timing.phase(mid), U, cnt, du_, Kp, &fourier_rotation_);
    stiffnessColumns(stiffness_, Kp, 2 * m_, o_.mesh_phase.data() + n, n_end - n,
                     o_.stiffness.data() + n, o_.mesh_state.data() + n);
    if (fast_) {  // K = k / Me scaled while de-interleaved
      affineRk4BlockVaryingK(n_end - n, h_, Kp, inv_me_, ca, cb, ff_, Tp, &maps_, n - n0);
    } else {
      const double inv_me = inv_me_;
      for (Eigen::Index j = 0; j < cnt; ++j) Kp[j] *= inv_me;
      for (Eigen::Index i = n; i < n_end; ++i)
        maps_.set(i - n0, affineStep(so_.integrator, h_, m_, 0.0, Kp + 2 * m_ * (i - n), ca, cb,
                                     ff_, Tp + 2 * m_ * (i - n)));
    }
  }

  // Pass 2: the sequential recurrence (split intervals stage-wise across their breakpoints).
  void recurrence(Eigen::Index n0, Eigen::Index n1) {
    const Model& model = *model_;
    auto coeffs = [&model](double t, double t_ref) { return model.sdof(t, t_ref); };
    const char* split = maps_.split.data();
    double* y = o_.dte.data() + n0 + 1;
    double* v = o_.dte_velocity.data() + n0 + 1;
    SdofState s = s_;
    for (Eigen::Index j = 0; j < n1 - n0;) {
      Eigen::Index e = j;
      while (e < n1 - n0 && !split[e]) ++e;
      s = affineRun(maps_, j, e, s, y, v);
      if (e < n1 - n0) {  // split interval e
        s = advanceSdof(coeffs, s, o_.time[n0 + e], o_.time[n0 + e + 1], m_, bp_, bps_.cend(),
                        so_.integrator);
        y[e] = s.y;
        v[e] = s.v;
        ++e;
      }
      j = e;
    }
    s_ = s;
  }

  // One RK step of the rigid combination q'' = g.
  void qStep(double hs, double g0, double gm, double g1) {
    if (so_.integrator == Integrator::Rk4) {
      q_ = {q_.y + hs * q_.v + hs * hs / 6.0 * (g0 + 2.0 * gm),
            q_.v + hs / 6.0 * (g0 + 4.0 * gm + g1)};
    } else {
      q_ = {q_.y + hs * (q_.v + 0.5 * hs * g0), q_.v + hs * gm};
    }
  }

  // Torsional: q over the block with the same RK steps, and (th1, th2) from (y, q).
  void rigidCombination(Eigen::Index n0, Eigen::Index n1, std::vector<double>::const_iterator bq) {
    const Model& model = *model_;
    const auto bp_end = bps_.cend();
    const double q_gain = q_gain_, h = h_;
    const int m = m_;
    const double* __restrict y = o_.dte.data();
    double* __restrict th1 = o_.theta1.data();
    double* __restrict th2 = o_.theta2.data();
    const double a1 = r1_ * j2_ / det_, b1 = r2_ / det_, a2 = -r2_ * j1_ / det_, b2 = r1_ / det_;
    const double h6 = h * h / 6.0, hs6 = h / 6.0;
    const double* __restrict T = T_.data();  // T[2 m (i - n0)]: interval i's start
    double qy = q_.y, qv = q_.v;
    for (Eigen::Index i = n0; i < n1; ++i) {
      if (fast_ && !maps_.split[i - n0]) {
        // The run of unsplit intervals from i, the state in registers.
        Eigen::Index e = i + 1;
        while (e < n1 && !maps_.split[e - n0]) ++e;
        for (; i < e; ++i) {
          const double* Ti = T + 2 * (i - n0);  // m == 1 on the fast path
          const double g0 = q_gain * Ti[0], gm = q_gain * Ti[1], g1 = q_gain * Ti[2];
          qy = qy + h * qv + h6 * (g0 + 2.0 * gm);
          qv = qv + hs6 * (g0 + 4.0 * gm + g1);
          th1[i + 1] = a1 * y[i + 1] + b1 * qy;
          th2[i + 1] = a2 * y[i + 1] + b2 * qy;
        }
        --i;  // the run's last interval: the loop's ++i moves past it
        continue;
      }
      q_ = {qy, qv};
      if (maps_.split[i - n0]) {
        forEachStep(o_.time[i], o_.time[i + 1], m, bq, bp_end, [&](double a, double e, double md) {
          qStep(e - a, q_gain * model.load.at(a), q_gain * model.load.at(md),
                q_gain * model.load.at(e));
        });
      } else {
        const double* Ti = T + 2 * m * (i - n0);
        for (int k = 0; k < m; ++k)
          qStep(h, q_gain * Ti[2 * k], q_gain * Ti[2 * k + 1], q_gain * Ti[2 * k + 2]);
      }
      qy = q_.y;
      qv = q_.v;
      th1[i + 1] = a1 * y[i + 1] + b1 * qy;
      th2[i + 1] = a2 * y[i + 1] + b2 * qy;
    }
    q_ = {qy, qv};
  }

  // Samples [a, b): is any not finite (or beyond kMaxFiniteDte)? Checked block by block while
  // the block is in cache, as one branch-free pass (vectorised); the first such block is noted.
  void checkBlock(Eigen::Index a, Eigen::Index b) {
    const double* __restrict y = o_.dte.data();
    const double* __restrict v = o_.dte_velocity.data();
    constexpr double kMax = std::numeric_limits<double>::max();
    bool bad = false;
    for (Eigen::Index n = a; n < b; ++n)
      bad |= !(std::abs(y[n]) <= kMaxFiniteDte) | !(std::abs(v[n]) <= kMax);  // NaN: false
    if (bad) first_bad_ = a;
  }

  // An unstable integration (a damping or stiffness far beyond the step's stability region)
  // ends in Inf/NaN: refused, never written as a record. The blocks were checked as they were
  // integrated (checkBlock); only a failed run scans for the first bad sample, named in the
  // message.
  Status checkFinite() {
    checkBlock(0, 1);  // the initial state
    if (first_bad_ < 0) return {};
    for (Eigen::Index n = 0; n < n_samples_; ++n)
      if (!std::isfinite(o_.dte[n]) || !std::isfinite(o_.dte_velocity[n]) ||
          !(std::abs(o_.dte[n]) <= kMaxFiniteDte)) {
        if (std::string why = unstableGear(n); !why.empty())
          return Status::invalidArgument(why, "speed.pinion_rpm");
        return Status::invalidArgument(
            "the integration diverged at t = " + formatNumber(o_.time[n]) +
                " s (|dte| beyond 1 m or not finite): the time step 1/(simulation.sample_rate "
                "x simulation.substeps) is too long for this damping and stiffness; raise "
                "simulation.substeps or simulation.sample_rate",
            "simulation.substeps");
      }
    return {};
  }

  // Why the run diverged where the model itself does: the mesh equation's Floquet growth rate
  // (parametricGrowthRate) at the mesh frequency of some sample up to n beyond the damping's decay
  // C/2 there (the motion grows without bound whatever the step); "" otherwise. Before, such a
  // run (held-out seed 14308: trapezoid stiffness, 5575 rpm) was blamed on the time step, and
  // raising the substeps 1 -> 16 diverged at the same instant.
  std::string unstableGear(Eigen::Index n) const {
    if (!model_) return "";
    const Model& model = *model_;
    constexpr int kProbes = 16;  // instants up to n (a speed ramp moves the mesh frequency)
    // One growth rate per distinct mesh frequency (a constant speed: one evaluation).
    constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
    double f_last = kNone, lambda = kNone;
    for (int q = kProbes; q >= 1; --q) {
      const Eigen::Index m = n * q / kProbes;
      const double t = o_.time[m], f = model.timing.meshFrequency(t);
      if (!(f == f_last)) lambda = parametricGrowthRate(cfg_.gears, cfg_.mesh, f), f_last = f;
      const double c = o_.damping.size() > m ? o_.damping[m] / model.me : 0.0;
      if (!(lambda > 0.5 * c)) continue;
      return "the gear pair is parametrically unstable: at t = " + formatNumber(t) +
             " s its mesh frequency " + formatNumber(f) +
             " Hz lies in an instability region of the mesh stiffness (Floquet growth rate " +
             formatNumber(lambda) +
             " 1/s beyond the damping's decay C/2 = " + formatNumber(0.5 * c) +
             " 1/s), so the DTE grows without bound in the model itself "
             "and diverged at t = " +
             formatNumber(o_.time[n]) +
             " s whatever the time step: choose another speed, more damping or a smaller "
             "stiffness variation";
    }
    return "";
  }

  const SimConfig& cfg_;
  const SimulationOptions& so_;
  SignalTable& o_;
  const Eigen::Index n_samples_;
  const double fs_, dt_, t_last_;
  const MeshStiffness stiffness_;
  const StaticTransmissionError ste_;
  const int m_;
  const double h_;
  const bool pc_, fast_, torsional_;
  std::optional<Model> model_;
  std::vector<double> bps_;
  std::vector<double>::const_iterator bp_;
  std::vector<double> T_, U_, Kh_;
  RotationTable rotation_;          // the sine load's, for T_'s half-step grid
  RotationTable fourier_rotation_;  // the Fourier stiffness's, for Kh_
  AffineBlock maps_;
  SdofState s_, q_;
  Eigen::Index first_bad_ = -1;  // first sample of the first block holding a bad sample
  double ff_ = 0.0, inv_me_ = 0.0, du_ = 0.0;
  double r1_ = 0.0, r2_ = 0.0, j1_ = 0.0, j2_ = 0.0, q_gain_ = 0.0, det_ = 0.0;
};

}  // namespace

Status simulate(const SimConfig& cfg, SignalTable* out) {
  if (Status s = cfg.check(); !s.ok()) return s;
  Simulation run(cfg, out);
  if (Status s = run.setUp(); !s.ok()) return s;
  constexpr Eigen::Index kBlock = Simulation::kBlock;
  for (Eigen::Index n0 = 0; n0 + 1 < run.samples(); n0 += kBlock)
    run.integrateBlock(n0, std::min(run.samples() - 1, n0 + kBlock));
  return run.finish();
}

}  // namespace gear_sim
