#include "gear_damping_id/output_error.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <utility>
#include <vector>

#include "gear_damping_id/damping_units.hpp"
#include "gear_damping_id/forward_model.hpp"
#include "gear_damping_id/quality_flags.hpp"
#include "gear_sim/sdof_integrator.hpp"
#include "gear_sim/signal_table.hpp"
#include "gear_sim/simd_clones.hpp"

namespace gear_damping_id {

namespace {

using Index = Eigen::Index;

// Roles of the unknowns of one segment's output-error problem.
// Basis: one unknown of a greybox fourier/table stiffness shape (K = sum theta_k b_k(phase)).
// Ste: one coefficient of the static transmission error (shared by the record).
enum class Role { Y0, V0, Theta0, Theta1, K0, DK, Basis, Ste };

constexpr int kMaxBasis = 2 * StiffnessShape::kMaxHarmonics + 1;  // >= StiffnessShape::kMaxNodes
constexpr int kMaxSte = SteRefinement::kMaxTerms;
// y0, v0, theta0, theta1, K0/dK or the shape's basis, the STE coefficients
constexpr int kMaxParams = 4 + kMaxBasis + kMaxSte;
constexpr int kMaxState = 2 + 2 * kMaxParams;
// Largest order of the autoregressive noise model fitted to the residuals: enough for the
// correlation of anti-aliasing filters and encoder interpolation, small against a segment.
constexpr int kMaxArOrder = 6;
// Outer rounds of (AR fit, prewhitened Gauss-Newton): the AR estimate from the residuals of a
// consistent estimate is itself consistent, so one refit after the first prewhitened solve is
// enough; the third round only runs when the coefficients still moved.
constexpr int kMaxNoiseRounds = 3;
constexpr double kArChangeTol = 1e-3;  // max |a_k| change that ends the rounds
// The curve shape test's variance leaves the torque-meter noise out (the square levels' carries
// it): it is not computed where that noise is more than this share of C's standard error (with
// 1 N*m on the Table 1 case the square score without it reached rms 1.5-2.0).
constexpr double kCurveTorqueShare = 0.5;

// An allocator whose resize leaves new elements default-initialised (doubles: not written). The
// fused passes' row buffers are written in full by the pass before they are read; zeroing them
// first cost about four instructions per element.
template <class T>
struct NoInitAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = NoInitAllocator<U>;
  };
  NoInitAllocator() = default;
  template <class U>
  NoInitAllocator(const NoInitAllocator<U>&) noexcept {}
  template <class U, class... A>
  void construct(U* p, A&&... a) {
    if constexpr (sizeof...(A) == 0) {
      ::new (static_cast<void*>(p)) U;
    } else {
      ::new (static_cast<void*>(p)) U(std::forward<A>(a)...);
    }
  }
};
using RowBuffer = std::vector<double, NoInitAllocator<double>>;

// Parameters of one segment: roles and values.
struct Params {
  int m = 0;
  Role role[kMaxParams];
  double theta0 = 0, theta1 = 0, K0 = 0, dK = 0, y0 = 0, v0 = 0;
  // C(t) = theta0 + theta1 (T1(t) - t_ref) [1/s]: t_ref = 0 for the load law; the segment's mean
  // torque for the within-segment variation test (theta0 is then C at the mean load).
  double t_ref = 0;
  int nb = 0, basis_first = 0;  // shape: basis unknowns are parameters basis_first..+nb
  double basis[kMaxBasis] = {0};
  int nste = 0, ste_first = 0;  // STE: coefficients are parameters ste_first..+nste
  double ste[kMaxSte] = {0};

  // The value of unknown k.
  double* slot(int k) {
    switch (role[k]) {
      case Role::Y0:
        return &y0;
      case Role::V0:
        return &v0;
      case Role::Theta0:
        return &theta0;
      case Role::Theta1:
        return &theta1;
      case Role::K0:
        return &K0;
      case Role::DK:
        return &dK;
      case Role::Ste:
        return &ste[k - ste_first];
      case Role::Basis:
        break;
    }
    return &basis[k - basis_first];
  }
};

constexpr int kMaxMaps = 4;  // distinct held K values per segment (square: 2)

// The parameter-independent look-ups of one damping segment [b, e) (SegmentSimulator::
// buildTable), made once and reused by every evaluation of the segment: the stage torques
// (sample values and interval midpoints) and, per sample interval, either the key of its held
// stiffness (known K, greybox mesh state) or kSplit for an interval stepped in parts by the
// generic path (a switch, kink or jump inside it, or more than kMaxMaps held values). A smooth
// stiffness keeps its three stage values per interval.
struct SegmentTable {
  static constexpr unsigned char kSplit = 255;
  Eigen::Index b = 0, e = 0;
  bool smooth = false;
  int n_keys = 0;
  double key_K[kMaxMaps] = {0}, key_sv[kMaxMaps] = {0};
  std::vector<double> T;           // per sample: the torque T1 [N*m]
  std::vector<double> T_mid;       // per interval: T1 at its midpoint
  std::vector<unsigned char> key;  // per interval
  std::vector<double> K3;          // smooth: K at u = 0, 0.5, 1 of every interval
  size_t intervals() const { return key.size(); }
};

// Integrates eq. (4) and its sensitivities over one damping segment with the forward model.
class SegmentSimulator {
 public:
  // `fast`: closed-form per-step affine maps where they apply (see run()).
  // `shape`: the greybox fourier/table stiffness shape (null: square levels or known K).
  // `ste`: the STE forcing K e (+ C e' in the relative form) and its coefficients' sensitivities
  // (null: none); always the generic RK4 step.
  SegmentSimulator(const ForwardModel& fm, bool fast, const StiffnessShape* shape,
                   const SteRefinement* ste = nullptr)
      : fm_(fm), fast_(fast), shape_(shape), ste_(ste) {}

  // Integrates over samples [b, e) from (p.y0, p.v0). Calls visit(n, z) for each sample with the
  // state z = (y, v, z_1, z_1', ..., z_m, z_m').
  template <class Visit>
  void run(Index b, Index e, const Params& p, int substeps, Visit&& visit) const {
    double z[kMaxState] = {0};
    const int D = initialState(p, z);
    visit(b, z);
    const double h = fm_.signal().dt;
    const bool grey = fm_.formulation() == Formulation::Greybox;
    const bool smooth = fm_.smoothStiffness(b);
    // Fast path: with K and the mesh state held on a whole sample interval, C constant (no load
    // law) and one step per sample, RK4 is an affine map of the state and the three stage
    // torques, z+ = M z + G T, the same for every such interval with the same K: formed once
    // (by stepping unit vectors) and applied in its block structure: the state x = (y, v) by
    // R x + Gx T, each sensitivity pair z_k by R z_k + S_k x + H_k T (S_k = H_k = 0 for the
    // initial-state sensitivities). Algebraically the same numbers as the RK4 step.
    if (shape_ != nullptr) {
      runShape(b, e, p, substeps, visit, z, D);
      return;
    }
    const bool fast = fast_ && !smooth && substeps == 1 && ste_ == nullptr && constantC(p);
    AffineMap maps[kMaxMaps];
    int n_maps = 0;
    for (Index j = b; j + 1 < e; ++j) {
      const double th = fm_.heldSplit(j);
      if (fast && th >= 1.0) {
        double sv = 0.0, Kc;
        if (grey) {
          sv = fm_.meshState(j, false);
          Kc = p.K0 + p.dK * sv;
        } else {
          Kc = fm_.knownStiffness(j, 0.0, false, b, e);
        }
        int im = 0;
        while (im < n_maps && !(maps[im].K == Kc && maps[im].sv == sv)) ++im;
        if (im == n_maps && n_maps < kMaxMaps) {
          maps[im] = affineMap(D, p, Kc, sv, h);
          ++n_maps;
        }
        if (im < n_maps) {
          const double T[3] = {fm_.torque(j, 0.0, b, e), fm_.torque(j, 0.5, b, e),
                               fm_.torque(j, 1.0, b, e)};
          maps[im].apply<0>(z, p.m, T);
          visit(j + 1, z);
          continue;
        }
      }
      genericInterval(j, th, b, e, p, substeps, smooth, z, D);
      visit(j + 1, z);
    }
  }

  struct AffineMap {
    double K = 0, sv = 0;
    double R[2][2], G[2][3];
    double S[kMaxParams][2][2], H[kMaxParams][2][3];
    bool coupled[kMaxParams];
    // M: the number of unknowns when fixed at compile time (0: m).
    template <int M>
    void apply(double* z, int m_dyn, const double* T) const {
      const int m = M > 0 ? M : m_dyn;
      const double y = z[0], v = z[1];
      z[0] = R[0][0] * y + R[0][1] * v + G[0][0] * T[0] + G[0][1] * T[1] + G[0][2] * T[2];
      z[1] = R[1][0] * y + R[1][1] * v + G[1][0] * T[0] + G[1][1] * T[1] + G[1][2] * T[2];
      for (int k = 0; k < m; ++k) {
        double* w = z + 2 + 2 * k;
        const double a = w[0], c = w[1];
        double n0 = R[0][0] * a + R[0][1] * c, n1 = R[1][0] * a + R[1][1] * c;
        if (coupled[k]) {
          n0 += S[k][0][0] * y + S[k][0][1] * v + H[k][0][0] * T[0] + H[k][0][1] * T[1] +
                H[k][0][2] * T[2];
          n1 += S[k][1][0] * y + S[k][1][1] * v + H[k][1][0] * T[0] + H[k][1][1] * T[1] +
                H[k][1][2] * T[2];
        }
        w[0] = n0, w[1] = n1;
      }
    }
  };

  // The affine maps of table t's held stiffness values at p (runTable's), into maps[0..n_keys):
  // false where they do not apply (a smooth stiffness, a load-varying C).
  bool heldMaps(const SegmentTable& t, const Params& p, AffineMap* maps) const {
    if (t.smooth || !constantC(p)) return false;
    const bool grey = fm_.formulation() == Formulation::Greybox;
    for (int k = 0; k < t.n_keys; ++k) {
      const double K = grey ? p.K0 + p.dK * t.key_sv[k] : t.key_K[k];
      maps[k] = affineMap(2 + 2 * p.m, p, K, t.key_sv[k], fm_.signal().dt);
    }
    return true;
  }

  // Interval i (from the segment's start) of table t stepped in parts by the generic RK4 (runTable
  // for a kSplit interval); z: the state and the p.m sensitivity pairs.
  void splitInterval(const SegmentTable& t, Index i, const Params& p, double* z) const {
    genericInterval(t.b + i, fm_.heldSplit(t.b + i), t.b, t.e, p, 1, t.smooth, z, 2 + 2 * p.m);
  }

  // Whether C is constant over the segment (no load-law unknown).
  static bool constantC(const Params& p) {
    for (int k = 0; k < p.m; ++k) {
      if (p.role[k] == Role::Theta1) return false;
    }
    return true;
  }

  // Whether runTable applies: the fast path, one step per sample, no shape and no STE.
  bool tableApplies(int substeps) const {
    return fast_ && substeps == 1 && shape_ == nullptr && ste_ == nullptr;
  }

  // The look-ups of segment [b, e) for runTable (the same values run() looks up per step).
  void buildTable(Index b, Index e, SegmentTable* t) const {
    const bool grey = fm_.formulation() == Formulation::Greybox;
    const Index n = std::max<Index>(e - b, 0), intervals = std::max<Index>(n - 1, 0);
    t->b = b, t->e = e;
    t->smooth = fm_.smoothStiffness(b);
    t->n_keys = 0;
    t->T.resize(n);
    t->T_mid.resize(intervals);
    t->key.assign(intervals, SegmentTable::kSplit);
    t->K3.resize(t->smooth ? 3 * intervals : 0);
    fillTorques(b, e, t);
    const std::vector<QuadratureBreak>& brk = fm_.breaks();
    auto bi = std::lower_bound(brk.begin(), brk.end(), b,
                               [](const QuadratureBreak& x, Index v) { return x.j < v; });
    for (Index j = b; j + 1 < e; ++j) {
      const Index i = j - b;
      while (bi != brk.end() && bi->j < j) ++bi;
      if (bi != brk.end() && bi->j == j && bi->th < 1.0) continue;  // stepped in parts
      if (t->smooth) {
        for (int q = 0; q < 3; ++q) t->K3[3 * i + q] = fm_.knownStiffness(j, 0.5 * q, false, b, e);
        t->key[i] = 0;
        continue;
      }
      const double sv = grey ? fm_.meshState(j, false) : 0.0;
      const double K = grey ? 0.0 : fm_.heldStiffness(j, false);
      int k = 0;
      while (k < t->n_keys && !(t->key_K[k] == K && t->key_sv[k] == sv)) ++k;
      if (k == t->n_keys && t->n_keys < kMaxMaps) t->key_K[k] = K, t->key_sv[k] = sv, ++t->n_keys;
      if (k < t->n_keys) t->key[i] = static_cast<unsigned char>(k);
    }
  }

  // The stage torques of [b, e) into t: T(j) and T(j + 1/2), fm_.torque's numbers; the interior
  // midpoints (ForwardModel::cubic's centred stencil j-1..j+2) in one loop with cubic's weights
  // and order of operations instead of a call per sample.
  void fillTorques(Index b, Index e, SegmentTable* t) const {
    const double* ch = fm_.signal().torque;
    const Index n = e - b;
    if (ch == nullptr || n < 4) {
      for (Index j = b; j < e; ++j) t->T[j - b] = fm_.torque(j, 0.0, b, e);
      for (Index j = b; j + 1 < e; ++j) t->T_mid[j - b] = fm_.torque(j, 0.5, b, e);
      return;
    }
    std::copy(ch + b, ch + e, t->T.begin());  // cubic at u = 0: the sample
    const auto& w = fm_.interiorMidpointWeights();
    const double w0 = w[0], w1 = w[1], w2 = w[2], w3 = w[3];
    double* mid = t->T_mid.data();
    const double* c = ch + b;  // c[i] = sample b + i
    mid[0] = fm_.torque(b, 0.5, b, e);
    for (Index i = 1; i + 2 < n; ++i)
      mid[i] = w0 * c[i - 1] + w1 * c[i] + w2 * c[i + 1] + w3 * c[i + 2];
    mid[n - 2] = fm_.torque(b + n - 2, 0.5, b, e);  // the last interval
  }

  // run() from the segment's table (same numbers): M the number of unknowns when fixed at
  // compile time (0: p.m). Held stiffness and constant C: the affine maps; otherwise the RK4
  // step with the tabled stage values; split intervals by the generic path.
  template <int M, class Visit>
  void runTable(const SegmentTable& t, const Params& p, Visit&& visit) const {
    const int m = M > 0 ? M : p.m;
    double z[kMaxState] = {0};
    const int D = initialState(p, z);
    visit(t.b, z);
    const double h = fm_.signal().dt;
    const bool grey = fm_.formulation() == Formulation::Greybox;
    const bool maps_ok = !t.smooth && constantC(p);
    AffineMap maps[kMaxMaps];
    auto heldK = [&](int k) { return grey ? p.K0 + p.dK * t.key_sv[k] : t.key_K[k]; };
    if (maps_ok) {
      for (int k = 0; k < t.n_keys; ++k) maps[k] = affineMap(D, p, heldK(k), t.key_sv[k], h);
    }
    const LinearRoles lr = linearRoles(p);
    const double* T = t.T.data();
    for (Index j = t.b; j + 1 < t.e; ++j) {
      const Index i = j - t.b;
      const unsigned char key = t.key[i];
      if (key == SegmentTable::kSplit) {
        genericInterval(j, fm_.heldSplit(j), t.b, t.e, p, 1, t.smooth, z, D);
      } else if (maps_ok) {
        const double Ts[3] = {T[i], t.T_mid[i], T[i + 1]};
        maps[key].apply<M>(z, m, Ts);
      } else {
        Stage st;
        st.T[0] = T[i], st.T[1] = t.T_mid[i], st.T[2] = T[i + 1];
        const double sv = tabledStiffness(t, static_cast<size_t>(i), p, &st);
        stepLinear<M>(z, m, p, lr, st, sv, h);
      }
      visit(j + 1, z);
    }
  }

  // The state-only RK4 step of every interval of segment t (p.m = 0, no load law: the response
  // to the torque, Refinement::torqueNoiseExact): x_{j+1} = A x_j + c (T_j, T_{j+1/2}, T_{j+1})
  // with the arithmetic of runTable's step (the affine map of the held stiffness, else the
  // tabled RK4 step on unit inputs); intervals stepped in parts (kSplit) are left untouched.
  struct StateMap {
    double A[2][2], c[2][3];
  };
  void stateMaps(const SegmentTable& t, const Params& p, std::vector<StateMap>* out) const {
    const double h = fm_.signal().dt;
    const bool grey = fm_.formulation() == Formulation::Greybox;
    const bool maps_ok = !t.smooth && constantC(p);
    auto heldK = [&](int k) { return grey ? p.K0 + p.dK * t.key_sv[k] : t.key_K[k]; };
    StateMap held[kMaxMaps];
    for (int k = 0; maps_ok && k < t.n_keys; ++k) {
      const AffineMap a = affineMap(2, p, heldK(k), t.key_sv[k], h);
      std::copy(&a.R[0][0], &a.R[0][0] + 4, &held[k].A[0][0]);
      std::copy(&a.G[0][0], &a.G[0][0] + 6, &held[k].c[0][0]);
    }
    const LinearRoles lr = linearRoles(p);
    out->resize(t.intervals());
    for (size_t i = 0; i < t.intervals(); ++i) {
      const unsigned char key = t.key[i];
      if (key == SegmentTable::kSplit) continue;
      if (maps_ok) {
        (*out)[i] = held[key];
        continue;
      }
      Stage st;
      const double sv = tabledStiffness(t, i, p, &st);
      for (int col = 0; col < 5; ++col) {  // unit state (2), unit stage torque (3)
        double z[2] = {col == 0 ? 1.0 : 0.0, col == 1 ? 1.0 : 0.0};
        for (int q = 0; q < 3; ++q) st.T[q] = col == 2 + q ? 1.0 : 0.0;
        stepLinear<0>(z, 0, p, lr, st, sv, h);
        for (int r = 0; r < 2; ++r) {
          if (col < 2)
            (*out)[i].A[r][col] = z[r];
          else
            (*out)[i].c[r][col - 2] = z[r];
        }
      }
    }
  }

  // Interval j of segment [b, e) by the generic RK4 (the state only: p.m = 0).
  void stepGeneric(Index j, Index b, Index e, const Params& p, double* z) const {
    genericInterval(j, fm_.heldSplit(j), b, e, p, 1, fm_.smoothStiffness(b), z, 2);
  }

 private:
  struct Stage {
    double K[3], T[3];               // at the step's start, midpoint and end
    const double* B[3] = {0, 0, 0};  // shape: the basis values there
    // STE: basis values and time derivatives there (E, dE of stage q in ste_buf_[q])
    const double* E[3] = {0, 0, 0};
    const double* dE[3] = {0, 0, 0};
  };

  // The tabled stiffness of interval i of segment t at its three stages into st->K; returns the
  // greybox mesh state (0 otherwise).
  double tabledStiffness(const SegmentTable& t, size_t i, const Params& p, Stage* st) const {
    if (t.smooth) {
      for (int q = 0; q < 3; ++q) st->K[q] = t.K3[3 * i + q];
      return 0.0;
    }
    const int key = t.key[i];
    const bool grey = fm_.formulation() == Formulation::Greybox;
    st->K[0] = st->K[1] = st->K[2] = grey ? p.K0 + p.dK * t.key_sv[key] : t.key_K[key];
    return grey ? t.key_sv[key] : 0.0;
  }

  // The STE basis and its time derivative at u of interval j into stage q of `st`: the mesh
  // phase is the local cubic of its samples, its rate the chord over up to 16 samples on either
  // side within the segment (the rigid rotation: smooth; the chord averages encoder noise).
  void steStage(Index j, double u, Index b, Index e, int q, Stage* st) const {
    const double* ph = fm_.signal().mesh_phase;
    const double phase = fm_.cubic(ph, j, u, b, e);
    const Index lo = std::max<Index>(b, j - 16), hi = std::min<Index>(e - 1, j + 17);
    const double rate = (ph[hi] - ph[lo]) / (static_cast<double>(hi - lo) * fm_.signal().dt);
    double* E = ste_buf_[q];
    double* dE = ste_buf_[q] + kMaxSte;
    ste_->basis.eval(phase, E, dE);
    for (int k = 0; k < ste_->basis.size(); ++k) dE[k] *= rate;
    st->E[q] = E;
    st->dE[q] = dE;
  }

  // The STE basis and its rate at the three stages u = 0, 1/2, 1 of a whole interval j of
  // segment [b, e) (steStage's values, which depend on no unknown), tabled per segment on first
  // use while the tables stay within kSteBudget doubles (rig records of tens of ms) (the evaluation
  // of a sine per harmonic, stage and iteration dominated the joint STE refinement); null beyond it
  // (computed per step).
  const double* steCached(Index j, Index b, Index e) const {
    constexpr size_t kSteBudget = size_t{1} << 22;  // doubles: 32 MB
    const int nb = ste_->basis.size();
    const size_t per = 6 * static_cast<size_t>(nb);  // 3 stages x (E, dE)
    auto it = ste_cache_.find(b);
    if (it == ste_cache_.end()) {
      const size_t need = static_cast<size_t>(std::max<Index>(e - b - 1, 0)) * per;
      if (ste_cached_ + need > kSteBudget) return nullptr;
      std::vector<double> tab(need);
      Stage st;
      for (Index i = b; i + 1 < e; ++i) {
        for (int q = 0; q < 3; ++q) {
          steStage(i, 0.5 * q, b, e, q, &st);
          double* dst = tab.data() + static_cast<size_t>(i - b) * per + 2 * nb * q;
          std::copy(st.E[q], st.E[q] + nb, dst);
          std::copy(st.dE[q], st.dE[q] + nb, dst + nb);
        }
      }
      ste_cached_ += need;
      it = ste_cache_.emplace(b, std::move(tab)).first;
    }
    return it->second.data() + static_cast<size_t>(j - b) * per;
  }

  // Greybox fourier/table shape: K(t) = sum_k theta_k b_k(u(t)) with the mesh phase u(t) the
  // local cubic of the mesh_phase samples; each interval split where u crosses a table node
  // (a kink of every table basis function), each part by `substeps` RK4 steps.
  template <class Visit>
  void runShape(Index b, Index e, const Params& p, int substeps, Visit& visit, double* z,
                int D) const {
    const double h = fm_.signal().dt;
    const double* ph = fm_.signal().mesh_phase;
    const bool table = shape_->kind == StiffnessShape::Kind::Table;
    const double nodes = shape_->n;
    double B[3][kMaxBasis];
    auto stageAt = [&](Index j, double u, int q, Stage* st) {
      const double phase = fm_.cubic(ph, j, u, b, e);
      shape_->basis(phase, B[q]);
      double K = 0.0;
      for (int k = 0; k < p.nb; ++k) K += p.basis[k] * B[q][k];
      st->K[q] = K;
      st->T[q] = fm_.torque(j, u, b, e);
      st->B[q] = B[q];
    };
    for (Index j = b; j + 1 < e; ++j) {
      double th = 1.0;
      if (table && ph[j + 1] > ph[j]) {
        const double c = std::floor(ph[j] * nodes) + 1.0;  // next node after ph[j], in nodes
        const double x = (c / nodes - ph[j]) / (ph[j + 1] - ph[j]);
        if (x > 0.0 && x < 1.0) th = x;
      }
      const double parts[2][2] = {{0.0, th}, {th, 1.0}};
      for (int piece = 0; piece < 2; ++piece) {
        const double u0 = parts[piece][0], u1 = parts[piece][1];
        if (!(u1 > u0)) continue;
        const double du = (u1 - u0) / substeps;
        for (int q = 0; q < substeps; ++q) {
          const double ua = u0 + q * du, ub = q + 1 == substeps ? u1 : ua + du;
          Stage st;
          stageAt(j, ua, 0, &st);
          stageAt(j, 0.5 * (ua + ub), 1, &st);
          stageAt(j, ub, 2, &st);
          step(z, D, p, st, 0.0, h * (ub - ua));
        }
      }
      visit(j + 1, z);
    }
  }
  // The initial state (p.y0, p.v0) and the unit sensitivities of the initial-state unknowns
  // into z; returns its dimension.
  static int initialState(const Params& p, double* z) {
    const int D = 2 + 2 * p.m;
    std::fill(z, z + D, 0.0);
    z[0] = p.y0, z[1] = p.v0;
    for (int k = 0; k < p.m; ++k) {
      if (p.role[k] == Role::Y0) z[2 + 2 * k] = 1.0;
      if (p.role[k] == Role::V0) z[3 + 2 * k] = 1.0;
    }
    return D;
  }

  // Interval j by the generic RK4, in two parts at its split fraction th (1: one part), each by
  // `substeps` steps with the coefficients looked up at the stage times.
  void genericInterval(Index j, double th, Index b, Index e, const Params& p, int substeps,
                       bool smooth, double* z, int D) const {
    const double h = fm_.signal().dt;
    const bool grey = fm_.formulation() == Formulation::Greybox;
    const double parts[2][2] = {{0.0, th}, {th, 1.0}};
    for (int piece = 0; piece < 2; ++piece) {
      const double u0 = parts[piece][0], u1 = parts[piece][1];
      if (!(u1 > u0)) continue;
      const bool right = piece == 1;
      double sv = 0.0, Kc = 0.0;
      if (grey) {
        sv = fm_.meshState(j, right);
        Kc = p.K0 + p.dK * sv;
      } else if (!smooth) {
        Kc = fm_.heldStiffness(j, right);
      }
      const double du = (u1 - u0) / substeps;
      for (int q = 0; q < substeps; ++q) {
        const double ua = u0 + q * du, ub = q + 1 == substeps ? u1 : ua + du;
        const double um = 0.5 * (ua + ub);
        Stage st;
        st.T[0] = fm_.torque(j, ua, b, e);
        st.T[1] = fm_.torque(j, um, b, e);
        st.T[2] = fm_.torque(j, ub, b, e);
        if (ste_ != nullptr) {
          const double* cached = ua == 0.0 && ub == 1.0 ? steCached(j, b, e) : nullptr;
          const double u3[3] = {ua, um, ub};
          for (int s = 0; s < 3; ++s) {
            if (cached != nullptr) {
              st.E[s] = cached + 2 * ste_->basis.size() * s;
              st.dE[s] = st.E[s] + ste_->basis.size();
            } else {
              steStage(j, u3[s], b, e, s, &st);
            }
          }
        }
        if (smooth) {
          st.K[0] = fm_.knownStiffness(j, ua, right, b, e);
          st.K[1] = fm_.knownStiffness(j, um, right, b, e);
          st.K[2] = fm_.knownStiffness(j, ub, right, b, e);
        } else {
          st.K[0] = st.K[1] = st.K[2] = Kc;
        }
        step(z, D, p, st, sv, h * (ub - ua));
      }
    }
  }

  // The affine map of one RK4 step of length h with K and the mesh state sv held.
  AffineMap affineMap(int D, const Params& p, double K, double sv, double h) const {
    AffineMap a;
    a.K = K, a.sv = sv;
    Stage st;
    st.K[0] = st.K[1] = st.K[2] = K;
    double col[kMaxState];
    auto stepOf = [&](int unit_state, int unit_torque) {
      std::fill(col, col + D, 0.0);
      if (unit_state >= 0) col[unit_state] = 1.0;
      for (int q = 0; q < 3; ++q) st.T[q] = q == unit_torque ? 1.0 : 0.0;
      step(col, D, p, st, sv, h);
    };
    for (int c = 0; c < 2; ++c) {  // columns of x
      stepOf(c, -1);
      a.R[0][c] = col[0], a.R[1][c] = col[1];
      for (int k = 0; k < p.m; ++k) a.S[k][0][c] = col[2 + 2 * k], a.S[k][1][c] = col[3 + 2 * k];
    }
    for (int q = 0; q < 3; ++q) {  // stage torques
      stepOf(-1, q);
      a.G[0][q] = col[0], a.G[1][q] = col[1];
      for (int k = 0; k < p.m; ++k) a.H[k][0][q] = col[2 + 2 * k], a.H[k][1][q] = col[3 + 2 * k];
    }
    for (int k = 0; k < p.m; ++k) {
      a.coupled[k] = p.role[k] != Role::Y0 && p.role[k] != Role::V0;
    }
    return a;
  }

  // One RK4 step of length hs with the coefficients at the stage times.
  void step(double* z, int D_in, const Params& p, const Stage& st, double sv, double hs) const {
    const int D = std::max(D_in, 2);  // the state (y, v) always
    double k1[kMaxState], k2[kMaxState], k3[kMaxState], k4[kMaxState], tmp[kMaxState];
    deriv(z, D, p, st.K[0], sv, st.T[0], st.B[0], st.E[0], st.dE[0], k1);
    for (int i = 0; i < D; ++i) tmp[i] = z[i] + 0.5 * hs * k1[i];
    deriv(tmp, D, p, st.K[1], sv, st.T[1], st.B[1], st.E[1], st.dE[1], k2);
    for (int i = 0; i < D; ++i) tmp[i] = z[i] + 0.5 * hs * k2[i];
    deriv(tmp, D, p, st.K[1], sv, st.T[1], st.B[1], st.E[1], st.dE[1], k3);
    for (int i = 0; i < D; ++i) tmp[i] = z[i] + hs * k3[i];
    deriv(tmp, D, p, st.K[2], sv, st.T[2], st.B[2], st.E[2], st.dE[2], k4);
    for (int i = 0; i < D; ++i) z[i] += hs / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
  }

  // The sensitivities' forcing without an STE or shape basis, -(cv v + cy y) at a stage, as
  // weights of the roles: cv = v0 + v1 (T1 - t_ref) (theta0, theta1), cy = y0 + y1 sv (K0, dK).
  struct LinearRoles {
    double v0[kMaxParams], v1[kMaxParams], y0[kMaxParams], y1[kMaxParams];
  };
  static LinearRoles linearRoles(const Params& p) {
    LinearRoles lr;
    for (int k = 0; k < p.m; ++k) {
      lr.v0[k] = p.role[k] == Role::Theta0 ? 1.0 : 0.0;
      lr.v1[k] = p.role[k] == Role::Theta1 ? 1.0 : 0.0;
      lr.y0[k] = p.role[k] == Role::K0 ? 1.0 : 0.0;
      lr.y1[k] = p.role[k] == Role::DK ? 1.0 : 0.0;
    }
    return lr;
  }

  // step() of the state and sensitivities without an STE or shape basis (the same arithmetic
  // per element): the state's RK4 first, keeping its four stage values, then each sensitivity
  // pair's RK4 with the forcing -(cv v_s + cy y_s) of those stages (weights lr). M: the number
  // of unknowns when fixed at compile time (0: m_dyn).
  template <int M>
  void stepLinear(double* z, int m_dyn, const Params& p, const LinearRoles& lr, const Stage& st,
                  double sv, double hs) const {
    const int m = M > 0 ? M : m_dyn;
    const double K[4] = {st.K[0], st.K[1], st.K[1], st.K[2]};
    const double T[4] = {st.T[0], st.T[1], st.T[1], st.T[2]};
    const double ff = fm_.gear().force_factor;
    double dT[4], C[4], F[4], ys[4], vs[4];
    for (int q = 0; q < 4; ++q) {
      dT[q] = T[q] - p.t_ref;
      C[q] = p.theta0 + p.theta1 * dT[q];
      F[q] = ff * T[q];
    }
    rk4Pair(z, F, C, K, hs, ys, vs);
    for (int k = 0; k < m; ++k) {
      const double cy = lr.y0[k] + lr.y1[k] * sv;
      double f[4];
      for (int q = 0; q < 4; ++q) f[q] = -((lr.v0[k] + lr.v1[k] * dT[q]) * vs[q] + cy * ys[q]);
      rk4Pair(z + 2 + 2 * k, f, C, K, hs, nullptr, nullptr);
    }
  }

  // RK4 of one pair (a, b)' = (b, f_q - C_q b - K_q a) with the stage values f, C, K (stages 2
  // and 3 at the midpoint); the four stage values of (a, b) into ys, vs (null: not kept).
  static void rk4Pair(double* w, const double* f, const double* C, const double* K, double hs,
                      double* ys, double* vs) {
    const double h2 = 0.5 * hs, a = w[0], b = w[1];
    double ka[4], kb[4], ta = a, tb = b;
    for (int q = 0; q < 4; ++q) {
      if (ys != nullptr) ys[q] = ta, vs[q] = tb;
      ka[q] = tb;
      kb[q] = f[q] - C[q] * tb - K[q] * ta;
      const double hq = q < 2 ? h2 : hs;
      ta = a + hq * ka[q], tb = b + hq * kb[q];
    }
    const double h6 = hs / 6.0;
    w[0] = a + h6 * (ka[0] + 2.0 * ka[1] + 2.0 * ka[2] + ka[3]);
    w[1] = b + h6 * (kb[0] + 2.0 * kb[1] + 2.0 * kb[2] + kb[3]);
  }

  // y'' = F - C (y' - e'_r) - K (y - e): e the STE (0 without), e'_r its rate in the relative
  // damping form (0 in the dte form or without an STE).
  void deriv(const double* z, int D, const Params& p, double K, double sv, double T1,
             const double* B, const double* E, const double* dE, double* dz) const {
    const double C = p.theta0 + p.theta1 * (T1 - p.t_ref);
    const double F = fm_.gear().force_factor * T1;
    const double y = z[0], v = z[1];
    double e = 0.0, de = 0.0;
    if (E != nullptr) {
      for (int j = 0; j < p.nste; ++j) e += p.ste[j] * E[j], de += p.ste[j] * dE[j];
      if (!ste_->relative) de = 0.0;
    }
    const double vr = v - de, yr = y - e;
    dz[0] = v;
    dz[1] = F - C * vr - K * yr;
    for (int k = 0, i = 2; i < D; ++k, i += 2) {
      double forcing = 0.0;
      switch (p.role[k]) {
        case Role::Theta0:
          forcing = -vr;
          break;
        case Role::Theta1:
          forcing = -(T1 - p.t_ref) * vr;
          break;
        case Role::K0:
          forcing = -yr;
          break;
        case Role::DK:
          forcing = -sv * yr;
          break;
        case Role::Basis:
          forcing = -B[k - p.basis_first] * y;
          break;
        case Role::Ste:
          forcing = K * E[k - p.ste_first];
          if (ste_->relative) forcing += C * dE[k - p.ste_first];
          break;
        default:
          break;
      }
      dz[i] = z[i + 1];
      dz[i + 1] = forcing - C * z[i + 1] - K * z[i];
    }
  }

  const ForwardModel& fm_;
  bool fast_;
  const StiffnessShape* shape_;
  const SteRefinement* ste_;
  mutable double ste_buf_[3][2 * kMaxSte];  // steStage: E and dE of the three stages
  mutable std::map<Index, std::vector<double>> ste_cache_;  // steCached: by the segment's start
  mutable size_t ste_cached_ = 0;
};

// Substeps per sample so that omega * h_step <= 0.1 (RK4 error well below the bars).
int substepsFor(double omega, double dt) {
  return std::max(1, static_cast<int>(std::ceil(omega * dt / 0.1)));
}

// Autoregressive model of the measurement noise: the innovation (whitened residual) is
// e_n = r_n + sum_{k=1..p} a_k r_{n-k}. p = 0 is white noise.
struct NoiseModel {
  int p = 0;
  double a[kMaxArOrder] = {0};
};

// AR(p) fit by Levinson-Durbin on the pooled autocovariance r[0..kMaxArOrder] of `count`
// residuals; the order minimises the Bayesian information criterion (white noise: p = 0 unless
// a coefficient is several standard errors, sqrt(1/count), from zero).
NoiseModel fitNoiseModel(const double* acov, double count) {
  NoiseModel best;
  if (!(acov[0] > 0.0) || !(count > 4.0 * kMaxArOrder)) return best;
  double a[kMaxArOrder + 1] = {1.0}, tmp[kMaxArOrder + 1];
  double err = acov[0];
  double best_bic = count * std::log(err);
  for (int p = 1; p <= kMaxArOrder; ++p) {
    double acc = acov[p];
    for (int k = 1; k < p; ++k) acc += a[k] * acov[p - k];
    const double refl = -acc / err;
    if (!(std::abs(refl) < 1.0)) break;
    std::copy(a, a + p, tmp);
    for (int k = 1; k < p; ++k) a[k] = tmp[k] + refl * tmp[p - k];
    a[p] = refl;
    err *= 1.0 - refl * refl;
    const double bic = count * std::log(err) + p * std::log(count);
    if (bic < best_bic) {
      best_bic = bic;
      best.p = p;
      for (int k = 1; k <= p; ++k) best.a[k - 1] = a[k];
    }
  }
  return best;
}

double maxChange(const NoiseModel& x, const NoiseModel& y) {
  double d = x.p == y.p ? 0.0 : 1.0;
  for (int k = 0; k < kMaxArOrder; ++k) d = std::max(d, std::abs(x.a[k] - y.a[k]));
  return d;
}

// ----------------------------------------------------------------------------------------------
// The fused pass (issue 18): one evaluation of a segment's prewhitened normal equations in a
// single loop, the state in scalars and the sensitivity pairs as lanes of AVX2 vectors (on the
// held-stiffness path they share the step matrix R): step, residual, AR prewhitening and the
// Gram of the whitened row, without storing the rows; the residual's autocovariances after the
// loop from the residuals kept in reverse order. Every element is computed with the operations
// of runTable + Accumulator in their order (no reassociation) and the sums run in sample order;
// the baseline clone gives their bits, the x86-64-v3 and v4 clones contract multiply-adds (FMA),
// the same numbers to rounding (~1e-16 per step; refine_fast_path_test holds the fast path to the
// generic RK4 at 1e-9). Intervals stepped in parts call back into the generic RK4.

// The passes are compiled for x86-64-v4 (AVX-512: the same code, the v3 clone's bits, more
// registers) and x86-64-v3 (AVX2 + FMA) as well as the baseline, chosen at load time
// (GEAR_FMA_CLONES, gear_sim/simd_clones.hpp; other compilers build the baseline), their
// helpers inlined into each clone. On one machine every run takes the same clone, so results do
// not depend on the run.
#define GD_FUSED_INLINE inline __attribute__((always_inline))

constexpr int kFusedLanes = 8;  // sensitivities of the fused pass (two vectors of four)
typedef double V4d __attribute__((vector_size(32)));  // a GCC vector: one AVX or two SSE2 registers
// The same at any double's address: stores of kept rows straight from the registers (a memcpy
// went through the stack in two halves, whose reload stalled the pass).
typedef double V4dU __attribute__((vector_size(32), aligned(8), may_alias));

// One held value's affine step in lanes: x+ = R x + G T (the state), and for sensitivity k
// z_k+ = R z_k + S_k x + H_k T (zero S, H for the initial-state unknowns).
struct FusedMap {
  double R[2][2], G[2][3];
  V4d Rv[2][2];    // R broadcast (the lanes' products read it from memory, no broadcast per step)
  V4d S[2][2][2];  // [row][y, v][lanes k / 4]
  V4d H[2][3][2];  // [row][stage][lanes k / 4]
};

struct FusedPass {
  // In: the maps and keys of the segment's intervals (SegmentTable::kSplit: split(i) steps it),
  // the stage torques, the measured y of its n samples, the noise model and the initial state.
  const FusedMap* maps = nullptr;
  const unsigned char* key = nullptr;
  const double *T = nullptr, *T_mid = nullptr, *y = nullptr;
  Index n = 0;
  NoiseModel nm;
  double x[2] = {0, 0};
  alignas(32) double s[2][kFusedLanes] = {{0}};  // sensitivity k: (s[0][k], s[1][k])
  void (*split)(const void* ctx, Index i, double* x, double (*s)[kFusedLanes]) = nullptr;
  const void* ctx = nullptr;
  double* rrev = nullptr;  // n + 8: the residuals in reverse order, then zeros
  double* keep = nullptr;  // null or n x 4 (m / 4 + 1): the raw rows (r, J) (fusedRow)
  // The RK4 step in lanes (fusedPassImpl<M, false>: a smooth stiffness or a load-varying C, as
  // SegmentSimulator::stepLinear): K of the held keys (with the greybox mesh state) or three
  // stage values per interval, C = theta0 + theta1 (T1 - t_ref), F = ff T1, and the weights of
  // the sensitivities' forcing -((v0 + v1 (T1 - t_ref)) v + (y0 + y1 sv) y) in lanes.
  const double* K3 = nullptr;
  double key_K[kMaxMaps] = {0}, key_sv[kMaxMaps] = {0};
  double theta0 = 0, theta1 = 0, t_ref = 0, ff = 0, h = 0;
  V4d lv0[2] = {}, lv1[2] = {}, ly0[2] = {}, ly1[2] = {};
  // Out: sums over the whitened rows (rhs_k = sum J_k e, N = sum J J^T) and the raw residual's.
  alignas(32) double N[kFusedLanes][kFusedLanes], rhs[kFusedLanes];
  double cost = 0, wlag = 0, acov[8] = {0};  // acov[0]: sum r^2
  long rows = 0;
};

// SegmentSimulator::stepLinear of interval i in lanes: the state's RK4 (rk4Pair) keeping its
// stage values, then every sensitivity pair's with the forcing of those stages.
template <int V>
GD_FUSED_INLINE void fusedLinearStep(const FusedPass* f, Index i, unsigned char key, double* y,
                                     double* vel, V4d* a, V4d* c) {
  double K[4], sv = 0.0;
  if (f->K3 != nullptr) {
    K[0] = f->K3[3 * i], K[1] = K[2] = f->K3[3 * i + 1], K[3] = f->K3[3 * i + 2];
  } else {
    K[0] = K[1] = K[2] = K[3] = f->key_K[key];
    sv = f->key_sv[key];
  }
  const double T[4] = {f->T[i], f->T_mid[i], f->T_mid[i], f->T[i + 1]};
  const double hs = f->h, h2 = 0.5 * hs, h6 = hs / 6.0;
  double dT[4], C[4], ys[4], vs[4];
  {
    const double y0 = *y, v0 = *vel;
    double ka[4], kb[4], ta = y0, tb = v0;
    for (int q = 0; q < 4; ++q) {
      dT[q] = T[q] - f->t_ref;
      C[q] = f->theta0 + f->theta1 * dT[q];
      ys[q] = ta, vs[q] = tb;
      ka[q] = tb;
      kb[q] = f->ff * T[q] - C[q] * tb - K[q] * ta;
      const double hq = q < 2 ? h2 : hs;
      ta = y0 + hq * ka[q], tb = v0 + hq * kb[q];
    }
    *y = y0 + h6 * (ka[0] + 2.0 * ka[1] + 2.0 * ka[2] + ka[3]);
    *vel = v0 + h6 * (kb[0] + 2.0 * kb[1] + 2.0 * kb[2] + kb[3]);
  }
  for (int v = 0; v < V; ++v) {
    const V4d cy = f->ly0[v] + f->ly1[v] * sv, a0 = a[v], b0 = c[v];
    V4d ka[4], kb[4], ta = a0, tb = b0;
    for (int q = 0; q < 4; ++q) {
      const V4d fq = -((f->lv0[v] + f->lv1[v] * dT[q]) * vs[q] + cy * ys[q]);
      ka[q] = tb;
      kb[q] = fq - C[q] * tb - K[q] * ta;
      const double hq = q < 2 ? h2 : hs;
      ta = a0 + hq * ka[q], tb = b0 + hq * kb[q];
    }
    a[v] = a0 + h6 * (ka[0] + 2.0 * ka[1] + 2.0 * ka[2] + ka[3]);
    c[v] = b0 + h6 * (kb[0] + 2.0 * kb[1] + 2.0 * kb[2] + kb[3]);
  }
}

// The affine step of a held interval (FusedMap) with stage torques T0, T1 (midpoint), T2, in
// AffineMap::apply's order of operations (the same numbers).
template <int V>
GD_FUSED_INLINE void fusedAffineStep(const FusedMap& mp, double T0, double T1, double T2, double* y,
                                     double* vel, V4d* a, V4d* c) {
  const double y0 = *y, v0 = *vel;
  for (int v = 0; v < V; ++v) {
    const V4d f0 = mp.S[0][0][v] * y0 + mp.S[0][1][v] * v0 + mp.H[0][0][v] * T0 +
                   mp.H[0][1][v] * T1 + mp.H[0][2][v] * T2;
    const V4d f1 = mp.S[1][0][v] * y0 + mp.S[1][1][v] * v0 + mp.H[1][0][v] * T0 +
                   mp.H[1][1][v] * T1 + mp.H[1][2][v] * T2;
    const V4d na = mp.Rv[0][0] * a[v] + mp.Rv[0][1] * c[v] + f0;
    c[v] = mp.Rv[1][0] * a[v] + mp.Rv[1][1] * c[v] + f1;
    a[v] = na;
  }
  *y = mp.R[0][0] * y0 + mp.R[0][1] * v0 + mp.G[0][0] * T0 + mp.G[0][1] * T1 + mp.G[0][2] * T2;
  *vel = mp.R[1][0] * y0 + mp.R[1][1] * v0 + mp.G[1][0] * T0 + mp.G[1][1] * T1 + mp.G[1][2] * T2;
}

// *out = {lo[3], hi[0], hi[1], hi[2]}.
GD_FUSED_INLINE void shiftIn(const V4d& lo, const V4d& hi, V4d* out) {
#if defined(__clang__)
  *out = __builtin_shufflevector(lo, hi, 3, 4, 5, 6);
#else
  typedef long I4 __attribute__((vector_size(32)));
  *out = __builtin_shuffle(lo, hi, I4{3, 4, 5, 6});
#endif
}

// The raw row (r, J_1..J_M) of a sample in W = M / 4 + 1 vectors from the residual and the
// sensitivities in lanes (a).
template <int M>
GD_FUSED_INLINE void fusedRow(double r, const V4d* a, V4d* w) {
  constexpr int V = (M + 3) / 4, W = M / 4 + 1;
  const V4d rb = {r, r, r, r}, zero = {0, 0, 0, 0};
  shiftIn(rb, a[0], &w[0]);
  for (int v = 1; v < W; ++v) shiftIn(a[v - 1], v < V ? a[v] : zero, &w[v]);
}

// The whitened rows' sums of a pass (fusedPassImpl, fusedRowsImpl): add() takes the raw row
// w = (r, J_1..J_M) of sample i in sample order; Nv[q] sums e e_q (e the whitened row): lane 0
// of Nv[0] the cost, Nv[0] the right-hand side, Nv[1..M] the normal matrix.
template <int M>
struct FusedSums {
  static constexpr int W = M / 4 + 1;
  V4d Nv[M + 1][W];
  double wlag = 0.0, eprev = 0.0;
  long rows = 0;

  GD_FUSED_INLINE FusedSums() {
    const V4d zero = {0, 0, 0, 0};
    for (int v = 0; v < W; ++v) {
      for (int q = 0; q <= M; ++q) Nv[q][v] = zero;
    }
  }

  // ring: 16 x W vectors, zero at first: the raw rows of the last 8 samples, twice. P: the AR
  // order nm.p when fixed at compile time (-1: nm.p).
  template <int P = -1>
  GD_FUSED_INLINE void add(const NoiseModel& nm, Index i, const V4d* w, V4d* ring) {
    accumulate<P>(nm, i, w, ring, Nv, wlag, eprev, rows);
  }

  // add() on sums held elsewhere (fusedSpan's locals, kept in registers).
  template <int P = -1>
  static GD_FUSED_INLINE void accumulate(const NoiseModel& nm, Index i, const V4d* w, V4d* ring,
                                         V4d (*Nv)[W], double& wlag, double& eprev, long& rows) {
    const int order = P >= 0 ? P : nm.p;
    V4d e[W];
    for (int v = 0; v < W; ++v) e[v] = w[v];
    if (order > 0) {  // e = w_i + a_1 w_{i-1} + ... + a_p w_{i-p} in this order
      V4d* slot = ring + (i & 7) * W;
      for (int v = 0; v < W; ++v) slot[v] = slot[v + 8 * W] = w[v];
      if (i < order) return;
      const V4d* prev = slot + 7 * W;
      for (int k = 0; k < order; ++k) {
        const double ak = nm.a[k];
        for (int v = 0; v < W; ++v) e[v] += ak * prev[v - k * W];
      }
    }
    const double e0 = e[0][0];
    wlag += e0 * eprev;  // eprev = 0 before the first row (a branch here went through memory)
    eprev = e0;
    ++rows;
    for (int q = 0; q <= M; ++q) {
      const double eq = e[q / 4][q % 4];
      for (int v = 0; v < W; ++v) {
        if (q >= 4 * v) Nv[q][v] += e[v] * eq;  // the others by symmetry (gram())
      }
    }
  }

  // The sum of e_a e_b: Nv[a] holds the columns b of its vectors v with a >= 4 v (accumulate(); the
  // same products in the same order as Nv[b]'s column a).
  GD_FUSED_INLINE double gram(int a, int b) const {
    return a >= 4 * (b / 4) ? Nv[a][b / 4][b % 4] : Nv[b][a / 4][a % 4];
  }

  // The sums into f, and the autocovariances (lag k in lane k: r_i times r_i, r_{i-1}, ... in
  // sample order) from the residuals f->rrev.
  GD_FUSED_INLINE void finish(FusedPass* f) const {
    const Index n = f->n;
    V4d acc_lo = {0, 0, 0, 0}, acc_hi = {0, 0, 0, 0};
    for (Index i = 0; i < n; ++i) {
      V4d lo, hi;
      std::memcpy(&lo, f->rrev + (n - 1 - i), sizeof(V4d));
      std::memcpy(&hi, f->rrev + (n + 3 - i), sizeof(V4d));
      const double r = lo[0];
      acc_lo += r * lo;
      acc_hi += r * hi;
    }
    for (int q = 0; q < M; ++q) {
      for (int k = 0; k < M; ++k) f->N[q][k] = gram(q + 1, k + 1);
    }
    for (int k = 0; k < M; ++k) f->rhs[k] = gram(0, k + 1);
    for (int k = 0; k < 4; ++k) f->acov[k] = acc_lo[k], f->acov[4 + k] = acc_hi[k];
    f->cost = Nv[0][0][0], f->wlag = wlag, f->rows = rows;
  }
};

// The state, the sensitivities in lanes and the sums of a pass between calls (fusedPassImpl).
template <int M>
struct FusedCarry {
  static constexpr int V = (M + 3) / 4, W = M / 4 + 1;
  V4d a[V], c[V];
  double y = 0.0, vel = 0.0;
  FusedSums<M> sums;
  V4d ring[16 * W] = {};
};

// The RK4 step's coefficients (fusedLinearStep) as a local copy of the pass (its reads then
// need no reload after each may_alias store of a kept row); nothing for the affine maps.
struct FusedNoCopy {};
template <bool Affine>
GD_FUSED_INLINE auto fusedLinearCopy(const FusedPass* f) {
  if constexpr (Affine) {
    return FusedNoCopy{};
  } else {
    return *f;
  }
}

// Samples i..end of a pass (rows i..end, intervals i..end - 1, none stepped in parts) in local
// copies of the carried values (kept in registers: no call, no address taken).
template <int M, bool Affine, int P>
GD_FUSED_INLINE void fusedSpan(const FusedPass* f, Index i, Index end, FusedCarry<M>* k) {
  constexpr int V = (M + 3) / 4, W = M / 4 + 1;
  V4d a[V], c[V];
  for (int v = 0; v < V; ++v) a[v] = k->a[v], c[v] = k->c[v];
  V4d Nv[M + 1][W];
  for (int q = 0; q <= M; ++q) {
    for (int v = 0; v < W; ++v) Nv[q][v] = k->sums.Nv[q][v];
  }
  double wlag = k->sums.wlag, eprev = k->sums.eprev;
  long rows = k->sums.rows;
  double y = k->y, vel = k->vel;
  const Index n = f->n;
  // The pass's inputs in locals: the kept rows' stores (may_alias) would otherwise make every
  // sample reload them from *f.
  const double *const ym = f->y, *const T = f->T, *const Tm = f->T_mid;
  double *const rrev = f->rrev, *const keep = f->keep;
  const unsigned char* const key = f->key;
  const FusedMap* const maps = f->maps;
  const NoiseModel nm = f->nm;
  [[maybe_unused]] const auto lin = fusedLinearCopy<Affine>(f);
  for (;; ++i) {
    const double r = ym[i] - y;
    rrev[n - 1 - i] = r;
    V4d w[W];
    fusedRow<M>(r, a, w);
    if (keep != nullptr) {
      V4dU* out = reinterpret_cast<V4dU*>(keep + 4 * W * i);
      for (int v = 0; v < W; ++v) out[v] = w[v];
    }
    FusedSums<M>::template accumulate<P>(nm, i, w, k->ring, Nv, wlag, eprev, rows);
    if (i == end) break;
    if constexpr (Affine) {
      fusedAffineStep<V>(maps[key[i]], T[i], Tm[i], T[i + 1], &y, &vel, a, c);
    } else {
      fusedLinearStep<V>(&lin, i, key[i], &y, &vel, a, c);
    }
  }
  for (int v = 0; v < V; ++v) k->a[v] = a[v], k->c[v] = c[v];
  for (int q = 0; q <= M; ++q) {
    for (int v = 0; v < W; ++v) k->sums.Nv[q][v] = Nv[q][v];
  }
  k->sums.wlag = wlag, k->sums.eprev = eprev, k->sums.rows = rows;
  k->y = y, k->vel = vel;
}

template <int M, bool Affine, int P = -1>
GD_FUSED_INLINE void fusedPassImpl(FusedPass* f) {
  constexpr int V = (M + 3) / 4;
  FusedCarry<M> k;
  std::memcpy(k.a, f->s[0], sizeof(k.a));
  std::memcpy(k.c, f->s[1], sizeof(k.c));
  k.y = f->x[0], k.vel = f->x[1];
  const Index n = f->n;
  for (Index i = 0;;) {
    // Up to the next interval stepped in parts (a call: the carried values through memory).
    Index end = i;
    while (end + 1 < n && f->key[end] != SegmentTable::kSplit) ++end;
    fusedSpan<M, Affine, P>(f, i, end, &k);
    if (end + 1 >= n) break;
    double x[2] = {k.y, k.vel};
    std::memcpy(f->s[0], k.a, sizeof(V4d) * V);
    std::memcpy(f->s[1], k.c, sizeof(V4d) * V);
    f->split(f->ctx, end, x, f->s);
    k.y = x[0], k.vel = x[1];
    std::memcpy(k.a, f->s[0], sizeof(V4d) * V);
    std::memcpy(k.c, f->s[1], sizeof(V4d) * V);
    i = end + 1;
  }
  k.sums.finish(f);
}

// The sums of the rows a pass kept (f->rrev, f->keep) under the noise model f->nm: the numbers
// of a new pass at the same unknowns.
template <int M, int P = -1>
GD_FUSED_INLINE void fusedRowsImpl(FusedPass* f) {
  constexpr int W = M / 4 + 1;
  FusedSums<M> sums;
  V4d ring[16 * W] = {};
  for (Index i = 0; i < f->n; ++i) {
    V4d w[W];
    std::memcpy(w, f->keep + 4 * W * i, sizeof(w));
    sums.template add<P>(f->nm, i, w, ring);
  }
  sums.finish(f);
}

// The passes by number of unknowns (3 to 6), affine maps or the RK4 step.
GEAR_FMA_CLONES void fusedAffine3(FusedPass* f) { fusedPassImpl<3, true>(f); }
GEAR_FMA_CLONES void fusedAffine4(FusedPass* f) { fusedPassImpl<4, true>(f); }
GEAR_FMA_CLONES void fusedAffine5(FusedPass* f) { fusedPassImpl<5, true>(f); }
GEAR_FMA_CLONES void fusedAffine6(FusedPass* f) { fusedPassImpl<6, true>(f); }
GEAR_FMA_CLONES void fusedLinear3(FusedPass* f) { fusedPassImpl<3, false>(f); }
GEAR_FMA_CLONES void fusedLinear4(FusedPass* f) { fusedPassImpl<4, false>(f); }
GEAR_FMA_CLONES void fusedLinear5(FusedPass* f) { fusedPassImpl<5, false>(f); }
GEAR_FMA_CLONES void fusedLinear6(FusedPass* f) { fusedPassImpl<6, false>(f); }
GEAR_FMA_CLONES void fusedRows3(FusedPass* f) { fusedRowsImpl<3>(f); }
GEAR_FMA_CLONES void fusedRows4(FusedPass* f) { fusedRowsImpl<4>(f); }
GEAR_FMA_CLONES void fusedRows5(FusedPass* f) { fusedRowsImpl<5>(f); }
GEAR_FMA_CLONES void fusedRows6(FusedPass* f) { fusedRowsImpl<6>(f); }
// The known piecewise problem's passes by AR order P (the filter unrolled): kind (runFused) 1
// and 2 with 3 unknowns, the load test's 0 with 4.
template <int M, int Kind, int P>
GEAR_FMA_CLONES void fusedAr(FusedPass* f) {
  if constexpr (Kind == 2) {
    fusedRowsImpl<M, P>(f);
  } else {
    fusedPassImpl<M, Kind != 0, P>(f);
  }
}
using FusedOrders = std::array<void (*)(FusedPass*), kMaxArOrder + 1>;
template <int M, int Kind>
constexpr FusedOrders fusedOrders() {
  static_assert(kMaxArOrder == 6, "one pass per AR order 0..6");
  return {fusedAr<M, Kind, 0>, fusedAr<M, Kind, 1>, fusedAr<M, Kind, 2>, fusedAr<M, Kind, 3>,
          fusedAr<M, Kind, 4>, fusedAr<M, Kind, 5>, fusedAr<M, Kind, 6>};
}

// kind 0: the RK4 step, 1: the affine maps, 2: the kept rows.
void runFused(FusedPass* f, int m, int kind) {
  static void (*const kPass[3][4])(FusedPass*) = {
      {fusedLinear3, fusedLinear4, fusedLinear5, fusedLinear6},
      {fusedAffine3, fusedAffine4, fusedAffine5, fusedAffine6},
      {fusedRows3, fusedRows4, fusedRows5, fusedRows6}};
  static const FusedOrders kByOrder[3] = {fusedOrders<3, 1>(), fusedOrders<3, 2>(),
                                          fusedOrders<4, 0>()};
  const int row = m == 3   ? (kind == 1   ? 0
                              : kind == 2 ? 1
                                          : -1)
                  : m == 4 ? (kind == 0 ? 2 : -1)
                           : -1;
  if (row >= 0 && f->nm.p >= 0 && f->nm.p <= kMaxArOrder) {
    kByOrder[row][f->nm.p](f);
    return;
  }
  kPass[kind][m - 3](f);
}

}  // namespace

void curveExtremes(const StiffnessShape& shape, const std::vector<double>& curve, double* k_min,
                   double* k_max) {
  constexpr int kGrid = 720;
  std::vector<double> b(curve.size());
  *k_min = std::numeric_limits<double>::infinity();
  *k_max = -*k_min;
  for (int g = 0; g < kGrid; ++g) {
    shape.basis(static_cast<double>(g) / kGrid, b.data());
    double k = 0.0;
    for (size_t j = 0; j < b.size(); ++j) k += curve[j] * b[j];
    *k_min = std::min(*k_min, k), *k_max = std::max(*k_max, k);
  }
}

// The mesh state's switches over samples [b, e) (meshSwitches), in order.
struct MeshSwitch {
  double at;             // instant [samples]: its interval j plus fm.heldSplit(j)
  double u;              // the same from b: (j - b) plus fm.heldSplit(j)
  double before, after;  // states either side
};
std::vector<MeshSwitch> meshSwitches(const ForwardModel& fm, Index b, Index e) {
  const double* st = fm.signal().mesh_state;
  std::vector<MeshSwitch> sw;
  for (Index j = b; j + 1 < e; ++j) {
    if (st[j] == st[j + 1]) continue;
    const double split = fm.heldSplit(j);
    sw.push_back({static_cast<double>(j) + split, double(j - b) + split, st[j], st[j + 1]});
  }
  return sw;
}

// The greybox square model's response over samples [b, e) with its mesh state s(t) (0/1,
// switching at the breaks fm.heldSplit locates) and with s_w(t), the same state ramped linearly
// over `hw` samples either side of each switch: yhat_w - yhat at every sample into column 0 of
// *out; with t_ref finite also the sensitivity of yhat to C1 of C(t) = C + C1 (T1(t) - t_ref)
// (forcing -(T1 - t_ref) yhat', from rest) into column 1. RK4 over the pieces between the
// sample instants, the switches and the ramps' corners (K is constant or linear on each piece);
// x = [y0, v0, C, K0, dK] of the piecewise greybox problem; torque(j, u) the torque at u in
// [0, 1] of interval j; sw the switches over [b, e) (meshSwitches). These are directions of the
// shape test (Refinement::shapeScore), so their accuracy is not critical.
template <class Torque>
void rampedResponseChange(const ForwardModel& fm, Index b, Index e,
                          const std::vector<MeshSwitch>& sw, const Eigen::VectorXd& x, double hw,
                          double t_ref, Torque&& torque, Eigen::MatrixXd* out,
                          double c_slope = 0.0) {
  const double* st = fm.signal().mesh_state;
  const double C0 = x[2], K0 = x[3], dK = x[4], h = fm.signal().dt;
  const double ff = fm.gear().force_factor;
  const bool c1 = std::isfinite(t_ref);
  // z = [y, v, C1 sensitivity and its rate] of the square model; w = [y, v] of the ramped one.
  // C = C0 + c_slope T1 (a shared load law's; 0 otherwise).
  double z[4] = {x[0], x[1], 0.0, 0.0}, w[2] = {x[0], x[1]};
  auto deriv = [&](const double* q, double T, double K, bool sens, double* dq) {
    const double C = C0 + c_slope * T;
    dq[0] = q[1];
    dq[1] = ff * T - C * q[1] - K * q[0];
    if (sens) dq[2] = q[3], dq[3] = -(T - t_ref) * q[1] - C * q[3] - K * q[2];
  };
  auto rk4 = [&](double* q, int dim, const double* T, const double* K, double hs) {
    double k[4][4], t[4];
    const bool sens = dim == 4;
    deriv(q, T[0], K[0], sens, k[0]);
    for (int i = 0; i < dim; ++i) t[i] = q[i] + 0.5 * hs * k[0][i];
    deriv(t, T[1], K[1], sens, k[1]);
    for (int i = 0; i < dim; ++i) t[i] = q[i] + 0.5 * hs * k[1][i];
    deriv(t, T[1], K[1], sens, k[2]);
    for (int i = 0; i < dim; ++i) t[i] = q[i] + hs * k[2][i];
    deriv(t, T[2], K[2], sens, k[3]);
    for (int i = 0; i < dim; ++i)
      q[i] += hs / 6.0 * (k[0][i] + 2.0 * (k[1][i] + k[2][i]) + k[3][i]);
  };
  out->setZero(e - b, 2);
  size_t k0 = 0;    // the first switch whose ramp ends after the interval's start
  double cuts[16];  // 2 + 3 per switch, at most 4 switches
  for (Index j = b; j + 1 < e; ++j) {
    const double u0 = double(j - b), u1 = u0 + 1.0;
    while (k0 < sw.size() && sw[k0].u + hw <= u0) ++k0;
    const double s0 = k0 == 0 ? st[b] : sw[k0 - 1].after;  // the state before switch k0
    size_t k1 = k0;  // switches k0 .. k1-1 reach into the interval (at most 4 counted)
    while (k1 < sw.size() && k1 < k0 + 4 && sw[k1].u - hw < u1) ++k1;
    auto square = [&](double u) {
      double s = s0;
      for (size_t k = k0; k < k1; ++k) s = u >= sw[k].u ? sw[k].after : s;
      return s;
    };
    auto ramped = [&](double u) {
      for (size_t k = k0; k < k1; ++k) {
        const MeshSwitch& q = sw[k];
        if (std::abs(u - q.u) < hw)
          return q.before + (q.after - q.before) * (u - q.u + hw) / (2 * hw);
      }
      return square(u);
    };
    int nc = 0;
    cuts[nc++] = u0, cuts[nc++] = u1;
    for (size_t k = k0; k < k1; ++k) {
      for (double c : {sw[k].u - hw, sw[k].u, sw[k].u + hw}) {
        if (c > u0 && c < u1) cuts[nc++] = c;
      }
    }
    std::sort(cuts, cuts + nc);
    for (int q = 0; q + 1 < nc; ++q) {
      const double ua = cuts[q], ub = cuts[q + 1], um = 0.5 * (ua + ub);
      if (!(ub > ua)) continue;
      const double us[3] = {ua, um, ub}, Ksq = K0 + dK * square(um);
      double T[3], Kw[3];
      for (int k = 0; k < 3; ++k) {
        T[k] = torque(j, us[k] - u0);
        Kw[k] = k1 > k0 ? K0 + dK * ramped(us[k]) : Ksq;
      }
      const double Ks[3] = {Ksq, Ksq, Ksq};
      rk4(z, c1 ? 4 : 2, T, Ks, (ub - ua) * h);
      rk4(w, 2, T, Kw, (ub - ua) * h);
    }
    (*out)(j + 1 - b, 0) = w[0] - z[0];
    (*out)(j + 1 - b, 1) = z[2];
  }
}

double shapeStiffness(const StiffnessShape& shape, const std::vector<double>& curve, double phase) {
  double b[2 * StiffnessShape::kMaxHarmonics + 1];
  shape.basis(phase, b);
  double k = 0.0;
  for (size_t j = 0; j < curve.size(); ++j) k += curve[j] * b[j];
  return k;
}

double torqueNoiseEstimate(const double* torque, Index n) {
  if (torque == nullptr || n < 5) return kNaN;
  std::vector<double> d(static_cast<size_t>(n - 4));
  for (Index k = 0; k + 4 < n; ++k) {
    const double* t = torque + k;
    d[static_cast<size_t>(k)] = std::abs(t[0] - 4.0 * t[1] + 6.0 * t[2] - 4.0 * t[3] + t[4]);
  }
  auto mid = d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2);
  std::nth_element(d.begin(), mid, d.end());
  return 1.482602218505602 * *mid / std::sqrt(70.0);
}

bool wantsRefinement(const IdentificationOptions& o) {
  if (o.formulation != Formulation::Known && o.formulation != Formulation::Greybox) return false;
  return o.refine != IdentificationOptions::Refine::Never;
}

namespace {

// The output-error refinement of one result (refineOutputError), in named steps: the unknowns
// and their start values, the prewhitened normal equations of a segment, the Gauss-Newton
// iteration per problem and noise round, the covariances, and the result.
class Refinement {
 public:
  Refinement(const SignalView& s, const std::vector<std::pair<Index, Index>>& ranges,
             const GearConstants& gear, const IdentificationOptions& o, IdentificationResult* res,
             bool reference_integration, SteRefinement* ste)
      : s_(s),
        ranges_(ranges),
        o_(o),
        res_(res),
        ste_(ste),
        me_(gear.equivalent_mass),
        grey_(o.formulation == Formulation::Greybox),
        load_(o.model == DampingModel::LoadLaw),
        piecewise_(o.model == DampingModel::Piecewise),
        shape_(grey_ && o.stiffness_shape.kind != StiffnessShape::Kind::Square),
        nb_(shape_ ? o.stiffness_shape.unknowns() : 0),
        nseg_(ranges.size()),
        fm_(s, gear, o.formulation, ranges),
        sim_(fm_, !reference_integration && ste == nullptr, shape_ ? &o.stiffness_shape : nullptr,
             ste),
        substeps_(substepsFor(res->omega0, s.dt)),
        reference_(reference_integration) {}

  gear_sim::Status run() {
    setUnknowns();
    if (gear_sim::Status s = startValues(); !s.ok()) return s;
    torqueLevels();
    loadSteps();
    if (gear_sim::Status s = iterate(); !s.ok()) return s;
    if (gear_sim::Status s = covariances(); !s.ok()) return s;
    if (gear_sim::Status s = positiveVariances(); !s.ok()) return s;
    torqueNoise();
    glitchShifts();
    quantisationShifts();
    fillSegments();
    fillShared();
    return {};
  }

 private:
  // Normal equations of one segment at (x, g) for the prewhitened output error: with the
  // residual r_n = y_n - yhat_n and the sensitivities J_n = dyhat_n/dp filtered alike,
  // e_n = r_n + sum a_k r_{n-k} (from the segment's (p+1)-th sample on),
  // N = sum Je Je^T, rhs = sum Je e, cost = sum e^2; plus the raw residual's statistics.
  struct Normal {
    Eigen::MatrixXd N;
    Eigen::VectorXd rhs;
    double cost = 0;  // whitened sum of squares (the objective)
    long rows = 0;    // whitened rows
    double raw = 0;   // sum r^2 over the segment
    long samples = 0;
    double acov[kMaxArOrder + 1] = {0};  // sum_n r_n r_{n-k} within the segment
    double wlag1 = 0;                    // sum_n e_n e_{n-1}
  };
  using Set = std::vector<size_t>;
  using Locals = std::vector<Eigen::VectorXd>;

  // Unknowns: per segment locals [y0, v0, (theta0 if piecewise), (K0, dK if greybox) or the
  // shape's basis]; shared [theta0 (constant, load_law), theta1 (load_law), the STE].
  void setUnknowns() {
    local_roles_ = {Role::Y0, Role::V0};
    if (piecewise_) local_roles_.push_back(Role::Theta0);
    basis_first_ = static_cast<int>(local_roles_.size());
    if (shape_) {
      for (int k = 0; k < nb_; ++k) local_roles_.push_back(Role::Basis);
    } else if (grey_) {
      local_roles_.push_back(Role::K0), local_roles_.push_back(Role::DK);
    }
    if (!piecewise_) shared_roles_.push_back(Role::Theta0);
    if (load_) shared_roles_.push_back(Role::Theta1);
    ste_shared_ = static_cast<int>(shared_roles_.size());
    nste_ = ste_ != nullptr ? ste_->basis.size() : 0;
    for (int k = 0; k < nste_; ++k) shared_roles_.push_back(Role::Ste);
    nl_ = static_cast<int>(local_roles_.size()), ns_ = static_cast<int>(shared_roles_.size());
    m_ = nl_ + ns_;
  }

  // Start values from the integral method; keeps its estimates beside the refined ones.
  gear_sim::Status startValues() {
    active_.assign(nseg_, 0);
    loc_.assign(nseg_, Eigen::VectorXd::Zero(nl_));
    sh_ = Eigen::VectorXd::Zero(ns_);
    auto keepIntegral = [](SegmentEstimate* e) {
      if (!e->refined) e->C_integral = e->C, e->C_integral_std = e->C_std;
    };
    for (auto& e : res_->segments) keepIntegral(&e);
    if (res_->constant) keepIntegral(&*res_->constant);
    if (!piecewise_) {
      if (load_ && res_->load_law && res_->load_law->identifiable) {
        sh_[0] = res_->load_law->c0 / me_;
        sh_[1] = res_->load_law->c1 / me_;
      } else if (!load_ && res_->constant && res_->constant->identifiable) {
        sh_[0] = res_->constant->C;
      } else {
        return gear_sim::Status::notIdentifiable(
            "refinement: no identifiable shared estimate to start from");
      }
    }
    for (int k = 0; k < nste_; ++k) sh_[ste_shared_ + k] = ste_->theta[k];
    for (size_t i = 0; i < nseg_; ++i) {
      const SegmentEstimate& e = res_->segments[i];
      if (!e.identifiable) continue;
      active_[i] = 1;
      Eigen::VectorXd& x = loc_[i];
      // Initial state: the integral method's first window of the segment.
      x[0] = s_.dte[ranges_[i].first];
      for (const WindowEstimate& w : res_->windows) {
        if (std::abs(w.t_start - e.t_start) <= 0.5 * s_.dt) {
          x[0] = w.y_T, x[1] = w.velocity;
          break;
        }
      }
      int k = 2;
      if (piecewise_) x[k++] = e.C;
      if (shape_) {
        if (static_cast<int>(e.stiffness_curve.size()) != nb_) {
          return gear_sim::Status::notIdentifiable("refinement: no stiffness curve to start from");
        }
        for (int b = 0; b < nb_; ++b) x[k++] = e.stiffness_curve[b] / me_;
      } else if (grey_) {
        x[k++] = e.k_min / me_;
        x[k++] = (e.k_max - e.k_min) / me_;
      }
    }
    return {};
  }

  Params makeParams(const Eigen::VectorXd& x, const Eigen::VectorXd& g) const {
    Params p;
    p.m = m_;
    for (int k = 0; k < nl_; ++k) p.role[k] = local_roles_[k];
    for (int k = 0; k < ns_; ++k) p.role[nl_ + k] = shared_roles_[k];
    p.nb = nb_;
    p.basis_first = basis_first_;
    p.nste = nste_;
    p.ste_first = nl_ + ste_shared_;
    for (int k = 0; k < nl_; ++k) *p.slot(k) = x[k];
    for (int k = 0; k < ns_; ++k) *p.slot(nl_ + k) = g[k];
    return p;
  }

  // The rows of a fused pass of one segment (FusedPass::rrev, keep), kept for the first
  // evaluation of its next noise round at the same unknowns (rewhiten).
  struct KeptRows {
    size_t seg = static_cast<size_t>(-1);  // none
    int m = 0;
    RowBuffer rrev, J;
  };

  Normal evaluate(size_t i, const Eigen::VectorXd& x, const Eigen::VectorXd& g,
                  const NoiseModel& nm, KeptRows* keep = nullptr) const {
    return evaluateAt(i, makeParams(x, g), nm, keep);
  }

  // Accumulates the normal equations (Normal) of the prewhitened residuals: add() stores each
  // sample's raw row [r, J] in a block, flush() sums a block with the sums in local variables
  // (the AR filter reads the kMaxArOrder rows before the block, kept at its front). MT: the
  // number of unknowns when fixed at compile time (0: m). The sums run in sample order.
  template <int MT>
  class Accumulator {
   public:
    Accumulator(int m, const NoiseModel& nm, const double* y)
        : m_(MT > 0 ? MT : m), nm_(nm), y_(y), buf_(static_cast<size_t>(kRows * (m_ + 1))) {
      std::fill(N_, N_ + m_ * m_, 0.0);
      std::fill(r_, r_ + m_, 0.0);
    }
    void add(Index n, const double* z) {
      const int m = MT > 0 ? MT : m_;
      double* row = buf_.data() + (kMaxArOrder + fill_) * (m + 1);
      row[0] = y_[n] - z[0];
      for (int a = 0; a < m; ++a) row[a + 1] = z[2 + 2 * a];
      if (++fill_ == kBlock) flush();
    }
    Normal finish() {
      flush();
      const int m = m_;
      Normal out;
      out.N.resize(m, m);
      out.rhs.resize(m);
      for (int a = 0; a < m; ++a) {
        out.rhs[a] = r_[a];
        for (int b = 0; b <= a; ++b) out.N(a, b) = out.N(b, a) = N_[a * m + b];
      }
      out.cost = cost_;
      out.rows = rows_;
      out.raw = raw_;
      std::copy(acov_, acov_ + kMaxArOrder + 1, out.acov);
      out.acov[0] = raw_;
      out.samples = count_;
      out.wlag1 = wlag_;
      return out;
    }

   private:
    static constexpr long kBlock = 256;                  // rows per block
    static constexpr long kRows = kMaxArOrder + kBlock;  // with the previous rows
    static constexpr int kCap = MT > 0 ? MT : kMaxParams;

    void flush() {
      const int m = MT > 0 ? MT : m_, S = m + 1, P = nm_.p;
      double N[kCap * kCap], R[kCap], acov[kMaxArOrder + 1];
      std::copy(N_, N_ + m * m, N);
      std::copy(r_, r_ + m, R);
      std::copy(acov_, acov_ + kMaxArOrder + 1, acov);
      double cost = cost_, raw = raw_, wlag = wlag_, wprev = wprev_;
      long rows = rows_, n = count_;
      const double* base = buf_.data() + kMaxArOrder * S;
      for (long i = 0; i < fill_; ++i, ++n) {
        const double* cur = base + i * S;
        const double r = cur[0];
        raw += r * r;
        if (n >= kMaxArOrder) {  // every lag (the loop unrolled)
          for (int k = 1; k <= kMaxArOrder; ++k) acov[k] += r * cur[-k * S];
        } else {
          for (int k = 1; k <= n; ++k) acov[k] += r * cur[-k * S];
        }
        if (n < P) continue;
        double w[kCap + 1];
        w[0] = r;
        for (int c = 1; c <= m; ++c) w[c] = cur[c];
        for (int k = 0; k < P; ++k) {  // w = cur + a_1 row_{n-1} + ... in this order
          const double ak = nm_.a[k];
          const double* prev = cur - (k + 1) * S;
          for (int c = 0; c <= m; ++c) w[c] += ak * prev[c];
        }
        cost += w[0] * w[0];
        if (rows > 0) wlag += w[0] * wprev;
        wprev = w[0];
        ++rows;
        for (int a = 0; a < m; ++a) {
          const double ja = w[a + 1];
          R[a] += ja * w[0];
          for (int b = 0; b <= a; ++b) N[a * m + b] += ja * w[b + 1];
        }
      }
      std::copy(N, N + m * m, N_);
      std::copy(R, R + m, r_);
      std::copy(acov, acov + kMaxArOrder + 1, acov_);
      cost_ = cost, raw_ = raw, wlag_ = wlag, wprev_ = wprev, rows_ = rows, count_ = n;
      // The block's last kMaxArOrder rows (with the earlier ones when it is shorter) to the front.
      std::copy(buf_.begin() + fill_ * S, buf_.begin() + (fill_ + kMaxArOrder) * S, buf_.begin());
      fill_ = 0;
    }

    const int m_;
    const NoiseModel& nm_;
    const double* y_;
    std::vector<double> buf_;  // kRows rows of m + 1: the previous rows, then the block
    long fill_ = 0;            // rows in the block
    double N_[kCap * kCap], r_[kCap];
    double acov_[kMaxArOrder + 1] = {0};
    double cost_ = 0, raw_ = 0, wlag_ = 0, wprev_ = 0;
    long count_ = 0, rows_ = 0;
  };

  // At parameters p (p.m unknowns: the problem's, or one more for the variation test).
  // `keep` (may be null): receives the rows of a fused pass (seg = i), else seg = none.
  Normal evaluateAt(size_t i, const Params& p, const NoiseModel& nm,
                    KeptRows* keep = nullptr) const {
    switch (p.m) {  // the common problem sizes unrolled
      case 3:
        return evaluateWith<3>(i, p, nm, keep);
      case 4:
        return evaluateWith<4>(i, p, nm, keep);
      case 5:
        return evaluateWith<5>(i, p, nm, keep);
      case 6:
        return evaluateWith<6>(i, p, nm, keep);
      default:
        return evaluateWith<0>(i, p, nm, keep);
    }
  }

  template <int MT>
  Normal evaluateWith(size_t i, const Params& p, const NoiseModel& nm, KeptRows* keep) const {
    const SegmentTable* t = sim_.tableApplies(substeps_) ? &tableOf(i) : nullptr;
    Normal fused;
    if (keep != nullptr) keep->seg = static_cast<size_t>(-1);
    if (t != nullptr && evaluateFused(*t, p, nm, &fused, keep)) {
      if (keep != nullptr) keep->seg = i, keep->m = p.m;
      return fused;
    }
    Accumulator<MT> acc(p.m, nm, s_.dte);
    auto visit = [&acc](Index n, const double* z) { acc.add(n, z); };
    if (t != nullptr) {
      sim_.runTable<MT>(*t, p, visit);
    } else {
      sim_.run(ranges_[i].first, ranges_[i].second, p, substeps_, visit);
    }
    return acc.finish();
  }

  // The held value's affine map (SegmentSimulator::AffineMap) of m sensitivities in lanes.
  static void toLanes(const SegmentSimulator::AffineMap& am, int m, FusedMap* out) {
    *out = FusedMap{};
    std::copy(&am.R[0][0], &am.R[0][0] + 4, &out->R[0][0]);
    for (int row = 0; row < 2; ++row) {
      for (int c = 0; c < 2; ++c) {
        const double r = am.R[row][c];
        out->Rv[row][c] = V4d{r, r, r, r};
      }
    }
    std::copy(&am.G[0][0], &am.G[0][0] + 6, &out->G[0][0]);
    for (int k = 0; k < m; ++k) {
      if (!am.coupled[k]) continue;
      for (int row = 0; row < 2; ++row) {
        for (int c = 0; c < 2; ++c) out->S[row][c][k / 4][k % 4] = am.S[k][row][c];
        for (int q = 0; q < 3; ++q) out->H[row][q][k / 4][k % 4] = am.H[k][row][q];
      }
    }
  }

  // The RK4 step's coefficients of table t at p for the fused pass (stepLinear's: the tabled
  // stiffness, C and F, the sensitivities' forcing weights).
  void linearLanes(const SegmentTable& t, const Params& p, FusedPass* f) const {
    const bool grey = o_.formulation == Formulation::Greybox;
    if (t.smooth) f->K3 = t.K3.data();
    for (int k = 0; k < t.n_keys; ++k) {
      f->key_K[k] = grey ? p.K0 + p.dK * t.key_sv[k] : t.key_K[k];
      f->key_sv[k] = grey ? t.key_sv[k] : 0.0;
    }
    f->theta0 = p.theta0, f->theta1 = p.theta1, f->t_ref = p.t_ref;
    f->ff = fm_.gear().force_factor, f->h = s_.dt;
    for (int k = 0; k < p.m; ++k) {
      f->lv0[k / 4][k % 4] = p.role[k] == Role::Theta0 ? 1.0 : 0.0;
      f->lv1[k / 4][k % 4] = p.role[k] == Role::Theta1 ? 1.0 : 0.0;
      f->ly0[k / 4][k % 4] = p.role[k] == Role::K0 ? 1.0 : 0.0;
      f->ly1[k / 4][k % 4] = p.role[k] == Role::DK ? 1.0 : 0.0;
    }
  }

  // Segment t's normal equations at p by the fused pass (3 to 6 unknowns): the numbers of
  // runTable + Accumulator (affine maps where the stiffness is held and C constant).
  bool evaluateFused(const SegmentTable& t, const Params& p, const NoiseModel& nm, Normal* out,
                     KeptRows* keep) const {
    if (p.m < 3 || p.m > 6 || t.e - t.b < 2) return false;
    SegmentSimulator::AffineMap am[kMaxMaps];
    FusedMap maps[kMaxMaps];
    FusedPass f;
    const bool affine = sim_.heldMaps(t, p, am);
    if (affine) {
      for (int k = 0; k < t.n_keys; ++k) toLanes(am[k], p.m, &maps[k]);
    } else {
      linearLanes(t, p, &f);
    }
    f.maps = maps, f.key = t.key.data(), f.T = t.T.data(), f.T_mid = t.T_mid.data();
    f.y = s_.dte + t.b, f.n = t.e - t.b, f.nm = nm;
    f.x[0] = p.y0, f.x[1] = p.v0;
    RowBuffer& rrev = keep != nullptr ? keep->rrev : fused_rrev_;
    if (rrev.size() < static_cast<size_t>(f.n + 8)) rrev.resize(f.n + 8);
    std::fill(rrev.begin() + f.n, rrev.begin() + f.n + 8, 0.0);
    f.rrev = rrev.data();
    if (keep != nullptr) {
      keep->J.resize(static_cast<size_t>(f.n * 4 * (p.m / 4 + 1)));
      f.keep = keep->J.data();
    }
    for (int k = 0; k < p.m; ++k) {
      if (p.role[k] == Role::Y0) f.s[0][k] = 1.0;
      if (p.role[k] == Role::V0) f.s[1][k] = 1.0;
    }
    struct Ctx {
      const SegmentSimulator* sim;
      const SegmentTable* t;
      const Params* p;
    } ctx{&sim_, &t, &p};
    f.ctx = &ctx;
    f.split = [](const void* c, Index i, double* x, double(*s)[kFusedLanes]) {
      const Ctx& q = *static_cast<const Ctx*>(c);
      double z[2 + 2 * kFusedLanes] = {x[0], x[1]};
      for (int k = 0; k < q.p->m; ++k) z[2 + 2 * k] = s[0][k], z[3 + 2 * k] = s[1][k];
      q.sim->splitInterval(*q.t, i, *q.p, z);
      x[0] = z[0], x[1] = z[1];
      for (int k = 0; k < q.p->m; ++k) s[0][k] = z[2 + 2 * k], s[1][k] = z[3 + 2 * k];
    };
    runFused(&f, p.m, affine ? 1 : 0);
    *out = normalOf(f, p.m);
    return true;
  }

  static Normal normalOf(const FusedPass& f, int m) {
    Normal out;
    out.N.resize(m, m);
    out.rhs.resize(m);
    for (int a = 0; a < m; ++a) {
      out.rhs[a] = f.rhs[a];
      for (int b = 0; b <= a; ++b) out.N(a, b) = out.N(b, a) = f.N[a][b];
    }
    out.cost = f.cost, out.rows = f.rows, out.raw = f.acov[0], out.samples = f.n;
    std::copy(f.acov, f.acov + kMaxArOrder + 1, out.acov);
    out.wlag1 = f.wlag;
    return out;
  }

  // Segment i's normal equations under the noise model nm from the rows kept at its current
  // unknowns (kept_[0]; the same numbers as a new pass there); false when none are kept.
  bool rewhiten(size_t i, const NoiseModel& nm, Normal* out) const {
    KeptRows& k = kept_[0];
    if (k.seg != i || k.m != m_) return false;
    FusedPass f;
    f.n = ranges_[i].second - ranges_[i].first;
    f.nm = nm;
    f.rrev = k.rrev.data();
    f.keep = k.J.data();
    runFused(&f, m_, 2);
    *out = normalOf(f, m_);
    return true;
  }

  // Segment i's look-ups (SegmentSimulator::buildTable), cached while the cached intervals stay
  // within kTableBudget. When full: the piecewise model's problems (one segment each, in order)
  // empty the cache; a joint problem over all segments keeps the tables it has and builds the
  // others into a scratch table per evaluation (as a segment larger than the budget).
  const SegmentTable& tableOf(size_t i) const {
    constexpr size_t kTableBudget = size_t{1} << 20;  // intervals: ~18 MB held, ~43 MB smooth
    if (tables_.size() != nseg_) tables_.assign(nseg_, SegmentTable{});
    SegmentTable& t = tables_[i];
    if (t.e > t.b) return t;
    const size_t n = static_cast<size_t>(std::max<Index>(ranges_[i].second - ranges_[i].first, 0));
    const bool single = piecewise_ && ns_ == 0;
    if (n > kTableBudget || (cached_ + n > kTableBudget && !single)) {
      sim_.buildTable(ranges_[i].first, ranges_[i].second, &scratch_);
      return scratch_;
    }
    if (cached_ + n > kTableBudget) {
      tables_.assign(nseg_, SegmentTable{});
      cached_ = 0;
    }
    sim_.buildTable(ranges_[i].first, ranges_[i].second, &t);
    cached_ += n;
    return t;
  }

  // Gauss-Newton step of a set of segments: locals eliminated per segment (Schur complement).
  void solveStep(const Set& set, const std::vector<Normal>& normals, Locals* dl,
                 Eigen::VectorXd* dg, Eigen::MatrixXd* shared_inv,
                 std::vector<Eigen::MatrixXd>* local_inv) const {
    const int nl = nl_, ns = ns_;
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(ns, ns);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(ns);
    std::vector<Eigen::MatrixXd>& Nll_inv = nll_inv_scratch_;  // per segment of the set
    if (Nll_inv.size() != nseg_) Nll_inv.resize(nseg_);
    for (size_t i : set) {
      const Normal& nm = normals[i];
      Nll_inv[i] = nm.N.topLeftCorner(nl, nl).ldlt().solve(Eigen::MatrixXd::Identity(nl, nl));
      const Eigen::MatrixXd Nsl = nm.N.block(nl, 0, ns, nl);
      A += nm.N.bottomRightCorner(ns, ns) - Nsl * Nll_inv[i] * Nsl.transpose();
      rhs += nm.rhs.tail(ns) - Nsl * (Nll_inv[i] * nm.rhs.head(nl));
    }
    Eigen::MatrixXd Ainv = Eigen::MatrixXd::Zero(ns, ns);
    if (ns > 0) Ainv = A.ldlt().solve(Eigen::MatrixXd::Identity(ns, ns));
    *dg = Ainv * rhs;
    for (size_t i : set) {
      const Normal& nm = normals[i];
      (*dl)[i] = Nll_inv[i] * (nm.rhs.head(nl) - nm.N.block(0, nl, nl, ns) * *dg);
    }
    if (shared_inv) *shared_inv = Ainv;
    if (local_inv) {
      for (size_t i : set) (*local_inv)[i] = Nll_inv[i];
    }
  }

  // Largest relative move of the damping (and stiffness, STE) unknowns by `step` * (dl, dg).
  double relativeChange(const Set& set, const Locals& dl, const Eigen::VectorXd& dg,
                        double step) const {
    double rel = 0.0;
    for (int k = 0; k < ns_; ++k) {
      const double to = sh_[k] + step * dg[k];
      rel = std::max(rel, std::abs(step * dg[k]) / std::max(std::abs(to), 1e-300));
    }
    for (size_t i : set) {
      for (int k = 2; k < nl_; ++k) {
        const double to = loc_[i][k] + step * dl[i][k];
        rel = std::max(rel, std::abs(step * dl[i][k]) / std::max(std::abs(to), 1e-300));
      }
    }
    return rel;
  }

  // Gauss-Newton with step halving on the segments of `set` (one segment for the piecewise
  // model, whose segments are independent problems; all for shared unknowns). Returns the
  // iterations; *converged false when the iteration limit stopped it. Converged when the
  // Gauss-Newton step would move the damping (and stiffness) unknowns by less than 1e-10
  // relative. One segment: the step is taken with the Gauss-Newton matrix plus the residual
  // curvature term S (sum e d2e/dp2) estimated by secant updates (structured quasi-Newton,
  // secantStep, secantUpdate), which converges faster where Gauss-Newton converges linearly;
  // the stopping test, at 1e-11, is Gauss-Newton's, so the minimiser is the same.
  int gaussNewton(const Set& set, const NoiseModel& nm, bool* converged, bool* finite) {
    constexpr double kConvergenceTol = 1e-10;
    constexpr double kSecantTol = 1e-11;  // one segment: closer to the minimiser for few passes
    double cost = 0.0;
    // One segment: its rows at the accepted unknowns are kept (kept_[0]; the trial's in
    // kept_[1]), so a new noise round starts without a pass.
    KeptRows* keep = set.size() == 1 ? &kept_[1] : nullptr;
    for (size_t i : set) {
      if (keep == nullptr || !rewhiten(i, nm, &normals_[i])) {
        normals_[i] = evaluate(i, loc_[i], sh_, nm, keep);
        if (keep != nullptr) std::swap(kept_[0], kept_[1]);
      }
      cost += normals_[i].cost;
    }
    *finite = std::isfinite(cost);
    *converged = false;
    if (!*finite) return 0;
    const bool secant = keep != nullptr && ns_ == 0;
    if (secant) startCurvature(set[0], nm);
    const double tol = secant ? kSecantTol : kConvergenceTol;
    int it = 0;
    for (; it < o_.max_iterations && !*converged; ++it) {
      // Scratch sized for every segment, used on the set's (no O(segments) work per step).
      Locals& dl = dl_scratch_;
      Eigen::VectorXd dg;
      solveStep(set, normals_, &dl, &dg, nullptr, nullptr);
      if (relativeChange(set, dl, dg, 1.0) < tol) {
        *converged = true;  // the full step would move nothing: no need to evaluate it
        break;
      }
      bool quasi = secant && secantStep(set[0], &dl[set[0]]);
      double step = 1.0;
      bool accepted = false;
      for (int halving = 0; halving < 30 && !accepted; ++halving, step *= 0.5) {
        Locals& x1 = x1_scratch_;
        const Eigen::VectorXd g1 = sh_ + step * dg;
        std::vector<Normal>& n1 = n1_scratch_;
        double c1 = 0.0;
        for (size_t i : set) {
          x1[i] = loc_[i] + step * dl[i];
          n1[i] = evaluate(i, x1[i], g1, nm, keep);
          c1 += n1[i].cost;
        }
        if (std::isfinite(c1) && c1 <= cost * (1.0 + 1e-12)) {
          accepted = true;
          *converged =
              relativeChange(set, dl, dg, step) < tol || (!quasi && c1 >= cost * (1.0 - 1e-14));
          if (secant) secantUpdate(set[0], step * dl[set[0]], n1[set[0]]);
          for (size_t i : set) {
            loc_[i] = x1[i];
            normals_[i] = std::move(n1[i]);
          }
          if (keep != nullptr) std::swap(kept_[0], kept_[1]);
          sh_ = g1;
          cost = c1;
        } else if (quasi) {
          // The quasi-Newton step did not descend: forget S, retry with Gauss-Newton's step.
          quasi = false;
          curvature_.setZero(m_, m_);
          solveStep(set, normals_, &dl, &dg, nullptr, nullptr);
          step = 2.0;
        }
      }
      if (!accepted) *converged = true;  // no descent left: at the minimum to rounding
    }
    return it;
  }

  // S at the start of segment i's round under nm: within a segment S carries over, from one
  // prewhitened round to the next as it is (their AR models differ by little), from the
  // white-noise round to the first prewhitened one rescaled by N's diagonal (the prewhitening
  // rescales the curvature about as it rescales J'J); zero for a new segment or round 0.
  void startCurvature(size_t i, const NoiseModel& nm) {
    const bool carry = curvature_.rows() == m_ && curvature_of_ == i && nm.p > 0;
    const bool rescale = carry && !curvature_ar_;
    if (rescale && curvature_d_.size() == m_) {
      const Eigen::VectorXd r = normals_[i].N.diagonal().cwiseSqrt().cwiseQuotient(curvature_d_);
      curvature_ = curvature_.cwiseProduct(r * r.transpose()).eval();
    }
    if (!carry || (rescale && curvature_d_.size() != m_) || !curvature_.allFinite())
      curvature_.setZero(m_, m_);
    curvature_of_ = i;
    curvature_ar_ = nm.p > 0;
  }

  // Segment i's step with the curvature estimate: (N + S) d = rhs into *d when S is set and
  // N + S is positive definite (else *d stays Gauss-Newton's and false).
  bool secantStep(size_t i, Eigen::VectorXd* d) const {
    if (curvature_.isZero(0.0)) return false;
    const Eigen::MatrixXd H = normals_[i].N + curvature_;
    Eigen::LLT<Eigen::MatrixXd> llt(H);
    if (llt.info() != Eigen::Success) return false;
    const Eigen::VectorXd q = llt.solve(normals_[i].rhs);
    if (!q.allFinite()) return false;
    *d = q;
    return true;
  }

  // The secant condition of a step s from normals_[i] to `next`: the gradient -rhs changes by
  // (N + S) s with N averaged over the step's two ends, so S s = t = rhs - rhs' - N s; a symmetric
  // rank-one update of S meets it (skipped when ill-defined). With one nonlinear unknown (the
  // known piecewise model: y0, v0, C) the condition determines S alone (secantOfC).
  void secantUpdate(size_t i, const Eigen::VectorXd& s, const Normal& next) {
    const Eigen::VectorXd y = normals_[i].rhs - next.rhs;
    const Eigen::VectorXd ns = 0.5 * (normals_[i].N * s + next.N * s);  // N along the step
    // In the unknowns scaled by N's diagonal (their magnitudes differ by ten orders).
    const Eigen::VectorXd d = next.N.diagonal().cwiseSqrt();
    curvature_d_ = d;
    if (m_ == 3 && local_roles_[2] == Role::Theta0) {
      secantOfC(y - ns, s, d);
      return;
    }
    const Eigen::VectorXd u = y - ns - curvature_ * s;
    const double den = u.dot(s);
    const double scale = u.cwiseQuotient(d).norm() * s.cwiseProduct(d).norm();
    if (!(std::abs(den) > 1e-8 * scale)) return;
    curvature_ += u * u.transpose() / den;
  }

  // S from S s = t where only C (unknown 2) enters nonlinearly: the response is linear in y0
  // and v0, so their second derivatives vanish and S = [0 0 w0; 0 0 w1; w0 w1 c], which the
  // three equations give: w_k = t_k / s_2, c = (t_2 - w0 s0 - w1 s1) / s_2 (the secant method
  // in C; the rank-one update needs a step per direction to get there). Kept unless the step
  // moves C by nothing (d: N's diagonal root, the unknowns' scale).
  void secantOfC(const Eigen::VectorXd& t, const Eigen::VectorXd& s, const Eigen::VectorXd& d) {
    const double sc = std::abs(s[2] * d[2]);
    if (!(sc > 1e-15 * s.cwiseProduct(d).norm())) return;
    Eigen::MatrixXd S = Eigen::MatrixXd::Zero(3, 3);
    S(0, 2) = S(2, 0) = t[0] / s[2];
    S(1, 2) = S(2, 1) = t[1] / s[2];
    S(2, 2) = (t[2] - S(2, 0) * s[0] - S(2, 1) * s[1]) / s[2];
    if (S.allFinite()) curvature_ = S;
  }

  // AR model fitted to the pooled residual autocovariances of a set of segments.
  NoiseModel pooledFit(const Set& set) const {
    double acov[kMaxArOrder + 1] = {0}, count = 0.0;
    for (size_t i : set) {
      for (int k = 0; k <= kMaxArOrder; ++k) acov[k] += normals_[i].acov[k];
      count += static_cast<double>(normals_[i].samples);
    }
    for (int k = 0; k <= kMaxArOrder; ++k) acov[k] /= count;
    return fitNoiseModel(acov, count);
  }

  // Per problem (a segment of the piecewise model, which therefore gives the same result
  // refined alone, as live; all segments for shared unknowns): round 0 assumes white noise;
  // then the AR model of its residuals and the prewhitened problem, refitted until the noise
  // model settles.
  gear_sim::Status iterate() {
    for (size_t i = 0; i < nseg_; ++i) {
      if (!active_[i]) continue;
      if ((piecewise_ && ns_ == 0) || problems_.empty()) problems_.emplace_back();
      problems_.back().push_back(i);
    }
    if (problems_.empty()) {
      return gear_sim::Status::notIdentifiable("refinement: no identifiable segment");
    }
    normals_.assign(nseg_, Normal{});
    dl_scratch_.assign(nseg_, Eigen::VectorXd());
    x1_scratch_.assign(nseg_, Eigen::VectorXd());
    n1_scratch_.assign(nseg_, Normal{});
    converged_.assign(nseg_, 1);
    noise_of_.assign(nseg_, NoiseModel{});
    for (const auto& set : problems_) {
      NoiseModel noise;
      for (int round = 0; round < kMaxNoiseRounds; ++round) {
        bool conv = false, finite = true;
        iterations_ += gaussNewton(set, noise, &conv, &finite);
        if (!finite) {
          return gear_sim::Status::notIdentifiable(
              "refinement: the model response is not finite at the " +
              std::string(round == 0 ? "integral-method estimate" : "white-noise estimate"));
        }
        for (size_t i : set) converged_[i] = conv;
        const NoiseModel next = pooledFit(set);
        if (maxChange(next, noise) < kArChangeTol || round + 1 == kMaxNoiseRounds) break;
        noise = next;
      }
      for (size_t i : set) noise_of_[i] = noise;
      if (set.size() == 1) keepFinalRows(set[0]);
    }
    return {};
  }

  // One segment's problem with torque noise: the rows of its last accepted pass (kept_[0], at
  // the solution) are kept for whitenedSensitivities, which would otherwise repeat that pass
  // (the rows do not depend on the noise model), within kKeptBudget samples over the segments.
  void keepFinalRows(size_t i) {
    constexpr size_t kKeptBudget = size_t{1} << 20;  // samples: ~42 MB of rows at 3 unknowns
    KeptRows& k = kept_[0];
    if (!(torque_sigma_[i] > 0.0) || k.seg != i || k.m != m_) return;
    const size_t n = static_cast<size_t>(ranges_[i].second - ranges_[i].first);
    if (kept_samples_ + n > kKeptBudget) return;
    if (final_rows_.size() != nseg_) final_rows_.resize(nseg_);
    final_rows_[i] = std::move(k);
    k = KeptRows{};
    kept_samples_ += n;
  }

  // Covariances at the solution and the pooled noise statistics.
  gear_sim::Status covariances() {
    Nll_inv_.assign(nseg_, Eigen::MatrixXd());
    Ainv_of_.assign(nseg_, Eigen::MatrixXd());
    Locals dl(nseg_);
    Eigen::VectorXd dg;
    for (const auto& set : problems_) {
      Eigen::MatrixXd Ainv;
      solveStep(set, normals_, &dl, &dg, &Ainv, &Nll_inv_);
      for (size_t i : set) Ainv_of_[i] = Ainv;
    }
    long n_total = 0, rows_total = 0;
    int n_active = 0;
    double raw_total = 0.0, cost_total = 0.0;
    for (size_t i = 0; i < nseg_; ++i) {
      if (!active_[i]) continue;
      n_total += normals_[i].samples, rows_total += normals_[i].rows, ++n_active;
      raw_total += normals_[i].raw, cost_total += normals_[i].cost;
    }
    const long unknowns = static_cast<long>(n_active) * nl_ + ns_;
    if (rows_total - unknowns < 1) {
      return gear_sim::Status::notIdentifiable("refinement: too few samples for the unknowns");
    }
    // Innovation variance (white noise: the residual variance) for the covariance.
    sigma2_pooled_ = cost_total / static_cast<double>(rows_total - unknowns);
    res_->noise_std = std::sqrt(raw_total / static_cast<double>(n_total - unknowns));
    res_->noise_innovation_std = std::sqrt(sigma2_pooled_);
    Set all;
    for (const auto& set : problems_) all.insert(all.end(), set.begin(), set.end());
    const NoiseModel record_noise = pooledFit(all);
    res_->noise_ar.assign(record_noise.a, record_noise.a + record_noise.p);
    res_->estimator = "output_error";
    res_->iterations = iterations_;
    return {};
  }

  // The covariance at the refined estimate must give every reported variance (C, and the greybox
  // levels) a positive finite value. A response that diverges (C far below zero: the sensitivities
  // overflow) or a singular problem gives zero or NaN, which would be reported as C_std = 0, an
  // exact number: the refinement has failed, and the caller keeps the integral estimate. The
  // covariances into cov_ll_ and cov_ss_ (fillSegments).
  gear_sim::Status positiveVariances() {
    auto bad = [](double v) { return !(v > 0.0) || !std::isfinite(v); };
    cov_ll_.assign(nseg_, Eigen::MatrixXd());
    cov_ss_.assign(nseg_, Eigen::MatrixXd());
    for (size_t i = 0; i < nseg_; ++i) {
      if (!active_[i]) continue;
      const Eigen::MatrixXd& ll = cov_ll_[i] = localCovariance(i);
      const Eigen::MatrixXd& ss = cov_ss_[i] = sigma2Of(i) * Ainv_of_[i];
      double v = cVariance(ll, ss);
      bool levels_bad = false;
      if (grey_ && !shape_) {
        const int a = piecewise_ ? 3 : 2;
        levels_bad = bad(ll(a, a)) || bad(ll(a, a) + ll(a + 1, a + 1) + 2 * ll(a, a + 1));
      }
      if (bad(v) || levels_bad) {
        std::ostringstream m;
        m << "refinement: the covariance at the refined estimate is not positive (segment at "
          << res_->segments[i].t_start << " s, C variance " << v
          << "): the model response diverges or the unknowns are not separable";
        return gear_sim::Status::notIdentifiable(m.str());
      }
    }
    return {};
  }

  // sigma^2 of segment i's covariance (per segment for the piecewise model, else pooled) and
  // the covariance of its locals, sigma^2 (Nll^-1 + B A^-1 B^T) (B = Nll^-1 Nls^T).
  double sigma2Of(size_t i) const {
    const Normal& nm = normals_[i];
    return piecewise_ ? nm.cost / static_cast<double>(nm.rows - nl_) : sigma2_pooled_;
  }
  Eigen::MatrixXd localCovariance(size_t i) const {
    const Normal& nm = normals_[i];
    const Eigen::MatrixXd Nsl = nm.N.block(nl_, 0, ns_, nl_);
    const Eigen::MatrixXd B = Nll_inv_[i] * Nsl.transpose();
    return sigma2Of(i) * (Nll_inv_[i] + B * Ainv_of_[i] * B.transpose());
  }
  // The variance of segment i's C in a covariance pair (locals, shared).
  double cVariance(const Eigen::MatrixXd& ll, const Eigen::MatrixXd& ss) const {
    return piecewise_ ? ll(2, 2) : ss(0, 0);
  }

  // Shape test of the greybox square levels (piecewise model): a score test of one more unknown g
  // in K = K0 + dK (s + g (s_w - s)), s_w the mesh state ramped linearly around each switch (over
  // a fifth of the natural period, at most 0.4 of the shortest interval between switches). The
  // response change d (rampedResponseChange), the residual e and the sensitivities J at the
  // converged estimate, prewhitened by the segment's noise model; J holds, beside the unknowns,
  // the damping's variation with the load (C1 of variationTest, where the torque varies), so
  // that a damping that follows the load does not raise the score. With d and e projected off
  // J: z = d'e / (sigma |d|), sigma^2 = |e|^2 / (rows - columns of J): N(0, 1) when the
  // stiffness switches at once. A stiffness that ramps (a trapezoid) biases C by many C_std
  // while the residual can stay at the noise level; z then grows. NaN without a switch.
  struct ShapeScore {
    double z = kNaN;      // the score, N(0, 1) when the stiffness switches at once
    double shift = kNaN;  // the ramped fit's change of C, relative to C
    double power = kNaN;  // switchTiming: z's mean with the switches half a sample earlier
  };
  ShapeScore shapeScore(size_t i, double variation_z) {
    const Index b = ranges_[i].first, e = ranges_[i].second;
    const std::vector<MeshSwitch> sw = meshSwitches(fm_, b, e);
    double spacing = INFINITY;
    for (size_t k = 1; k < sw.size(); ++k) spacing = std::min(spacing, sw[k].at - sw[k - 1].at);
    if (sw.empty() || !(res_->omega0 > 0.0)) return {};
    const double period = 2.0 * M_PI / (res_->omega0 * s_.dt);  // samples
    const double hw = std::min(0.1 * period, 0.2 * spacing);
    if (!(hw > 0.0)) return {};
    // The residual and the unknowns' sensitivities at the solution (solutionRows), the change d
    // and, where the damping varies with the load (|variation_z| > 1), the C1 sensitivity.
    const Eigen::MatrixXd sol = solutionRows(i, true);
    double mean_t = 0.0;
    const bool c1 = std::abs(variation_z) > 1.0 && torqueVaries(b, e, &mean_t);
    const SegmentTable* tab = sim_.tableApplies(substeps_) ? &tableOf(i) : nullptr;
    auto torque = [&](Index j, double u) {  // quadratic through the stage torques, or the cubic
      if (tab == nullptr) return fm_.torque(j, u, b, e);
      const double t0 = tab->T[j - b], tm = tab->T_mid[j - b], t1 = tab->T[j + 1 - b];
      return t0 * (1.0 - u) * (1.0 - 2.0 * u) + tm * 4.0 * u * (1.0 - u) + t1 * u * (2.0 * u - 1.0);
    };
    Eigen::MatrixXd dc;
    // The unknowns in the piecewise layout (y0, v0, C, K0, dK): a shared C (constant model) or
    // load law (C = theta0 + theta1 T1) comes from the shared unknowns.
    Eigen::VectorXd x = loc_[i];
    double c_slope = 0.0;
    if (!piecewise_) {
      x.resize(5);
      x << loc_[i][0], loc_[i][1], sh_[0], loc_[i][2], loc_[i][3];
      if (load_) c_slope = sh_[1];
    }
    rampedResponseChange(fm_, b, e, sw, x, hw, c1 ? mean_t : kNaN, torque, &dc, c_slope);
    const Index m = sol.cols() - 1;
    Eigen::MatrixXd rows(e - b, 2 + m + (c1 ? 1 : 0));  // e, d, J, (C1)
    rows.col(0) = sol.col(0);
    rows.col(1) = dc.col(0);
    rows.middleCols(2, m) = sol.rightCols(m);
    if (c1) rows.col(2 + m) = dc.col(1);
    return directionScore(i, rows, true);
  }

  // The score of a direction d against the residual e (rows = [e, d, J], J the sensitivities of
  // the unknowns, C the third, and of any extra nuisance column), all prewhitened by segment i's
  // noise model: with d and e projected off J, z = d'e / (sigma |d|), its variance with the
  // torque noise's response on d. `fitted`: the shift is C's change, relative to C, of the fit
  // enlarged by d's coefficient g = d'e / |d|^2 (Frisch-Waugh: the unknowns move by -beta g,
  // beta = d regressed on J); else that of a full step along d (g = 1), with power |d| / sigma,
  // z's mean where the data hold that step.
  ShapeScore directionScore(size_t i, const Eigen::MatrixXd& rows, bool fitted) {
    const Eigen::MatrixXd w = whiten(rows, noise_of_[i]);
    Eigen::MatrixXd J = w.rightCols(w.cols() - 2);
    // C's column: unknown 2 (piecewise), else the shared theta0 after the locals. For a load
    // law, C at the segment moves by d theta0 + d theta1 T (the segment's mean torque): within a
    // segment of a steady load the two columns are nearly collinear, so only that combination
    // is determined, not theta0's share of it.
    const Index cc = piecewise_ ? 2 : nl_;
    const double c_norm = J.col(cc).norm();
    Eigen::VectorXd norms(J.cols());
    for (Index c = 0; c < J.cols(); ++c) {
      norms[c] = J.col(c).norm();
      if (norms[c] > 0.0) J.col(c) /= norms[c];
    }
    auto cShift = [&](const Eigen::VectorXd& b) {  // C's change for unknowns moved by -b
      double d = -b[cc] / c_norm;
      if (!piecewise_ && load_ && norms[cc + 1] > 0.0)
        d -= b[cc + 1] / norms[cc + 1] * res_->segments[i].mean_torque;
      return d;
    };
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(J);
    const Eigen::VectorXd beta = qr.solve(w.col(1));  // d regressed on the sensitivities
    const Eigen::VectorXd ep = w.col(0) - J * qr.solve(w.col(0));
    const Eigen::VectorXd dp = w.col(1) - J * beta;
    const double dof = static_cast<double>(w.rows() - qr.rank());
    double den = std::sqrt(ep.squaredNorm() / dof) * dp.norm();
    if (!torque_sigma_.empty() && torque_sigma_[i] > 0.0)  // the torque noise's response on dp
      den = std::sqrt(den * den + torqueProjectedVariance(i, dp, den * den));
    if (!(dof > 0.0 && den > 0.0 && c_norm > 0.0)) return {};
    const double C = std::abs(piecewise_ ? loc_[i][2] : res_->segments[i].C);
    if (!fitted) return {dp.dot(ep) / den, cShift(beta) / C, dp.squaredNorm() / den};
    const double g = dp.dot(ep) / dp.squaredNorm();
    return {dp.dot(ep) / den, cShift(beta) * g / C};
  }

  // Switch timing (a held stiffness or mesh state without mesh_phase): a switch between samples
  // is held from the sample where its new value is first seen, up to a sample late, half a
  // sample on average where the switches fall anywhere between samples (most speeds). The
  // response change d = yhat(switches at u = 0.5) - yhat at the solution (both by the same
  // integration), the residual e and the sensitivities J, prewhitened: d regressed on J moves
  // the unknowns by -beta, C by the returned shift (relative to C) with every switch half a
  // sample earlier; with d and e projected off J, z = d'e / (sigma |d|) is the data's score for
  // that shift (as shapeScore's, with the torque noise): N(0, 1) with the switches at the
  // samples. NaN with mesh_phase, a smooth stiffness, or no switch in the segment.
  ShapeScore switchTiming(size_t i) {
    const Index b = ranges_[i].first, e = ranges_[i].second;
    if (s_.mesh_phase != nullptr || fm_.smoothStiffness(b) || !(std::abs(loc_[i][2]) > 0.0))
      return {};
    const auto& brk = fm_.breaks();
    const auto first = std::lower_bound(brk.begin(), brk.end(), b,
                                        [](const QuadratureBreak& q, Index v) { return q.j < v; });
    if (first == brk.end() || first->j + 1 >= e) return {};
    const ForwardModel mid = fm_.withUnlocatedSwitchesAt(0.5);
    const SegmentSimulator held_sim(fm_, !reference_, nullptr), mid_sim(mid, !reference_, nullptr);
    Params p = makeParams(loc_[i], sh_);
    p.m = 0;  // the state only
    const Eigen::MatrixXd sol = solutionRows(i, true);
    const Index m = sol.cols() - 1;
    Eigen::MatrixXd rows(e - b, 2 + m);  // e, d, J
    rows.col(0) = sol.col(0);
    held_sim.run(b, e, p, substeps_, [&](Index n, const double* z) { rows(n - b, 1) = -z[0]; });
    mid_sim.run(b, e, p, substeps_, [&](Index n, const double* z) { rows(n - b, 1) += z[0]; });
    rows.rightCols(m) = sol.rightCols(m);
    return directionScore(i, rows, false);
  }

  // Shape test of a greybox fourier:H / table:N curve (piecewise model, no STE): a score test
  // of the unknowns a finer curve adds. At the refined curve the finer one (table:2N with the
  // midpoint nodes the averages of their neighbours; fourier:2H, at most kMaxHarmonics, with
  // zero extra coefficients) gives the same stiffness; one run of the finer model there gives
  // the residual e, the sensitivities J of the current unknowns (table: a coarse node's hat is
  // the fine hat on it plus half of each neighbouring midpoint's) and D of the q extra ones
  // (table: the midpoint nodes; fourier: harmonics H+1..2H), plus the damping's variation with
  // the load as in shapeScore. Prewhitened, projected off J: S = |P_D e|^2 / sigma^2 is
  // chi-square q when the curve is right, reported as its Wilson-Hilferty z; the shift is the
  // enlarged fit's change of C (Frisch-Waugh), relative to C. NaN where the finer curve
  // exceeds the shape limits.
  ShapeScore curveScore(size_t i, double variation_z) const {
    const StiffnessShape& sh = o_.stiffness_shape;
    const bool table = sh.kind == StiffnessShape::Kind::Table;
    StiffnessShape fine = sh;
    fine.n = table ? 2 * sh.n : std::min(2 * sh.n, int{StiffnessShape::kMaxHarmonics});
    if (fine.n == sh.n || fine.n > StiffnessShape::kMaxNodes || !(std::abs(loc_[i][2]) > 0.0))
      return {};
    const Index b = ranges_[i].first, e = ranges_[i].second;
    const int nbf = fine.unknowns(), q = nbf - nb_;
    double mean_t = 0.0;
    const bool c1 = std::abs(variation_z) > 1.0 && torqueVaries(b, e, &mean_t);
    // The finer model's unknowns: the locals before the basis, the fine basis, (C1).
    const Params p = makeParams(loc_[i], sh_);
    Params pf = p;
    pf.nb = nbf;
    pf.m = basis_first_ + nbf + (c1 ? 1 : 0);
    for (int k = 0; k < nbf; ++k) pf.role[basis_first_ + k] = Role::Basis;
    for (int k = 0; k < nbf; ++k) {
      const int j = k / 2, j1 = (j + 1) % sh.n;
      pf.basis[k] = !table ? (k < nb_ ? p.basis[k] : 0.0)
                           : (k % 2 == 0 ? p.basis[j] : 0.5 * (p.basis[j] + p.basis[j1]));
    }
    if (c1) pf.role[pf.m - 1] = Role::Theta1, pf.theta1 = 0.0, pf.t_ref = mean_t;
    const SegmentSimulator sim(fm_, false, &fine, nullptr);
    const int mj = basis_first_ + nb_ + (c1 ? 1 : 0);
    Eigen::MatrixXd rows(e - b, 1 + mj + q);  // e, J (C1 last), D
    sim.run(b, e, pf, substeps_, [&](Index n, const double* z) {
      auto F = [&](int k) { return z[2 + 2 * (basis_first_ + (k + nbf) % nbf)]; };
      rows(n - b, 0) = s_.dte[n] - z[0];
      for (int a = 0; a < basis_first_; ++a) rows(n - b, 1 + a) = z[2 + 2 * a];
      for (int k = 0; k < nb_; ++k)
        rows(n - b, 1 + basis_first_ + k) =
            table ? F(2 * k) + 0.5 * (F(2 * k - 1) + F(2 * k + 1)) : F(k);
      if (c1) rows(n - b, mj) = z[2 + 2 * (pf.m - 1)];
      for (int k = 0; k < q; ++k) rows(n - b, 1 + mj + k) = table ? F(2 * k + 1) : F(nb_ + k);
    });
    return projectedScore(whiten(rows, noise_of_[i]), mj, std::abs(loc_[i][2]));
  }

  // The score of the last q columns of w = [e, J (mj columns, C the third), D (q)] (curveScore).
  static ShapeScore projectedScore(const Eigen::MatrixXd& w, Index mj, double C) {
    Eigen::MatrixXd J = w.middleCols(1, mj), D = w.rightCols(w.cols() - 1 - mj);
    const double c_norm = J.col(2).norm();
    for (Eigen::MatrixXd* M : {&J, &D}) {
      for (Index c = 0; c < M->cols(); ++c) {
        const double norm = M->col(c).norm();
        if (norm > 0.0) M->col(c) /= norm;
      }
    }
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(J);
    const Eigen::MatrixXd beta = qr.solve(D);  // D regressed on the sensitivities
    const Eigen::VectorXd ep = w.col(0) - J * qr.solve(w.col(0));
    const Eigen::MatrixXd Dp = D - J * beta;
    const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qd(Dp);
    const Eigen::VectorXd g = qd.solve(ep);  // the enlarged fit's extra unknowns
    const double dof = static_cast<double>(w.rows() - qr.rank()), df = qd.rank();
    const double s2 = ep.squaredNorm() / dof;
    if (!(dof > 0.0 && s2 > 0.0 && df > 0.0 && c_norm > 0.0)) return {};
    const double S = (Dp * g).squaredNorm() / s2, v = 2.0 / (9.0 * df);
    return {(std::cbrt(S / df) - (1.0 - v)) / std::sqrt(v), -(beta * g)[2] / c_norm / C};
  }

  // Whether the torque varies within samples [b, e) (relative standard deviation above 1e-9),
  // with its mean into *mean.
  bool torqueVaries(Index b, Index e, double* mean) const {
    if (s_.torque == nullptr || e - b < 2) return false;
    double mean_t = 0.0, var_t = 0.0;
    for (Index n = b; n < e; ++n) mean_t += s_.torque[n];
    mean_t /= static_cast<double>(e - b);
    for (Index n = b; n < e; ++n) var_t += (s_.torque[n] - mean_t) * (s_.torque[n] - mean_t);
    *mean = mean_t;
    return std::sqrt(var_t / static_cast<double>(e - b)) > 1e-9 * std::abs(mean_t);
  }

  // Rows n >= p of `M` (one row per sample of a segment) filtered by the AR model as the
  // residuals are (Accumulator): e_n = M_n + sum_k a_k M_{n-k}.
  static Eigen::MatrixXd whiten(const Eigen::MatrixXd& M, const NoiseModel& nm) {
    const Index rows = std::max<Index>(M.rows() - nm.p, 0);
    Eigen::MatrixXd out(rows, M.cols());
    for (Index c = 0; c < M.cols(); ++c) {  // by columns: the same operations per element
      const double* in = M.col(c).data();
      double* o = out.col(c).data();
      for (Index n = 0; n < rows; ++n) {
        o[n] = in[n + nm.p];
        for (int k = 0; k < nm.p; ++k) o[n] += nm.a[k] * in[n + nm.p - k - 1];
      }
    }
    return out;
  }

  // The splitmix64 sequence: the next 64 random bits of the state `x`.
  static std::uint64_t splitmix64(std::uint64_t* x) {
    std::uint64_t z = (*x += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }

  // Segment i's sensitivities at the solution, prewhitened (rows x m).
  Eigen::MatrixXd whitenedSensitivities(size_t i) const {
    return whiten(solutionRows(i, false), noise_of_[i]);
  }

  // Segment i's sensitivities at p (p.m unknowns: the variation test's enlarged problem),
  // prewhitened (rows x p.m). The rows its enlarged evaluation at p kept would do by one pass
  // fewer, but that fused pass's x86-64-v3 clone contracts FMA: up to 5e-12 relative off these.
  Eigen::MatrixXd whitenedSensitivitiesAt(size_t i, const Params& p) const {
    switch (p.m) {  // the common sizes (known, greybox square: 3 and 5 unknowns plus C1)
      case 4:
        return whitenedSensitivitiesOf<4>(i, p);
      case 6:
        return whitenedSensitivitiesOf<6>(i, p);
      default:
        return whitenedSensitivitiesOf<0>(i, p);
    }
  }
  // MT: p.m when fixed at compile time (0: p.m).
  template <int MT>
  Eigen::MatrixXd whitenedSensitivitiesOf(size_t i, const Params& p) const {
    const Index b = ranges_[i].first, e = ranges_[i].second;
    const int m = MT > 0 ? MT : p.m;
    Eigen::MatrixXd J(e - b, m);
    auto visit = [&](Index n, const double* z) {
      for (int a = 0; a < m; ++a) J(n - b, a) = z[2 + 2 * a];
    };
    if (sim_.tableApplies(substeps_)) {
      sim_.runTable<MT>(tableOf(i), p, visit);
    } else {
      sim_.run(b, e, p, substeps_, visit);
    }
    return whiten(J, noise_of_[i]);
  }

  // Segment i's rows at the solution, not whitened: the residual y - yhat (column 0, when
  // `residual`) and the sensitivities (rows x (residual + m)). Held stiffness and constant C:
  // from the rows of a fused pass (the same numbers), those of the last accepted pass where
  // they were kept (keepFinalRows).
  Eigen::MatrixXd solutionRows(size_t i, bool residual) const {
    const Index b = ranges_[i].first, e = ranges_[i].second;
    const int m = m_, r0 = residual ? 1 : 0;
    Eigen::MatrixXd J(e - b, r0 + m);
    const Params p = makeParams(loc_[i], sh_);
    const SegmentTable* t = sim_.tableApplies(substeps_) ? &tableOf(i) : nullptr;
    const bool kept = i < final_rows_.size() && final_rows_[i].seg == i && final_rows_[i].m == m;
    KeptRows rows;
    Normal unused;
    if (t != nullptr && !t->smooth && SegmentSimulator::constantC(p) &&
        (kept || evaluateFused(*t, p, NoiseModel{}, &unused, &rows))) {
      const RowBuffer& Jr = kept ? final_rows_[i].J : rows.J;
      const Index stride = 4 * (m / 4 + 1);  // the row (r, J_1..J_m) of each sample
      for (Index n = 0; n < e - b; ++n) {
        for (int a = 1 - r0; a <= m; ++a)
          J(n, a - 1 + r0) = Jr[static_cast<size_t>(stride * n + a)];
      }
    } else {
      sim_.run(b, e, p, substeps_, [&](Index n, const double* z) {
        if (residual) J(n - b, 0) = s_.dte[n] - z[0];
        for (int a = 0; a < m; ++a) J(n - b, r0 + a) = z[2 + 2 * a];
      });
    }
    return J;
  }

  // The converged model's response (zero initial state, no STE forcing: linear in the torque)
  // to the torque in noise_torque_ over segment i, prewhitened. `tab`: the segment's look-ups on
  // the noise record (buildTable), its stage torques refilled here: the affine maps of the held
  // stiffness then step the response (no sensitivities) at a few flops per sample.
  Eigen::VectorXd responseToTorque(size_t i, SegmentTable* tab) const {
    const Index b = ranges_[i].first, e = ranges_[i].second;
    Eigen::MatrixXd g(e - b, 1);
    auto visit = [&](Index n, const double* z) { g(n - b, 0) = z[0]; };
    const Params p = noiseParams(i);
    if (noise_sim_->tableApplies(substeps_)) {
      for (Index n = b; n < e; ++n) tab->T[n - b] = noise_torque_[static_cast<size_t>(n)];
      for (Index j = b; j + 1 < e; ++j) tab->T_mid[j - b] = noise_fm_->torque(j, 0.5, b, e);
      noise_sim_->runTable<0>(*tab, p, visit);
    } else {
      noise_sim_->run(b, e, p, substeps_, visit);
    }
    return whiten(g, noise_of_[i]).col(0);
  }

  // The converged model of segment i for its response to the torque: state only, from rest.
  Params noiseParams(size_t i, bool state = false) const {
    Params p = makeParams(loc_[i], sh_);
    p.m = 0, p.nste = 0;
    if (!state) p.y0 = 0.0, p.v0 = 0.0;  // from rest (the response to the torque alone)
    return p;
  }

  // One draw of white torque noise of segment i's level into noise_torque_: Rademacher draws
  // (+-sigma, independent, zero mean, variance sigma^2): the covariance of a linear response is
  // the same as for Gaussian draws, its Monte Carlo estimate scatters less (no fourth-moment
  // excess) and 64 signs come from one splitmix64 number.
  void drawTorqueNoise(size_t i, std::uint64_t* rng) {
    const Index b = ranges_[i].first, e = ranges_[i].second;
    const double sd = torque_sigma_[i];
    std::uint64_t bits = 0;
    for (Index n = b; n < e; ++n) {
      if ((n - b) % 64 == 0) bits = splitmix64(rng);
      noise_torque_[static_cast<size_t>(n)] = (bits & 1u) ? sd : -sd;
      bits >>= 1;
    }
  }

  // Each active segment's torque-noise level (model-free), before the iteration (keepFinalRows):
  // torque_sd_ the estimate, torque_sigma_ the level used (zero where the torque is exact to
  // rounding). None for the load law or without a torque channel.
  void torqueLevels() {
    torque_sd_.assign(nseg_, kNaN);
    torque_sigma_.assign(nseg_, 0.0);
    if (s_.torque == nullptr || load_) return;
    for (size_t i = 0; i < nseg_; ++i) {
      if (!active_[i]) continue;
      const Index b = ranges_[i].first, e = ranges_[i].second;
      const double sd = torqueNoiseEstimate(s_.torque + b, e - b);
      torque_sd_[i] = sd;
      double peak = 0.0;
      for (Index n = b; n < e; ++n) peak = std::max(peak, std::abs(s_.torque[n]));
      if (std::isfinite(sd) && sd > 1e-12 * peak) torque_sigma_[i] = sd;
    }
  }

  // A step of the torque between two samples inside a segment (flag load_step). The forward model
  // interpolates T1 linearly across each sample interval, so a step inside one is placed at its
  // middle in effect, while it can lie anywhere in it: the impulse force_factor dT dt is off by
  // up to half of itself, and the response misses a free vibration of up to
  // a = force_factor |dT| dt / (2 omega0). Measured before the flag (held-out sweeps, 2026-11-28):
  // segments with a load step at 40 dB up to 8 standard errors off without a warning (seeds
  // 15282, 17666; 112 such clean noisy segments, rms z 1.60). The step is the segment's largest
  // jump of an increment over the mean of its two neighbours, j_n = d_n - (d_{n-1} + d_{n+1}) / 2
  // (a step: its size; a smooth load: its curvature, ~dT dt^2; white torque noise of standard
  // deviation s: sqrt(5) s), kept where it stands out of the torque noise by kStepSigmas and of
  // its neighbouring increments by kStepRatio (a kink of a trapezoid load, which the linear
  // interpolation follows to second order, has |j| <= max |d_{n+-1}|).
  //
  // A glitch (torque_glitch): one sample n off both neighbours by g = T_n - (T_{n-1} + T_{n+1}) / 2
  // (a meter or transmission spike). Its increments d_n ~ g and d_{n+1} ~ -g are as large as
  // each other, so it is no step; the interpolated torque turns it into an impulse
  // force_factor g dt the gear never felt, whose free vibration of up to
  // force_factor |g| dt / omega0 stays unmodelled. Before the flag (hostile review, 2026-11-28):
  // 20-200 N*m in one sample left 9 of 42 clean segments beyond 4 C_std (up to 7.7). Kept where
  // g stands out of the torque noise (sd sqrt(3/2)) by kStepSigmas and of the net change across
  // it and of the increments next to it by kStepRatio (a step has |g| = |T_{n+1} - T_{n-1}| / 2,
  // a smooth load |g| ~ curvature dt^2).
  //
  // A staircase (torqueQuantum: the torque on a lattice of levels q apart, exact to rounding
  // otherwise; quantisationShifts) steps by q at every level change: its largest is judged as a
  // load step too (the load crosses the level somewhere inside the interval).
  void loadSteps() {
    constexpr double kStepSigmas = 8.0, kStepRatio = 4.0;
    glitches_.assign(nseg_, {});
    quantum_.assign(nseg_, 0.0);
    if (s_.torque == nullptr) return;
    const double* t = s_.torque;
    auto inc = [&](Index n) { return n >= 1 && n < s_.n ? t[n] - t[n - 1] : 0.0; };
    for (size_t i = 0; i < nseg_; ++i) {
      if (!active_[i]) continue;
      const Index b = ranges_[i].first, e = ranges_[i].second;
      if (piecewise_ && torque_sigma_[i] == 0.0) quantum_[i] = torqueQuantum(t, b, e);
      // (torqueLevels' estimate where it made one: the load law's model has none)
      double sd = std::isfinite(torque_sd_[i]) ? torque_sd_[i] : torqueNoiseEstimate(t + b, e - b);
      if (!std::isfinite(sd)) sd = 0.0;
      // On a staircase a load at a level's midpoint toggles one sample by q: rounding
      // (quantisationShifts), not a glitch; the rounding's own spread q / sqrt(12) then.
      const double glitch_min =
          kStepSigmas * std::sqrt(1.5) * std::max(sd, quantum_[i] / std::sqrt(12.0));
      double best = 0.0, spike = 0.0;
      Index at = -1, spike_at = -1;
      for (Index n = b + 1; n < e; ++n) {  // the interval (n - 1, n)
        const double before = inc(n - 1), here = inc(n), after = inc(n + 1);
        const double j = here - 0.5 * (before + after);
        const double around = std::max(std::abs(before), std::abs(after));
        if (std::abs(j) > std::abs(best) && std::abs(j) > kStepRatio * around) best = j, at = n;
        if (n + 1 >= e) continue;  // the sample n with both neighbours in the segment
        const double g = 0.5 * (here - after);
        const double beside =
            std::max({0.5 * std::abs(here + after), std::abs(before), std::abs(inc(n + 2))});
        if (!(std::abs(g) > kStepRatio * beside && std::abs(g) > glitch_min)) continue;
        glitches_[i].emplace_back(n, g);  // every glitch (glitchShifts), the largest reported
        if (std::abs(g) > std::abs(spike)) spike = g, spike_at = n;
      }
      SegmentEstimate& est = res_->segments[i];
      const double ff = fm_.gear().force_factor;
      if (at >= 0 && std::isfinite(best) && std::abs(best) > kStepSigmas * std::sqrt(5.0) * sd) {
        est.torque_step = best;
        est.torque_step_time = s_.time(at) - 0.5 * s_.dt;
        est.torque_step_response = std::abs(ff * best) * s_.dt / (2.0 * res_->omega0);
      }
      if (spike_at >= 0 && std::isfinite(spike)) {
        est.torque_glitch = spike;
        est.torque_glitch_time = s_.time(spike_at);
        est.torque_glitch_response = std::abs(ff * spike) * s_.dt / res_->omega0;
        est.torque_glitches = static_cast<long>(glitches_[i].size());
      }
    }
  }

  // The level step q of a torque quantised without dither over samples [b, e) (0: none): most
  // increments zero, the others whole multiples of the smallest, and at least kMinChanges level
  // changes (a load stepping once or twice is a load, not a quantiser).
  static double torqueQuantum(const double* t, Index b, Index e) {
    constexpr long kMinChanges = 3;
    constexpr double kLattice = 1e-6;  // of q: the increments' distance from whole multiples
    double q = std::numeric_limits<double>::infinity();
    long changes = 0;
    for (Index n = b + 1; n < e; ++n) {
      const double d = std::abs(t[n] - t[n - 1]);
      if (d > 0.0) q = std::min(q, d), ++changes;
    }
    if (changes < kMinChanges || 2 * changes > e - b || !std::isfinite(q)) return 0.0;
    for (Index n = b + 1; n < e; ++n) {
      const double k = std::abs(t[n] - t[n - 1]) / q;
      if (!(std::abs(k - std::round(k)) <= kLattice)) return 0.0;
    }
    return q;
  }

  // The torque a staircase of levels q apart rounded, over samples [b, e) into out[0, e - b):
  // straight lines through its level crossings, each the mean of the two levels half a sample
  // before the first sample of the new level (a rounding quantiser changes level where the load
  // crosses the levels' midpoint), extended beyond the first and last crossing by the nearest
  // two's line, and kept within each sample's rounding band (+-q/2). Only the segment's own
  // samples are read, so a segment gets the same answer from any view of the record (batch,
  // streamed, live).
  void staircaseTorque(Index b, Index e, double q, double* out) const {
    const double* t = s_.torque;
    std::vector<std::pair<double, double>> cross;  // (time in samples, torque)
    for (Index n = b + 1; n < e; ++n) {
      if (t[n] != t[n - 1]) cross.emplace_back(n - 0.5, 0.5 * (t[n] + t[n - 1]));
    }
    const size_t nc = cross.size();  // >= 2 (torqueQuantum: at least 3 changes)
    size_t k = 0;
    for (Index n = b; n < e; ++n) {
      const double x = static_cast<double>(n);
      while (k < nc && cross[k].first < x) ++k;
      const size_t hi = std::clamp<size_t>(k, 1, nc - 1);
      const auto& p = cross[hi - 1];
      const auto& r = cross[hi];
      const double v = p.second + (r.second - p.second) * (x - p.first) / (r.first - p.first);
      out[n - b] = std::clamp(v, t[n] - 0.5 * q, t[n] + 0.5 * q);
    }
  }

  // How far the quantisation of each staircase segment's torque (loadSteps) moved its C, to
  // first order: the model's response to the samples minus the torque they rounded
  // (staircaseTorque) through the segment's fit (torqueErrorEffect); and which of the two the
  // DTE supports (a load that really steps leaves the free vibrations of its steps in the
  // response, a quantised smooth load does not).
  void quantisationShifts() {
    for (size_t i = 0; i < nseg_; ++i) {
      if (!active_[i] || !(quantum_[i] > 0.0)) continue;
      SegmentEstimate& est = res_->segments[i];
      est.torque_quantum = quantum_[i];
      const Index b = ranges_[i].first, e = ranges_[i].second;
      std::vector<double> smooth(static_cast<size_t>(e - b));
      staircaseTorque(b, e, quantum_[i], smooth.data());
      const TorqueErrorEffect te = torqueErrorEffect(i, [&](double* err) {
        for (Index n = b; n < e; ++n) err[n] = s_.torque[n] - smooth[static_cast<size_t>(n - b)];
      });
      est.torque_quantisation_shift = te.shift;
      est.torque_quantisation_fit = te.fit, est.torque_quantisation_fit_std = te.fit_std;
    }
  }

  // The model on a torque record of its own (noise_torque_, zero), for responses to a torque
  // perturbation (responseToTorque): the torque noise's, a glitch's.
  void makeNoiseModel() {
    if (noise_sim_ != nullptr) return;
    noise_torque_.assign(static_cast<size_t>(s_.n), 0.0);
    noise_view_ = s_;
    noise_view_.torque = noise_torque_.data();
    noise_fm_ = std::make_unique<ForwardModel>(noise_view_, fm_.gear(), o_.formulation, ranges_);
    noise_sim_ = std::make_unique<SegmentSimulator>(
        *noise_fm_, !reference_, shape_ ? &o_.stiffness_shape : nullptr, nullptr);
  }

  // How far each piecewise segment's torque glitches (loadSteps, all of them) moved its C, to
  // first order: the converged model's response G to the glitches alone (from rest),
  // prewhitened, through the segment's solve map, dtheta = -(Jw' Jw)^-1 Jw' W G (the model puts
  // their impulses into the response the data do not hold). The shared models keep loadSteps'
  // bound (of the largest).
  void glitchShifts() {
    if (!piecewise_) return;
    for (size_t i = 0; i < nseg_; ++i) {  // (glitches_: empty without a torque or off active_)
      if (glitches_[i].empty()) continue;
      res_->segments[i].torque_glitch_shift = torqueErrorEffect(i, [&](double* err) {
                                                for (const auto& [n, g] : glitches_[i]) err[n] = g;
                                              }).shift;
    }
  }

  // What an error of the torque samples (the samples minus the torque the gear felt, written by
  // fill(err) into the record-indexed err over segment i) did to segment i's fit, to first
  // order, with g = W G err (G the converged model's response from rest, prewhitened) and the
  // prewhitened residual r and sensitivities Jw at the solution:
  // - shift: how far it moved C, -[(Jw' Jw)^-1 Jw' g]_C (the model puts the error's response
  //   into the fit, the data do not hold it);
  // - fit: the share of the error the DTE itself supports, -r' Pg / |Pg|^2 with Pg the part of g
  //   the fit cannot absorb (1: the error is real, the data follow the corrected torque; 0: the
  //   samples were the load), and its standard error sigma / |Pg|. NaN where not solvable.
  struct TorqueErrorEffect {
    double shift = kNaN, fit = kNaN, fit_std = kNaN;
  };
  template <class Fill>
  TorqueErrorEffect torqueErrorEffect(size_t i, Fill&& fill) {
    constexpr int kC = 2;  // C among the piecewise locals [y0, v0, C, ...]
    makeNoiseModel();
    const Index b = ranges_[i].first, e = ranges_[i].second;
    SegmentTable tab;
    if (noise_sim_->tableApplies(substeps_)) noise_sim_->buildTable(b, e, &tab);
    fill(noise_torque_.data());
    const Eigen::VectorXd g = responseToTorque(i, &tab);
    std::fill(noise_torque_.begin() + b, noise_torque_.begin() + e, 0.0);
    const Eigen::MatrixXd rows = whiten(solutionRows(i, true), noise_of_[i]);
    const Eigen::VectorXd r = rows.col(0);
    const Eigen::MatrixXd Jw = rows.rightCols(rows.cols() - 1);
    const Eigen::VectorXd d = (Jw.transpose() * Jw).ldlt().solve(Jw.transpose() * g);
    TorqueErrorEffect out;
    if (d.size() > kC && std::isfinite(d[kC])) out.shift = -d[kC];
    const Eigen::VectorXd pg = g - Jw * d;
    const double den = pg.squaredNorm();
    if (den > 0.0 && std::isfinite(den)) {
      out.fit = -r.dot(pg) / den;
      out.fit_std = std::sqrt(sigma2Of(i) / den);
    }
    return out;
  }

  // Torque-meter noise (output_error.hpp): each segment's estimated level, and the covariance
  // its response adds to the unknowns: tcov_ll_ (locals) and tcov_ss_ (shared, of the segment's
  // problem). Zero where the torque is exact to rounding.
  void torqueNoise() {
    tcov_ll_.assign(nseg_, Eigen::MatrixXd::Zero(nl_, nl_));
    tcov_ss_.assign(nseg_, Eigen::MatrixXd::Zero(ns_, ns_));
    tgram_.assign(nseg_, Eigen::MatrixXd());
    if (s_.torque == nullptr || load_) return;
    bool any = false;
    for (size_t i = 0; i < nseg_; ++i) {
      if (!active_[i]) continue;
      res_->segments[i].torque_noise_std = torque_sd_[i];
      any = any || torque_sigma_[i] > 0.0;
    }
    if (!any) return;
    makeNoiseModel();
    draw_normals_.assign(nseg_, Normal{});
    for (const auto& set : problems_) {
      bool noisy = false;
      for (size_t i : set) noisy = noisy || torque_sigma_[i] > 0.0;
      if (!noisy) continue;
      // The residual change -G w of a torque noise w moves the unknowns by the solve map of the
      // converged problem applied to Jw^T W G w (Jw the prewhitened sensitivities).
      std::vector<Eigen::MatrixXd> Jw(set.size());
      for (size_t q = 0; q < set.size(); ++q) {
        if (torque_sigma_[set[q]] > 0.0) Jw[q] = whitenedSensitivities(set[q]);
        if (set[q] < final_rows_.size()) final_rows_[set[q]] = KeptRows{};
      }
      if (reference_)
        torqueNoiseImpulses(set, Jw);
      else if (noise_sim_->tableApplies(substeps_))
        torqueNoiseExact(set, Jw);
      else
        torqueNoiseDraws(set, Jw);
    }
  }

  // Exact: the right-hand sides rhs_i = Jw_i^T W G_i w_i of the segments are independent with
  // covariance Q_i = sigma_i^2 M_i M_i^T, M_i = Jw_i^T W G_i (torqueResponseGram: one backward
  // pass through the converged model's step maps); the solve map is linear, so
  //   dg = A^-1 sum_i P_i rhs_i,  P_i = [-N_sl,i N_ll,i^-1, I],
  //   dl_i = N_ll,i^-1 (D_i rhs_i - N_ls,i A^-1 sum_{j != i} P_j rhs_j),  D_i = [I, 0] - N_ls,i
  //   A^-1 P_i,
  // and their covariances follow in closed form (what the draws estimate).
  void torqueNoiseExact(const Set& set, const std::vector<Eigen::MatrixXd>& Jw) {
    const int nl = nl_, ns = ns_;
    std::vector<Eigen::MatrixXd> Q(set.size()), P(set.size());
    Eigen::MatrixXd T = Eigen::MatrixXd::Zero(ns, ns);
    const Eigen::MatrixXd& Ainv = Ainv_of_[set[0]];
    for (size_t q = 0; q < set.size(); ++q) {
      const size_t i = set[q];
      const double sd = torque_sigma_[i];
      Q[q] = sd > 0.0 ? Eigen::MatrixXd(sd * sd * torqueResponseGram(i, Jw[q]))
                      : Eigen::MatrixXd::Zero(m_, m_);
      tgram_[i] = Q[q];
      P[q] = Eigen::MatrixXd::Zero(ns, m_);
      P[q].leftCols(nl) = -normals_[i].N.block(nl, 0, ns, nl) * Nll_inv_[i];
      P[q].rightCols(ns).setIdentity();
      T += P[q] * Q[q] * P[q].transpose();
    }
    const Eigen::MatrixXd Cg = Ainv * T * Ainv;
    for (size_t q = 0; q < set.size(); ++q) {
      const size_t i = set[q];
      const Eigen::MatrixXd Nls = normals_[i].N.block(0, nl, nl, ns);
      Eigen::MatrixXd D = -Nls * Ainv * P[q];
      D.leftCols(nl) += Eigen::MatrixXd::Identity(nl, nl);
      const Eigen::MatrixXd others = T - P[q] * Q[q] * P[q].transpose();
      const Eigen::MatrixXd inner =
          D * Q[q] * D.transpose() + Nls * Ainv * others * Ainv * Nls.transpose();
      tcov_ll_[i] = Nll_inv_[i] * inner * Nll_inv_[i];
      tcov_ss_[i] = Cg;
    }
  }

  // M^T M for segment i, M = Jw^T W G (m x samples): the prewhitening's transpose W^T applied
  // to the sensitivities gives the weight of each response sample, and the adjoint (backward)
  // recursion of the state steps x_{j+1} = A_j x_j + (the torque samples' terms) carries the
  // weights to the torque samples. Split intervals' maps by unit inputs through the generic RK4.
  // Jw's columns: the problem's unknowns, or one projected direction (torqueProjectedVariance).
  Eigen::MatrixXd torqueResponseGram(size_t i, const Eigen::MatrixXd& Jw) {
    switch (Jw.cols()) {  // the common problem sizes unrolled
      case 1:
        return torqueResponseGramOf<1>(i, Jw);
      case 3:
        return torqueResponseGramOf<3>(i, Jw);
      case 4:
        return torqueResponseGramOf<4>(i, Jw);
      case 5:
        return torqueResponseGramOf<5>(i, Jw);
      default:
        return torqueResponseGramOf<0>(i, Jw);
    }
  }
  // MT: Jw's columns when fixed at compile time (0: Jw.cols()).
  template <int MT>
  Eigen::MatrixXd torqueResponseGramOf(size_t i, const Eigen::MatrixXd& Jw) {
    const Index b = ranges_[i].first, e = ranges_[i].second, n = e - b;
    const NoiseModel& nm = noise_of_[i];
    const int m = MT > 0 ? MT : static_cast<int>(Jw.cols());
    // Row-major scratch reused over the segments (first touch of fresh pages is slow here).
    std::vector<double>& U = adj_u_;  // W^T Jw, a row per sample
    U.assign(static_cast<size_t>(n * m), 0.0);
    for (Index r = 0; r < Jw.rows(); ++r) {
      double* u = &U[static_cast<size_t>((r + nm.p) * m)];
      for (int a = 0; a < m; ++a) u[a] += Jw(r, a);
      for (int k = 0; k < nm.p; ++k) {
        double* uk = &U[static_cast<size_t>((r + nm.p - k - 1) * m)];
        for (int a = 0; a < m; ++a) uk[a] += nm.a[k] * Jw(r, a);
      }
    }
    const Params p = noiseParams(i);
    SegmentTable& tab = adj_tab_;
    noise_sim_->buildTable(b, e, &tab);
    std::vector<SegmentSimulator::StateMap>& maps = adj_maps_;
    noise_sim_->stateMaps(tab, p, &maps);
    std::vector<double>& M = adj_m_;  // M^T, a row per torque sample
    M.assign(static_cast<size_t>(n * m), 0.0);
    auto addTo = [&](Index s, double w0, const double* x0, double w1, const double* x1) {
      double* row = &M[static_cast<size_t>((s - b) * m)];
      for (int a = 0; a < m; ++a) row[a] += w0 * x0[a] + w1 * x1[a];
    };
    double lam0[kMaxParams] = {0}, lam1[kMaxParams] = {0}, g[kMaxParams], nx0[kMaxParams];
    for (Index idx = n - 1; idx >= 1; --idx) {
      const double* u = &U[static_cast<size_t>(idx * m)];
      for (int a = 0; a < m; ++a) lam0[a] += u[a];  // the response sample idx = the state's y
      const Index j = b + idx - 1;
      double A[2][2];
      if (tab.key[static_cast<size_t>(idx - 1)] != SegmentTable::kSplit) {
        const SegmentSimulator::StateMap& sm = maps[static_cast<size_t>(idx - 1)];
        for (int q = 0; q < 3; ++q) {
          for (int a = 0; a < m; ++a) g[a] = sm.c[0][q] * lam0[a] + sm.c[1][q] * lam1[a];
          const Index at = q == 0 ? j : j + 1;
          if (q != 1) {
            double* row = &M[static_cast<size_t>((at - b) * m)];
            for (int a = 0; a < m; ++a) row[a] += g[a];
            continue;
          }
          Index first;  // the midpoint torque's stencil weights
          double w[4];
          const int nw = noise_fm_->cubicWeights(j, 0.5, b, e, &first, w);
          for (int k = 0; k < nw; ++k) {
            if (w[k] == 0.0) continue;
            double* row = &M[static_cast<size_t>((first + k - b) * m)];
            for (int a = 0; a < m; ++a) row[a] += w[k] * g[a];
          }
        }
        std::copy(&sm.A[0][0], &sm.A[0][0] + 4, &A[0][0]);
      } else {
        // Unit torque samples (zero state) that can reach interval j: the cubic stencils lie
        // within j-2..j+3; then unit states (zero torque).
        for (Index s = std::max<Index>(b, j - 3); s < std::min<Index>(e, j + 5); ++s) {
          double z[2] = {0.0, 0.0};
          noise_torque_[static_cast<size_t>(s)] = 1.0;
          noise_sim_->stepGeneric(j, b, e, p, z);
          noise_torque_[static_cast<size_t>(s)] = 0.0;
          addTo(s, z[0], lam0, z[1], lam1);
        }
        for (int c = 0; c < 2; ++c) {
          double z[2] = {c == 0 ? 1.0 : 0.0, c == 1 ? 1.0 : 0.0};
          noise_sim_->stepGeneric(j, b, e, p, z);
          A[0][c] = z[0], A[1][c] = z[1];
        }
      }
      for (int a = 0; a < m; ++a) {
        nx0[a] = A[0][0] * lam0[a] + A[1][0] * lam1[a];
        lam1[a] = A[0][1] * lam0[a] + A[1][1] * lam1[a];
        lam0[a] = nx0[a];
      }
    }
    Eigen::MatrixXd& Mc = adj_M_;  // column-major for the product, as before
    Mc.resize(n, m);
    for (Index s = 0; s < n; ++s) {
      for (int a = 0; a < m; ++a) Mc(s, a) = M[static_cast<size_t>(s * m + a)];
    }
    return Mc.transpose() * Mc;
  }

  // The variance the torque-meter noise adds to u'e, e segment i's prewhitened residual and u a
  // direction in its rows (a score's): sigma_T^2 |G^T W^T u|^2, the torque noise's response
  // G w projected on u, as C_std carries it (torqueNoise). Exact by torqueResponseGram with one
  // column where the step maps are tabled; otherwise by unit impulses on the reference path, else
  // by Rademacher draws (torqueNoiseDraws' seeding and rule: batches of 16 until the Monte Carlo
  // standard error is below 10 % of the total variance, `base` + the added, at most 64).
  double torqueProjectedVariance(size_t i, const Eigen::VectorXd& u, double base) {
    const double sd = torque_sigma_.empty() ? 0.0 : torque_sigma_[i];
    if (!(sd > 0.0) || noise_sim_ == nullptr) return 0.0;
    if (!reference_ && noise_sim_->tableApplies(substeps_))
      return sd * sd * torqueResponseGram(i, u)(0, 0);
    constexpr int kBatch = 16, kMaxDraws = 64;
    constexpr double kMonteCarloTol = 0.1;  // of the total variance
    const Index b = ranges_[i].first, e = ranges_[i].second;
    SegmentTable tab;
    if (noise_sim_->tableApplies(substeps_)) noise_sim_->buildTable(b, e, &tab);
    double sum = 0.0;
    if (reference_) {
      for (Index s = b; s < e; ++s) {
        noise_torque_[static_cast<size_t>(s)] = sd;
        const double r = u.dot(responseToTorque(i, &tab));
        noise_torque_[static_cast<size_t>(s)] = 0.0;
        sum += r * r;
      }
      return sum;
    }
    std::uint64_t rng =
        0x9E3779B97F4A7C15ULL ^ static_cast<std::uint64_t>(std::llround(s_.time(b) / s_.dt));
    int draws = 0;
    while (draws < kMaxDraws) {
      for (int d = 0; d < kBatch; ++d) {
        drawTorqueNoise(i, &rng);
        const double r = u.dot(responseToTorque(i, &tab));
        sum += r * r;
      }
      draws += kBatch;
      const double vt = sum / draws;
      if (std::sqrt(2.0 / draws) * vt <= kMonteCarloTol * (base + vt)) break;
    }
    std::fill(noise_torque_.begin() + b, noise_torque_.begin() + e, 0.0);
    return sum / draws;
  }

  // The reference (tests): exact by brute force, one unit impulse sigma e_s of the torque per
  // sample s of each noisy segment in turn (the others' right-hand sides zero), each response
  // by the forward model and each through the solve map: sum of dl dl^T and dg dg^T.
  void torqueNoiseImpulses(const Set& set, const std::vector<Eigen::MatrixXd>& Jw) {
    std::vector<Eigen::MatrixXd> Sll(set.size(), Eigen::MatrixXd::Zero(nl_, nl_));
    Eigen::MatrixXd Sss = Eigen::MatrixXd::Zero(ns_, ns_);
    for (size_t i : set) draw_normals_[i] = normals_[i];
    Locals& dl = dl_scratch_;
    Eigen::VectorXd dg;
    SegmentTable tab;
    for (size_t q = 0; q < set.size(); ++q) {
      const size_t i = set[q];
      if (!(torque_sigma_[i] > 0.0)) continue;
      for (Index s = ranges_[i].first; s < ranges_[i].second; ++s) {
        for (size_t r : set) draw_normals_[r].rhs.setZero(m_);
        noise_torque_[static_cast<size_t>(s)] = torque_sigma_[i];
        draw_normals_[i].rhs = Jw[q].transpose() * responseToTorque(i, &tab);
        noise_torque_[static_cast<size_t>(s)] = 0.0;
        solveStep(set, draw_normals_, &dl, &dg, nullptr, nullptr);
        for (size_t r = 0; r < set.size(); ++r) Sll[r] += dl[set[r]] * dl[set[r]].transpose();
        if (ns_ > 0) Sss += dg * dg.transpose();
      }
    }
    for (size_t q = 0; q < set.size(); ++q) {
      tcov_ll_[set[q]] = Sll[q];
      tcov_ss_[set[q]] = Sss;
      draw_normals_[set[q]] = Normal{};
    }
  }

  // Monte Carlo where the step maps are not tabled (a greybox stiffness shape, several RK4 steps
  // per sample): draws of w through the solve map (solveStep with the converged normal
  // matrices), seeded by the segment's first sample (the same draws on every path), in batches
  // of 16 until the Monte Carlo standard error of the added variance is below 10 % of C's total
  // variance, at most 64 draws.
  void torqueNoiseDraws(const Set& set, const std::vector<Eigen::MatrixXd>& Jw) {
    constexpr int kBatch = 16, kMaxDraws = 64;
    constexpr double kMonteCarloTol = 0.1;  // of C's total variance
    std::vector<SegmentTable> tab(set.size());
    std::vector<std::uint64_t> rng(set.size());
    std::vector<Eigen::MatrixXd> Sll(set.size(), Eigen::MatrixXd::Zero(nl_, nl_));
    Eigen::MatrixXd Sss = Eigen::MatrixXd::Zero(ns_, ns_);
    std::vector<double> base(set.size());
    for (size_t q = 0; q < set.size(); ++q) {
      const size_t i = set[q];
      draw_normals_[i] = normals_[i];
      base[q] = cVariance(localCovariance(i), sigma2_pooled_ * Ainv_of_[i]);
      if (!(torque_sigma_[i] > 0.0)) continue;
      if (noise_sim_->tableApplies(substeps_))
        noise_sim_->buildTable(ranges_[i].first, ranges_[i].second, &tab[q]);
      const double first = s_.time(ranges_[i].first) / s_.dt;
      rng[q] = 0x9E3779B97F4A7C15ULL ^ static_cast<std::uint64_t>(std::llround(first));
    }
    Locals& dl = dl_scratch_;
    Eigen::VectorXd dg;
    int draws = 0;
    while (draws < kMaxDraws) {
      for (int d = 0; d < kBatch; ++d) {
        for (size_t q = 0; q < set.size(); ++q) {
          Normal& nm = draw_normals_[set[q]];
          nm.rhs.setZero(m_);
          if (Jw[q].size() == 0) continue;
          drawTorqueNoise(set[q], &rng[q]);
          nm.rhs = Jw[q].transpose() * responseToTorque(set[q], &tab[q]);
        }
        solveStep(set, draw_normals_, &dl, &dg, nullptr, nullptr);
        for (size_t q = 0; q < set.size(); ++q) Sll[q] += dl[set[q]] * dl[set[q]].transpose();
        if (ns_ > 0) Sss += dg * dg.transpose();
      }
      draws += kBatch;
      bool settled = true;
      for (size_t q = 0; q < set.size(); ++q) {
        const double vt = cVariance(Sll[q], Sss) / draws;
        settled = settled && std::sqrt(2.0 / draws) * vt <= kMonteCarloTol * (base[q] + vt);
      }
      if (settled) break;
    }
    for (size_t q = 0; q < set.size(); ++q) {
      tcov_ll_[set[q]] = Sll[q] / draws;
      tcov_ss_[set[q]] = Sss / draws;
      draw_normals_[set[q]] = Normal{};
    }
    std::fill(noise_torque_.begin(), noise_torque_.end(), 0.0);
  }

  // Within-segment variation of the damping with the load (piecewise model): the converged
  // constant-C problem plus the unknown C1 of C(t) = C0 + C1 (T1(t) - mean T1), evaluated once
  // at C1 = 0 with the segment's noise model; one Gauss-Newton step gives C1 and C0, the damping
  // at the segment's mean load, and their covariance sigma2 N^-1 (the prewhitened normal
  // equations of the problem plus one column). C0 is the segment's time-mean damping whenever
  // C(t) is linear in the load over the segment (constant C included), whereas the constant-C
  // fit weights C(t) by the response's sensitivity to it. Skipped when the torque is unknown or
  // does not vary in the segment (C1 not identifiable: the constant-C fit is then the same).
  void variationTest(size_t i, double sigma2, SegmentEstimate* e) {
    double mean_t = 0.0;
    if (!torqueVaries(ranges_[i].first, ranges_[i].second, &mean_t)) return;
    Params p = makeParams(loc_[i], sh_);
    if (p.m + 1 > kMaxParams) return;
    p.role[p.m] = Role::Theta1;
    p.theta1 = 0.0;
    p.t_ref = mean_t;
    ++p.m;
    Normal aug = evaluateAt(i, p, noise_of_[i]);
    const int last = p.m - 1;
    // C1 identifiable: its sensitivity not (nearly) a combination of the others'.
    const Eigen::MatrixXd Nrr = aug.N.topLeftCorner(last, last);
    const Eigen::VectorXd Nr1 = aug.N.col(last).head(last);
    const double schur = aug.N(last, last) - Nr1.dot(Nrr.ldlt().solve(Nr1));
    if (!(schur > 1e-10 * aug.N(last, last))) return;
    Eigen::MatrixXd inv = aug.N.ldlt().solve(Eigen::MatrixXd::Identity(p.m, p.m));
    Eigen::VectorXd d = inv * aug.rhs;
    double var1 = sigma2 * inv(last, last);
    // Torque-meter noise: the response of d[last] = e_last' inv Jw' e to it (torqueNoise).
    if (!torque_sigma_.empty() && torque_sigma_[i] > 0.0)
      var1 += torqueProjectedVariance(i, whitenedSensitivitiesAt(i, p) * inv.col(last), var1);
    if (!(var1 > 0.0) || !std::isfinite(d[last])) return;
    e->variation_z = d[last] / std::sqrt(var1);
    // Where C1 is significant the one step, linearised at C1 = 0, is iterated (Gauss-Newton on
    // the enlarged problem, a step kept only while the cost falls), and sigma^2 is the enlarged
    // fit's: the constant-C fit's residual holds the variation it could not follow.
    double s2 = sigma2;
    if (std::abs(e->variation_z) > QualityLimits::kVariationZ) {
      // Until the next step of C0 is below kEnlargedTol of its standard error (statistically
      // nothing; noise-free: 1e-10 relative) or no longer lowers the cost.
      constexpr double kEnlargedTol = 1e-3;
      auto sigma2Of = [&](const Normal& n) {
        return n.cost / static_cast<double>(std::max<long>(n.rows - p.m, 1));
      };
      bool moved = false;
      for (int it = 0; it < o_.max_iterations; ++it) {
        const double se0 = std::sqrt(std::max(sigma2Of(aug) * inv(2, 2), 0.0));
        if (std::abs(d[2]) <= std::max(kEnlargedTol * se0, 1e-10 * std::abs(p.theta0))) break;
        Params q = p;
        for (int k = 0; k < p.m; ++k) *q.slot(k) += d[k];
        const Normal next = evaluateAt(i, q, noise_of_[i]);
        if (!(next.cost < aug.cost)) {
          if (moved) d.setZero();  // no descent left: p is the enlarged fit to rounding
          break;
        }
        p = q, aug = next, moved = true;
        inv = aug.N.ldlt().solve(Eigen::MatrixXd::Identity(p.m, p.m));
        d = inv * aug.rhs;
      }
      if (moved) s2 = sigma2Of(aug);
    }
    e->C_mean_load = p.theta0 + d[2];
    e->C_mean_load_std = std::sqrt(std::max(s2 * inv(2, 2), 0.0));
  }

  void fillC(SegmentEstimate* e, double C, double var) const {
    e->C = C;
    e->C_std = std::sqrt(std::max(var, 0.0));
    e->c = coefficientFromC(C, me_);
    e->xi = ratioFromC(C, res_->omega0);
    e->refined = true;
  }

  std::string notConverged() const {
    return "output-error refinement stopped after the iteration limit (" +
           std::to_string(o_.max_iterations) + ") without converging to 1e-10";
  }

  // The stiffness unknowns of segment i (greybox levels or shape) into e.
  void fillStiffness(size_t i, const Eigen::MatrixXd& cov_ll, int k, SegmentEstimate* e) const {
    const Eigen::VectorXd& x = loc_[i];
    if (shape_) {
      // The refined curve and its extremes over a mesh cycle.
      e->stiffness_curve.resize(nb_);
      e->stiffness_curve_std.resize(nb_);
      for (int b = 0; b < nb_; ++b) {
        e->stiffness_curve[b] = me_ * x[basis_first_ + b];
        e->stiffness_curve_std[b] =
            me_ * std::sqrt(std::max(cov_ll(basis_first_ + b, basis_first_ + b), 0.0));
      }
      curveExtremes(o_.stiffness_shape, e->stiffness_curve, &e->k_min, &e->k_max);
      e->k_min_std = e->k_max_std = kNaN;
    } else if (grey_) {
      const int a = k, b = k + 1;
      e->k_min = me_ * x[a];
      e->k_max = me_ * (x[a] + x[b]);
      e->k_min_std = me_ * std::sqrt(std::max(cov_ll(a, a), 0.0));
      e->k_max_std = me_ * std::sqrt(std::max(cov_ll(a, a) + cov_ll(b, b) + 2 * cov_ll(a, b), 0.0));
    }
  }

  // Every refined segment: C, the stiffness, the residual statistics and its refined state.
  void fillSegments() {
    res_->windows.clear();
    for (size_t i = 0; i < nseg_; ++i) {
      if (!active_[i]) continue;
      SegmentEstimate& e = res_->segments[i];
      const Eigen::VectorXd& x = loc_[i];
      const Normal& nm = normals_[i];
      const double sigma2 = sigma2Of(i);
      // Covariance of this segment's unknowns [locals, shared], with the torque noise's.
      const Eigen::MatrixXd cov_ll = cov_ll_[i] + tcov_ll_[i];
      const Eigen::MatrixXd cov_ss = cov_ss_[i] + tcov_ss_[i];
      if (std::isfinite(e.torque_noise_std))
        e.C_torque_std = std::sqrt(std::max(cVariance(tcov_ll_[i], tcov_ss_[i]), 0.0));
      int k = 2;
      if (piecewise_) {
        // The constant-C fit is a weighted mean of C(t) over the segment; the reported C is the
        // damping at the segment's mean load where the load varies (variationTest).
        e.C_weighted = x[k];
        e.C_weighted_std = std::sqrt(std::max(cov_ll(k, k), 0.0));
        variationTest(i, sigma2, &e);
        if (grey_ && !shape_ && ste_ == nullptr && s_.mesh_state != nullptr) {
          const ShapeScore sc = shapeScore(i, e.variation_z);
          e.shape_z = sc.z, e.shape_shift = sc.shift;
        } else if (shape_ && ste_ == nullptr &&
                   !(e.C_torque_std > kCurveTorqueShare * std::sqrt(std::max(cov_ll(k, k), 0.0)))) {
          const ShapeScore sc = curveScore(i, e.variation_z);
          e.shape_z = sc.z, e.shape_shift = sc.shift;
        }
        if (!shape_ && ste_ == nullptr) {
          const ShapeScore st = switchTiming(i);
          e.switch_timing_z = st.z, e.switch_timing_shift = st.shift;
          e.switch_timing_power = st.power;
        }
        if (std::isfinite(e.C_mean_load)) {
          const double t = std::isfinite(e.C_torque_std) ? e.C_torque_std : 0.0;
          e.C_mean_load_std = std::hypot(e.C_mean_load_std, t);
          fillC(&e, e.C_mean_load, e.C_mean_load_std * e.C_mean_load_std);
        } else
          fillC(&e, x[k], cov_ll(k, k));
        ++k;
      } else if (load_) {
        const double T = e.mean_torque;
        fillC(&e, sh_[0] + sh_[1] * T, cov_ss(0, 0) + T * T * cov_ss(1, 1) + 2 * T * cov_ss(0, 1));
      } else {
        fillC(&e, sh_[0], cov_ss(0, 0));
      }
      // Shared damping (constant, load law): the square levels' shape test too (before, it ran
      // for the piecewise model only, and a greybox load law on a trapezoid stiffness was 6 SE
      // off without a warning: held-out seed 13618).
      if (!piecewise_ && grey_ && !shape_ && ste_ == nullptr && s_.mesh_state != nullptr) {
        const ShapeScore sc = shapeScore(i, 0.0);
        e.shape_z = sc.z, e.shape_shift = sc.shift;
      }
      fillStiffness(i, cov_ll, k, &e);
      ResidualStatistics& rs = e.residuals;
      rs.rms = std::sqrt(nm.raw / static_cast<double>(nm.samples));
      rs.lag1 = nm.raw > 0.0 ? nm.acov[1] / nm.raw : kNaN;
      rs.whitened_lag1 = nm.cost > 0.0 ? nm.wlag1 / nm.cost : kNaN;
      rs.innovation_std = std::sqrt(nm.cost / static_cast<double>(nm.rows));
      rs.ar.assign(noise_of_[i].a, noise_of_[i].a + noise_of_[i].p);
      if (!converged_[i]) {
        all_converged_ = false;
        e.warnings.push_back({quality_code::kRefineNotConverged, notConverged()});
      }
      WindowEstimate w;
      w.t_start = e.t_start;
      w.t_end = e.t_end;
      w.y_T = x[0];
      w.velocity = x[1];
      w.alpha = kNaN;
      res_->windows.push_back(w);
    }
  }

  // The load law's directed test of curvature in the load (curvatureTest).
  struct Curvature {
    double z = kNaN, spread = kNaN;  // curvature_z, curvature_spread
  };
  // sharedDampingTest's results.
  struct SharedTest {
    double z = kNaN, spread = kNaN;                     // variation_z, variation_spread
    double share = kNaN, t_start = kNaN, t_end = kNaN;  // information_share, its segment
    Curvature curvature;                                // the load law's
  };

  // The shared damping's test of one damping per segment (flag damping_varies), at the refined
  // estimate. Constant model: the score test of one C_i per segment against the shared C,
  //   S = (sum u_i^2 / I_i - (sum u_i)^2 / sum I_i) / sigma^2 ~ chi-square(n - 1)
  // when the damping is the same in every segment (u_i: segment i's score of its own C, I_i its
  // information, both with the segment's locals profiled out, from the prewhitened normal
  // equations at the solution; sigma^2 the pooled innovation variance), into e->variation_z by
  // the Wilson-Hilferty transform; and the spread of the segments' C beyond the noise (a method
  // of moments: the one-step deviations u_i / I_i have the I-weighted variance
  // sigma^2 (S - (n - 1)) / sum I_i beyond the noise), relative to C, into e->variation_spread.
  // Both stay NaN where not judged: other shared unknowns (the STE), fewer than two segments, or
  // a residual RMS below kWhitenessFloor of the DTE's standard deviation.
  // Torque-meter noise adds t_i (constancyTorqueVariance) to u_i's variance sigma^2 I_i; with
  // V_i = sigma^2 I_i + t_i the one-step deviations d_i = u_i / I_i, weighted w_i = I_i^2 / V_i,
  // give S = sum w_i d_i^2 - (sum w_i d_i)^2 / sum w_i ~ chi-square(n - 1) (the same S when every
  // t_i is zero, computed as before then) and the spread sqrt((S - (n - 1)) / sum w_i).
  // Load law (C = theta0 + theta1 T): the score test of the same offsets of C per segment (the
  // theta0 column within the segment) with theta1 kept (the unrestricted model: an own C per
  // segment and the shared slope), at the law's estimate where theta0's and theta1's scores
  // vanish. With the locals profiled out, I_i, J_i, K_i segment i's information of theta0, their
  // cross information and theta1's, the block inverse of that model's information gives
  //   S = (sum u_i^2 / I_i + (sum u_i J_i / I_i)^2 / s) / sigma^2 ~ chi-square(n - 1),
  //   s = sum (K_i - J_i^2 / I_i),
  // s the slope's information within the segments (zero when the torque is constant in each:
  // the slope is then only seen between segments, the second term drops and S ~ chi-square(n - 2)).
  // The spread as above, relative to the law's C at the information-weighted mean torque
  // sum J_i / sum I_i. Without it a damping that is not linear in the load (or changes in time)
  // gave a confidently wrong law (held-out seed 13607: 5.8 standard errors, no warning).
  //
  // Also the largest share one segment has in the information about C (theta0), and its span
  // (share, t_start, t_end; flag information_concentrated, the constant model's): where one
  // segment holds most of it (a start-up transient, a resonance crossing) the shared C is in
  // effect that segment's damping and the test above has little power elsewhere. Measured
  // (held-out --check constant, seeds 15400-15799): all 11 records whose damping varied and whose
  // constant was clean and more than 4 C_std from the time mean (up to 76 C_std, 16 %) had a
  // share of 0.75-0.999.
  //
  // Load law, also a directed test of curvature in the load (curvatureTest). The chi-square
  // spreads its power over n - 1 directions: a damping curved in the load by +-0.2-0.3 % had laws
  // 4-5 SE off with variation_z 2.8-2.95 (hostile review, 2026-11-28).
  SharedTest sharedDampingTest() {
    SharedTest out;
    if (piecewise_ || ns_ != (load_ ? 2 : 1) || !(sigma2_pooled_ > 0.0)) return out;
    double info_max = 0.0;
    size_t i_max = 0;
    std::vector<double> us, is, ts;  // load law: u_i, I_i, t_i (the curvature test)
    double su2 = 0.0, su = 0.0, si = 0.0, raw = 0.0, dev2 = 0.0;
    double sw = 0.0, swd = 0.0, swd2 = 0.0;  // with the torque noise (w_i, w_i d_i, w_i d_i^2)
    double q = 0.0, slope_info = 0.0, sk = 0.0, sj = 0.0;  // load law: sum u J / I, s, sum K, J
    bool torque = false;
    int n = 0;
    for (size_t i = 0; i < nseg_; ++i) {
      if (!active_[i]) continue;
      const Normal& nm = normals_[i];
      const Eigen::VectorXd ncl = nm.N.block(nl_, 0, 1, nl_).transpose();
      const double u = nm.rhs[nl_] - ncl.dot(Nll_inv_[i] * nm.rhs.head(nl_));
      const double info = nm.N(nl_, nl_) - ncl.dot(Nll_inv_[i] * ncl);
      if (!(info > 0.0) || !std::isfinite(u)) return out;
      su2 += u * u / info, su += u, si += info, ++n;
      if (info > info_max) info_max = info, i_max = i;
      if (load_) {
        const Eigen::VectorXd n1l = nm.N.block(nl_ + 1, 0, 1, nl_).transpose();
        const double J = nm.N(nl_, nl_ + 1) - ncl.dot(Nll_inv_[i] * n1l);
        const double K = nm.N(nl_ + 1, nl_ + 1) - n1l.dot(Nll_inv_[i] * n1l);
        q += u * J / info, slope_info += K - J * J / info, sk += K, sj += J;
        us.push_back(u), is.push_back(info), ts.push_back(J / info);
      }
      const double t = constancyTorqueVariance(i, ncl, sigma2_pooled_ * info);
      const double var = sigma2_pooled_ * info + t;
      torque = torque || t > 0.0;
      sw += info * info / var, swd += u * info / var, swd2 += u * u / var;
      raw += nm.raw;
      const Index b = ranges_[i].first, end = ranges_[i].second;
      double mean = 0.0;
      for (Index k = b; k < end; ++k) mean += s_.dte[k];
      mean /= static_cast<double>(std::max<Index>(end - b, 1));
      for (Index k = b; k < end; ++k) dev2 += (s_.dte[k] - mean) * (s_.dte[k] - mean);
    }
    if (n >= 2) {
      out.share = info_max / si;
      out.t_start = res_->segments[i_max].t_start;
      out.t_end = res_->segments[i_max].t_end;
    }
    constexpr double kFloor2 = QualityLimits::kWhitenessFloor * QualityLimits::kWhitenessFloor;
    if (n < 2 || !(raw > kFloor2 * dev2)) return out;
    double df = n - 1.0, S = 0.0, c_ref = sh_[0];
    if (!load_) {
      S = torque ? swd2 - swd * swd / sw : (su2 - su * su / si) / sigma2_pooled_;
    } else {
      constexpr double kSlopeWithin = 1e-9;  // of sum K: the slope not seen within segments
      S = su2 / sigma2_pooled_;
      if (slope_info > kSlopeWithin * sk && std::isfinite(q))
        S += q * q / slope_info / sigma2_pooled_;
      else if (--df < 1.0)
        return out;
      c_ref = sh_[0] + sh_[1] * sj / si;
      if (n >= 3) out.curvature = curvatureTest(us, is, ts, c_ref);
    }
    const double v = 2.0 / (9.0 * df);
    const double c_var = torque ? 1.0 / sw : sigma2_pooled_ / si;  // the weighted mean's
    out.z = (std::cbrt(std::max(S, 0.0) / df) - (1.0 - v)) / std::sqrt(v);
    out.spread = std::sqrt(std::max(S - df, 0.0) * c_var) / std::abs(c_ref);
    return out;
  }

  // sharedDampingTest's curvature test of the load law, from u_i, I_i, t_i per judged segment:
  // the one-step deviations d_i = u_i / I_i against r_i, the residual of t_i^2 (t_i = J_i / I_i)
  // after its weighted fit on [1, t_i], z = sum u_i r_i / (sigma sqrt(sum I_i r_i^2)), N(0, 1)
  // when the damping is linear in the load; and the curvature's departure from the line at its
  // largest, |beta| max |r_i| (beta = sum u_i r_i / sum I_i r_i^2), relative to the law's C.
  Curvature curvatureTest(const std::vector<double>& u, const std::vector<double>& info,
                          const std::vector<double>& t, double c_ref) const {
    const size_t n = u.size();
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0, s4 = 0.0;  // sum I t^k
    for (size_t i = 0; i < n; ++i) {
      const double w = info[i], x = t[i];
      s0 += w, s1 += w * x, s2 += w * x * x, s3 += w * x * x * x, s4 += w * x * x * x * x;
    }
    // t^2 = a + b t by weighted least squares; r = t^2 - a - b t.
    const double det = s0 * s2 - s1 * s1;
    Curvature c;
    if (!(det > 1e-12 * s0 * s2)) return c;  // the segments' torques do not spread
    const double b = (s0 * s3 - s1 * s2) / det, a = (s2 - b * s1) / s0;
    double num = 0.0, den = 0.0, r_max = 0.0;
    for (size_t i = 0; i < n; ++i) {
      const double r = t[i] * t[i] - a - b * t[i];
      num += u[i] * r, den += info[i] * r * r, r_max = std::max(r_max, std::abs(r));
    }
    if (!(den > 1e-12 * (s4 + s0 * a * a))) return c;
    c.z = num / std::sqrt(sigma2_pooled_ * den);
    c.spread = std::abs(num / den) * r_max / std::abs(c_ref);
    return c;
  }

  // The variance the torque-meter noise adds to segment i's profiled score of C in the constant
  // model, u_i = a' Jw' e with a = [-N_ll^-1 N_lc; 1] (ncl = N_lc): a' Q_i a with Q_i the
  // right-hand side's covariance where torqueNoiseExact kept it, else torqueProjectedVariance of
  // the direction Jw a (`base`: the score's variance without it). Zero without a known level, and
  // for the load law, whose standard errors leave the torque noise out (torqueNoise).
  double constancyTorqueVariance(size_t i, const Eigen::VectorXd& ncl, double base) {
    if (load_ || torque_sigma_.empty() || !(torque_sigma_[i] > 0.0)) return 0.0;
    Eigen::VectorXd a(nl_ + 1);
    a.head(nl_) = -(Nll_inv_[i] * ncl);
    a[nl_] = 1.0;
    if (i < tgram_.size() && tgram_[i].rows() == a.size()) return a.dot(tgram_[i] * a);
    return torqueProjectedVariance(i, whitenedSensitivities(i) * a, base);
  }

  // The shared estimates: constant C, the load law, the STE; the run's convergence warning.
  void fillShared() {
    const Eigen::MatrixXd& Ainv = Ainv_of_[problems_[0][0]];
    const Eigen::MatrixXd& tcov = tcov_ss_[problems_[0][0]];  // torque noise (zero: none)
    if (res_->constant && !piecewise_ && !load_) {
      fillC(&*res_->constant, sh_[0], sigma2_pooled_ * Ainv(0, 0) + tcov(0, 0));
      const SharedTest st = sharedDampingTest();
      SegmentEstimate& e = *res_->constant;
      e.variation_z = st.z, e.variation_spread = st.spread;
      e.information_share = st.share, e.information_t_start = st.t_start;
      e.information_t_end = st.t_end;
      if (!all_converged_)
        res_->constant->warnings.push_back({quality_code::kRefineNotConverged, notConverged()});
    }
    if (res_->load_law && load_) {
      res_->load_law->c0 = me_ * sh_[0];
      res_->load_law->c1 = me_ * sh_[1];
      res_->load_law->c0_std = me_ * std::sqrt(std::max(sigma2_pooled_ * Ainv(0, 0), 0.0));
      res_->load_law->c1_std = me_ * std::sqrt(std::max(sigma2_pooled_ * Ainv(1, 1), 0.0));
      // (The information share is the constant model's flag only: for the law it added nothing.)
      const SharedTest st = sharedDampingTest();
      LoadLawEstimate& l = *res_->load_law;
      l.variation_z = st.z, l.variation_spread = st.spread;
      l.curvature_z = st.curvature.z, l.curvature_spread = st.curvature.spread;
    }
    if (ste_ != nullptr) {
      ste_->theta.resize(nste_);
      ste_->theta_std.resize(nste_);
      for (int k = 0; k < nste_; ++k) {
        const int a = ste_shared_ + k;
        ste_->theta[k] = sh_[a];
        ste_->theta_std[k] = std::sqrt(std::max(sigma2_pooled_ * Ainv(a, a) + tcov(a, a), 0.0));
      }
    }
    if (!all_converged_)
      res_->warnings.push_back({quality_code::kRefineNotConverged, notConverged()});
  }

  const SignalView& s_;
  const std::vector<std::pair<Index, Index>>& ranges_;
  const IdentificationOptions& o_;
  IdentificationResult* res_;
  SteRefinement* ste_;
  const double me_;
  const bool grey_, load_, piecewise_, shape_;
  const int nb_;
  const size_t nseg_;
  const ForwardModel fm_;
  const SegmentSimulator sim_;
  const int substeps_;
  // The reference path (tests): generic RK4, torque noise by impulses.
  const bool reference_;
  std::vector<Role> local_roles_, shared_roles_;
  int basis_first_ = 0, ste_shared_ = 0, nste_ = 0, nl_ = 0, ns_ = 0, m_ = 0;
  std::vector<char> active_, converged_;
  Locals loc_;
  Eigen::VectorXd sh_;
  std::vector<Normal> normals_;
  std::vector<Set> problems_;
  std::vector<NoiseModel> noise_of_;
  int iterations_ = 0;
  std::vector<Eigen::MatrixXd> Nll_inv_, Ainv_of_;
  std::vector<Eigen::MatrixXd> cov_ll_, cov_ss_;  // positiveVariances: locals, shared (no torque)
  double sigma2_pooled_ = 0.0;
  bool all_converged_ = true;
  // Per-segment scratch of solveStep and gaussNewton (sized once).
  mutable std::vector<Eigen::MatrixXd> nll_inv_scratch_;
  Locals dl_scratch_, x1_scratch_;
  Eigen::MatrixXd curvature_;  // gaussNewton: the secant estimate S of one segment
  size_t curvature_of_ = static_cast<size_t>(-1);  // the segment it belongs to
  Eigen::VectorXd curvature_d_;                    // N's diagonal root at its last update
  bool curvature_ar_ = false;                      // estimated under an AR noise model
  std::vector<Normal> n1_scratch_;
  mutable std::vector<SegmentTable> tables_;  // tableOf's cache
  mutable RowBuffer fused_rrev_;              // evaluateFused's scratch
  mutable KeptRows kept_[2];                  // gaussNewton: accepted, trial
  std::vector<KeptRows> final_rows_;          // keepFinalRows: at the solution, by segment
  size_t kept_samples_ = 0;                   // samples held in final_rows_ so far
  mutable SegmentTable scratch_;
  mutable size_t cached_ = 0;
  // Torque noise (torqueNoise): per-segment level and added covariances, and the draws' model
  // (the record with the torque channel replaced by one draw of noise).
  std::vector<double> torque_sigma_, torque_sd_;
  std::vector<Eigen::MatrixXd> tcov_ll_, tcov_ss_;
  // Per segment, the covariance of the right-hand side's torque-noise part (torqueNoiseExact).
  std::vector<Eigen::MatrixXd> tgram_;
  std::vector<double> noise_torque_;
  // Each segment's torque glitches (loadSteps): (sample, size).
  std::vector<std::vector<std::pair<Index, double>>> glitches_;
  std::vector<double> quantum_;  // each segment's torque quantum (loadSteps; 0: none)
  SignalView noise_view_;
  std::unique_ptr<ForwardModel> noise_fm_;
  std::unique_ptr<SegmentSimulator> noise_sim_;
  std::vector<Normal> draw_normals_;
  // torqueResponseGram's scratch.
  std::vector<double> adj_u_, adj_m_;
  Eigen::MatrixXd adj_M_;
  SegmentTable adj_tab_;
  std::vector<SegmentSimulator::StateMap> adj_maps_;
};

}  // namespace

gear_sim::Status refineOutputError(const SignalView& s,
                                   const std::vector<std::pair<Index, Index>>& ranges,
                                   const GearConstants& gear, const IdentificationOptions& o,
                                   IdentificationResult* res, bool reference_integration,
                                   SteRefinement* ste) {
  if (o.formulation != Formulation::Known && o.formulation != Formulation::Greybox) return {};
  if (ranges.size() != res->segments.size()) {
    return gear_sim::Status::internal("refinement: segment ranges do not match the result");
  }
  const bool shape = o.formulation == Formulation::Greybox &&
                     o.stiffness_shape.kind != StiffnessShape::Kind::Square;
  if (shape && s.mesh_phase == nullptr) {
    return gear_sim::Status::invalidInput("refinement: the stiffness shape " +
                                              toString(o.stiffness_shape) +
                                              " needs the mesh_phase channel",
                                          "mesh_phase");
  }
  if (ste != nullptr) {
    if (shape || o.model == DampingModel::LoadLaw || s.mesh_phase == nullptr) {
      return gear_sim::Status::invalidArgument(
          "refinement: the STE needs the mesh_phase channel, the square stiffness and "
          "piecewise or constant damping");
    }
    if (ste->basis.size() > SteRefinement::kMaxTerms ||
        static_cast<int>(ste->theta.size()) != ste->basis.size()) {
      return gear_sim::Status::invalidArgument("refinement: at most " +
                                               std::to_string(SteRefinement::kMaxTerms) +
                                               " STE coefficients, with start values");
    }
  }
  Refinement r(s, ranges, gear, o, res, reference_integration, ste);
  return r.run();
}

// ----------------------------------------------------------------------------------------------
// Modeled response

void fitMetrics(const Eigen::VectorXd& y, const Eigen::VectorXd& yh, double* nrmse, double* fit) {
  // Over the samples where both series are finite (a NaN sample of the record must not turn
  // the whole record's fit into NaN); NaN when there are none or y is constant there.
  // Every sum keeps its sample order (the values are bit for bit those of the plain loops);
  // when both series are finite (the usual case, checked with vector instructions) the loops
  // have no per-sample test, else a skipped sample adds +0.0, which leaves a sum as it was
  // (none of them is ever -0.0). The squared errors are summed in the first pass.
  const double* a = y.data();
  const double* b = yh.data();
  const Eigen::Index m = y.size();
  double n = 0.0, sum = 0.0, num = 0.0, den = 0.0;
  if (y.allFinite() && yh.allFinite()) {
    for (Eigen::Index i = 0; i < m; ++i) {
      const double e = a[i] - b[i];
      sum += a[i];
      num += e * e;
    }
    n = static_cast<double>(m);  // exact: the count of a vector's elements is below 2^53
    const double mean = n > 0.0 ? sum / n : 0.0;
    for (Eigen::Index i = 0; i < m; ++i) den += (a[i] - mean) * (a[i] - mean);
  } else {
    for (Eigen::Index i = 0; i < m; ++i) {
      const bool ok = std::isfinite(a[i]) && std::isfinite(b[i]);
      const double e = a[i] - b[i];
      sum += ok ? a[i] : 0.0;
      n += ok ? 1.0 : 0.0;
      num += ok ? e * e : 0.0;
    }
    const double mean = n > 0.0 ? sum / n : 0.0;
    for (Eigen::Index i = 0; i < m; ++i) {
      const bool ok = std::isfinite(a[i]) && std::isfinite(b[i]);
      den += ok ? (a[i] - mean) * (a[i] - mean) : 0.0;
    }
  }
  *nrmse = den > 0.0 ? std::sqrt(num / den) : kNaN;
  *fit = 100.0 * (1.0 - *nrmse);
}

namespace {

// The segments of `r` for the re-simulation: a non-identifiable segment takes the previous
// identifiable one's values (else the next one's), keeping its own times. False when none is
// identifiable.
bool segmentsWithFallbacks(const IdentificationResult& r, std::vector<SegmentEstimate>* out) {
  std::vector<SegmentEstimate>& seg = *out;
  seg = r.segments;
  int last = -1;
  for (size_t i = 0; i < seg.size(); ++i) {
    if (seg[i].identifiable) {
      last = static_cast<int>(i);
    } else if (last >= 0) {
      const double t0 = seg[i].t_start, t1 = seg[i].t_end;
      seg[i] = seg[last];
      seg[i].t_start = t0, seg[i].t_end = t1;
    }
  }
  if (last < 0) return false;
  for (int i = static_cast<int>(seg.size()) - 1, next = -1; i >= 0; --i) {
    if (r.segments[i].identifiable)
      next = i;
    else if (next >= 0 && !std::isfinite(seg[i].C)) {
      const double t0 = seg[i].t_start, t1 = seg[i].t_end;
      seg[i] = seg[next];
      seg[i].t_start = t0, seg[i].t_end = t1;
    }
  }
  return true;
}

// The re-simulation's breakpoints over samples [begin, end): the breaks of the stiffness/mesh-
// state channel (switches, jumps, kinks), the table nodes of a greybox table shape (kinks) and
// the segment boundaries; sorted.
std::vector<double> responseBreakpoints(const SignalView& s, const ForwardModel& fm, bool shape,
                                        const IdentificationResult& r,
                                        const std::vector<SegmentEstimate>& seg, Index begin,
                                        Index end) {
  std::vector<double> bps;
  for (const QuadratureBreak& b : fm.breaks()) {
    if (b.j >= begin && b.j + 1 < end && b.th < 1.0) bps.push_back(s.time(b.j) + b.th * s.dt);
  }
  if (shape && r.stiffness_shape.kind == StiffnessShape::Kind::Table) {
    const double nodes = r.stiffness_shape.n;
    for (Index j = begin; j + 1 < end; ++j) {
      const double pa = s.mesh_phase[j], pb = s.mesh_phase[j + 1];
      if (!(pb > pa)) continue;
      const double x = ((std::floor(pa * nodes) + 1.0) / nodes - pa) / (pb - pa);
      if (x > 0.0 && x < 1.0) bps.push_back(s.time(j) + x * s.dt);
    }
  }
  for (const auto& e : seg) bps.push_back(e.t_start);
  std::sort(bps.begin(), bps.end());
  return bps;
}

// C(t), K(t), F(t) of the modeled response from the identified segments and the forward model:
// the generic driver's look-up by time (generic) and the affine fast path's by interval and
// stage (stage, intervals in ascending order).
// What both stage providers of the modeled response read: the record, the segments, their
// sample ranges, the forward model and which segments hold their stiffness, with cursors over
// the segments and the breaks for intervals visited in ascending order.
struct StageCursor {
  StageCursor(const SignalView& sig, const std::vector<SegmentEstimate>& segs,
              const ForwardModel::Ranges& rng, const ForwardModel& model)
      : s(sig), seg(segs), ranges(rng), fm(model) {
    held.resize(seg.size());
    for (size_t i = 0; i < seg.size(); ++i) held[i] = !fm.smoothStiffness(ranges[i].first);
  }

  // Moves the cursors to interval j; returns the local coordinate of j's break (1: none).
  double advance(Index j) {
    const std::vector<QuadratureBreak>& brk = fm.breaks();
    while (si + 1 < seg.size() && ranges[si + 1].first <= j) ++si;
    while (bi < brk.size() && brk[bi].j < j) ++bi;
    return bi < brk.size() && brk[bi].j == j ? brk[bi].th : 1.0;
  }

  const SignalView& s;
  const std::vector<SegmentEstimate>& seg;
  const ForwardModel::Ranges& ranges;
  const ForwardModel& fm;
  std::vector<char> held;
  size_t si = 0, bi = 0;
};

class ResponseCoefficients {
 public:
  ResponseCoefficients(const SignalView& s, const GearConstants& gear,
                       const IdentificationResult& r, const std::vector<SegmentEstimate>& seg,
                       const ForwardModel::Ranges& ranges, const ForwardModel& fm, int substeps,
                       Index begin)
      : cur_(s, seg, ranges, fm),
        gear_(gear),
        r_(r),
        me_(gear.equivalent_mass),
        inv_me_(1.0 / me_),
        load_(r.model == DampingModel::LoadLaw && r.load_law && r.load_law->identifiable),
        th0_(load_ ? r.load_law->c0 / me_ : 0.0),
        th1_(load_ ? r.load_law->c1 / me_ : 0.0),
        shape_(r.formulation == Formulation::Greybox &&
               r.stiffness_shape.kind != StiffnessShape::Kind::Square && s.mesh_phase != nullptr),
        begin_(begin),
        u_first_mid_(0.5 / substeps) {
    u_stage_.resize(static_cast<size_t>(2 * substeps + 1));
    for (int k = 0; k < 2 * substeps; ++k) u_stage_[static_cast<size_t>(k)] = k * (0.5 / substeps);
    u_stage_.back() = 1.0;
  }

  bool shape() const { return shape_; }

  // The generic driver's look-up: K(t), F(t) of the piece holding t_ref.
  gear_sim::SdofCoefficients generic(double t, double t_ref) const {
    const double uref = (t_ref - cur_.s.t0) / cur_.s.dt;
    const Index j = std::clamp<Index>(static_cast<Index>(std::floor(uref)), 0, cur_.s.n - 2);
    const double u = std::clamp((t - cur_.s.t0) / cur_.s.dt - static_cast<double>(j), 0.0, 1.0);
    const bool right = uref - static_cast<double>(j) >= cur_.fm.heldSplit(j);
    return at(j, u, right, segmentAt(t_ref));
  }

  // The fast path's look-up of an interval without a breakpoint inside, at the exact stage
  // coordinates u = k / (2 substeps) (the midpoint and the ends take the precomputed stencils):
  // cursors over the segments and the breaks instead of a search per look-up.
  gear_sim::SdofCoefficients stage(Index i, int k) {
    const Index j = begin_ + i;
    const double split = cur_.advance(j);
    return at(j, u_stage_[static_cast<size_t>(k)], u_first_mid_ >= split, cur_.si);
  }

 private:
  size_t segmentAt(double t) const {
    size_t lo = 0, hi = cur_.seg.size();
    while (hi - lo > 1) {
      const size_t mid = (lo + hi) / 2;
      if (cur_.seg[mid].t_start <= t)
        lo = mid;
      else
        hi = mid;
    }
    return lo;
  }

  // Coefficients at local coordinate u of interval j, segment `si`, before (right = false) or
  // after the interval's break.
  gear_sim::SdofCoefficients at(Index j, double u, bool right, size_t si) const {
    const SegmentEstimate& e = cur_.seg[si];
    const Index lo = cur_.ranges[si].first, hi = cur_.ranges[si].second;
    const double T1 = cur_.fm.torque(j, u, lo, hi);
    gear_sim::SdofCoefficients c;
    c.C = load_ ? th0_ + th1_ * T1 : e.C;
    c.F = gear_.force_factor * T1;
    switch (r_.formulation) {
      case Formulation::Known:
        // A held channel's value directly (knownStiffness's first case, without its search of
        // the segment's smoothness per look-up).
        c.K = cur_.held[si]
                  ? (right && j + 1 < cur_.s.n ? cur_.s.stiffness[j + 1] : cur_.s.stiffness[j]) *
                        inv_me_
                  : cur_.fm.knownStiffness(j, u, right, lo, hi);
        break;
      case Formulation::Greybox:
        if (shape_ && !e.stiffness_curve.empty()) {
          const double phase = cur_.fm.cubic(cur_.s.mesh_phase, j, u, lo, hi);
          c.K = shapeStiffness(r_.stiffness_shape, e.stiffness_curve, phase) / me_;
        } else {
          c.K = (e.k_min + (e.k_max - e.k_min) * cur_.fm.meshState(j, right)) / me_;
        }
        break;
      case Formulation::Paper:
      case Formulation::Legacy:
        c.K = e.k_min / me_;
        c.F = std::isfinite(e.forcing) ? e.forcing : 0.0;
        break;
    }
    return c;
  }

  StageCursor cur_;
  const GearConstants& gear_;
  const IdentificationResult& r_;
  const double me_, inv_me_;
  const bool load_;
  const double th0_, th1_;
  const bool shape_;
  const Index begin_;
  const double u_first_mid_;
  std::vector<double> u_stage_;
};

// The modeled response's stage look-ups in the common case, without ResponseCoefficients'
// generality: the known formulation with the stiffness held in the segment, one RK4 step per
// sample, no load law. It computes what ResponseCoefficients::stage computes there, with the same
// operations (so the same values): C = the segment's C, K = the held sample (that of j+1 when
// the interval's break lies at or before its midpoint), F = force_factor T1 with T1 the sample
// values at the ends and the forward model's cubic at the midpoint.
class HeldKnownStages {
 public:
  HeldKnownStages(const SignalView& s, const GearConstants& gear, const IdentificationResult& r,
                  const std::vector<SegmentEstimate>& seg, const ForwardModel::Ranges& ranges,
                  const ForwardModel& fm, int substeps, Index begin)
      : cur_(s, seg, ranges, fm),
        force_factor_(gear.force_factor),
        inv_me_(1.0 / gear.equivalent_mass),
        begin_(begin),
        on_(substeps == 1 && r.formulation == Formulation::Known && s.stiffness != nullptr &&
            !(r.model == DampingModel::LoadLaw && r.load_law && r.load_law->identifiable)) {}

  // Stages 0, 1, 2 of interval i into c/k/f[0], [stride], [2 stride]; false (nothing written)
  // outside the common case.
  bool fill(Index i, double* c, double* k, double* f, size_t stride) {
    double C, K;
    if (!held(i, &C, &K, f, f + stride, f + 2 * stride)) return false;
    c[0] = c[stride] = c[2 * stride] = C;
    k[0] = k[stride] = k[2 * stride] = K;
    return true;
  }

  // The same for one interval as scalars: its damping C and stiffness K (the same at the three
  // stages) and the forcing at the start, midpoint and end; false outside the common case.
  bool held(Index i, double* C, double* K, double* f0, double* fm, double* f1) {
    if (!on_) return false;
    const Index j = begin_ + i;
    const double split = cur_.advance(j);
    if (!cur_.held[cur_.si]) return false;
    const bool right = 0.5 >= split;
    const Index lo = cur_.ranges[cur_.si].first, hi = cur_.ranges[cur_.si].second;
    *K = (right && j + 1 < cur_.s.n ? cur_.s.stiffness[j + 1] : cur_.s.stiffness[j]) * inv_me_;
    const double* T = cur_.s.torque;
    const double t0 = T == nullptr ? 0.0 : T[j];
    const double tm = T == nullptr ? 0.0 : cur_.fm.torque(j, 0.5, lo, hi);
    const double t1 =
        T == nullptr ? 0.0 : (j + 1 < cur_.s.n ? T[j + 1] : cur_.fm.torque(j, 1.0, lo, hi));
    *C = cur_.seg[cur_.si].C;
    *f0 = force_factor_ * t0;
    *fm = force_factor_ * tm;
    *f1 = force_factor_ * t1;
    return true;
  }

  // Whether the common case applies to the record (a segment may still not hold its stiffness).
  bool on() const { return on_; }

  // After held(i) returned true: the end E of the intervals i' in (i, E) that held() would treat
  // plainly (the same segment, no break, the interior midpoint rule, samples j' - 1 .. j' + 2 in
  // the segment and the record, a torque channel), for which Plain below gives what held() gives.
  Index plainEnd(Index i) const {
    const Index j = begin_ + i;
    const std::vector<QuadratureBreak>& brk = cur_.fm.breaks();
    const Index lo = cur_.ranges[cur_.si].first, hi = cur_.ranges[cur_.si].second;
    if (cur_.s.torque == nullptr || j < lo) return i + 1;
    Index end = std::min(hi - 2, cur_.s.n - 1);  // j' + 2 < hi, j' + 1 < n
    if (cur_.si + 1 < cur_.seg.size()) end = std::min(end, cur_.ranges[cur_.si + 1].first);
    size_t b = cur_.bi;
    while (b < brk.size() && brk[b].j <= j) ++b;
    if (b < brk.size()) end = std::min(end, static_cast<Index>(brk[b].j));
    return std::max(i + 1, end - begin_);
  }

  // What held() computes for a plain interval, from the arrays directly.
  struct Plain {
    const double *k, *T;
    double inv_me, force_factor;
    Index begin;
    CubicIntervalRule::Weights w;  // the interior rule's midpoint weights (offset -1)
  };
  Plain plain() const {
    return {cur_.s.stiffness, cur_.s.torque, inv_me_,
            force_factor_,    begin_,        cur_.fm.interiorMidpointWeights()};
  }

 private:
  StageCursor cur_;
  const double force_factor_, inv_me_;
  const Index begin_;
  const bool on_;
};

// Whether two doubles are the same bits (the affine map's cache key compares bits, as memcmp).
inline bool sameBits(double a, double b) {
  std::uint64_t x, y;
  std::memcpy(&x, &a, 8);
  std::memcpy(&y, &b, 8);
  return x == y;
}

// The forcing part (g1, g2) of the steps of plain intervals i = 0 .. len - 1 (record samples
// j0 + i; HeldKnownStages::Plain), the scaled damping and stiffness stages b, c, k1, km held over
// them: per step what heldResponse's scalar loop computed (held()'s values, rk4AffineForcing), the
// same operations in the same order per lane. The steps are independent, so the loop vectorises;
// GEAR_AVX2_CLONES is AVX2 without FMA (nothing contracted), so every clone gives the same bits.
GEAR_AVX2_CLONES
void plainForcing(const HeldKnownStages::Plain& p, double inv_h, double h2, double b, double c,
                  double k1, double km, Index j0, Index len, double* __restrict g1,
                  double* __restrict g2) {
  const double* __restrict T = p.T;
  const double w0 = p.w[0], w1 = p.w[1], w2 = p.w[2], w3 = p.w[3], ff = p.force_factor;
  for (Index i = 0; i < len; ++i) {
    const Index j = j0 + i;
    const double tm = w0 * T[j - 1] + w1 * T[j] + w2 * T[j + 1] + w3 * T[j + 2];
    gear_sim::AffineStep a;
    gear_sim::rk4AffineForcing(inv_h, b, c, k1, km, h2 * (ff * T[j]), h2 * (ff * tm),
                               h2 * (ff * T[j + 1]), &a);
    g1[i] = a.g1;
    g2[i] = a.g2;
  }
}

// The number of leading k[0 .. len) whose product with inv_me has the bits of K (sameBits), four
// at a time (vectorised; AVX2 clone: the same products).
GEAR_AVX2_CLONES
Index sameProducts(const double* k, Index len, double inv_me, double K) {
  typedef std::int64_t L4 __attribute__((vector_size(32)));
  std::int64_t kbits;
  std::memcpy(&kbits, &K, 8);
  Index i = 0;
  for (; i + 4 <= len; i += 4) {
    V4d v;
    std::memcpy(&v, k + i, sizeof(V4d));
    v *= inv_me;
    L4 bits;
    std::memcpy(&bits, &v, sizeof(L4));
    const L4 same = bits == kbits;
    if (!(same[0] & same[1] & same[2] & same[3])) break;
  }
  while (i < len && sameBits(k[i] * inv_me, K)) ++i;
  return i;
}

// The first interval m in [m0, limit) (limit if none) that has a breakpoint strictly inside, as
// heldResponse's split(m) finds it, from `scan` (at or before the first breakpoint after the
// start of interval m0; a copy is moved). With B the first breakpoint after the start t0 + m dt,
// split(m') for m' >= m is B < t0 + (m' + 1) dt until the start reaches B, and that end is
// monotone in m': the first m' where it exceeds B is found from an estimate and checked with
// the same expressions. Where a start equals B exactly, the search goes on from there past B.
template <class It>
Index firstSplit(It scan, It bp_end, double t0, double dt, Index m0, Index limit) {
  for (Index m = m0; m < limit;) {
    const double ta = t0 + m * dt;
    while (scan != bp_end && *scan <= ta) ++scan;
    if (scan == bp_end) return limit;
    const double B = *scan;
    auto past = [&](Index q) { return t0 + (q + 1) * dt > B; };  // interval q ends after B
    double x = (B - t0) / dt - 1.0;
    if (!(x >= static_cast<double>(m))) x = static_cast<double>(m);
    if (!(x <= static_cast<double>(limit))) x = static_cast<double>(limit);
    Index q = static_cast<Index>(x);
    while (q > m && past(q - 1)) --q;
    while (q < limit && !past(q)) ++q;
    if (q >= limit) return limit;
    if (t0 + q * dt < B) return q;  // B lies inside interval q
    m = q;                          // interval q starts at B
  }
  return limit;
}

// gear_sim::integrateSdofAffineBlocks for one RK4 step per sample (substeps 1) with the
// common case's stages taken per interval as scalars (HeldKnownStages::held; the other
// intervals from `stages`, split ones by advanceSdof with `coeffs`): the same steps, stages and
// operations in the same order, so the same values, in one loop without stage arrays. The
// homogeneous part of the step's map is recomputed only when its scaled damping or stiffness
// stages change (bit for bit), i.e. at stiffness switches and segment boundaries.
template <class CoeffFn, class StagesFn>
gear_sim::Status heldResponse(const CoeffFn& coeffs, HeldKnownStages& held, const StagesFn& stages,
                              std::vector<double> breakpoints, double t0, double dt,
                              Index n_samples, gear_sim::SdofState initial, double* y_out) {
  if (gear_sim::Status e = gear_sim::checkSdofArguments(dt, n_samples, initial, 1); !e.ok())
    return e;
  std::sort(breakpoints.begin(), breakpoints.end());
  const auto bp_end = breakpoints.cend();
  auto bp = breakpoints.cbegin();    // the stepping cursor (advanceSdof's)
  auto scan = breakpoints.cbegin();  // first breakpoint > the interval's start
  const double h = dt / 1, inv_h = 1.0 / h, h2 = h * h;
  std::array<double, 6> key{};  // the scaled stages (a, b, c, k0, km, k1) of `hom`
  gear_sim::AffineStep hom;
  bool have = false;
  const char no_split = 0;
  constexpr Index kPlainRun = 256;
  double g1[kPlainRun], g2[kPlainRun];  // the forcing parts of a run of plain intervals
  gear_sim::SdofState s = initial;
  y_out[0] = s.y;
  // Whether interval n has a breakpoint strictly inside (the scan cursor moved to it).
  auto split = [&](Index n) {
    const double ta = t0 + n * dt, tb = t0 + (n + 1) * dt;
    while (scan != bp_end && *scan <= ta) ++scan;
    return scan != bp_end && *scan < tb;
  };
  for (Index n = 0; n + 1 < n_samples;) {
    if (split(n)) {
      s = gear_sim::advanceSdof(coeffs, s, t0 + n * dt, t0 + (n + 1) * dt, 1, bp, bp_end,
                                gear_sim::Integrator::Rk4);
      y_out[++n] = s.y;
      continue;
    }
    double c[3], k[3], f[3];
    const bool fast = held.held(n, &c[0], &k[0], &f[0], &f[1], &f[2]);
    if (fast) {
      c[1] = c[2] = c[0];
      k[1] = k[2] = k[0];
    } else {
      stages(n, n + 1, &no_split, c, k, f, size_t{1});
    }
    const std::array<double, 6> now{h * c[0], h * c[1], h * c[2], h2 * k[0], h2 * k[1], h2 * k[2]};
    if (!have || std::memcmp(now.data(), key.data(), sizeof(now)) != 0) {
      gear_sim::rk4AffineHomogeneous(h, inv_h, now[0], now[1], now[2], now[3], now[4], now[5],
                                     &hom);
      key = now;
      have = true;
    }
    gear_sim::AffineStep a = hom;
    gear_sim::rk4AffineForcing(inv_h, now[1], now[2], now[5], now[4], h2 * f[0], h2 * f[1],
                               h2 * f[2], &a);
    s = {a.m11 * s.y + a.m12 * s.v + a.g1, a.m21 * s.y + a.m22 * s.v + a.g2};
    y_out[++n] = s.y;
    if (!fast) continue;
    // The plain intervals that follow (HeldKnownStages::plainEnd) with the same stiffness, bit
    // for bit (so the same damping, stiffness and homogeneous part): held()'s values read from
    // the arrays, the stages' scaled damping and stiffness loop constants (plainForcing; its
    // terms made of them alone are hoisted by the compiler: the same operations, the same
    // values).
    const Index end = std::min(n_samples - 1, held.plainEnd(n - 1));
    const HeldKnownStages::Plain p = held.plain();
    const double K = k[0];
    const gear_sim::AffineStep m = hom;
    for (Index len = kPlainRun; len == kPlainRun;) {
      // The next run of such intervals (at most kPlainRun): up to the first that split() or the
      // stiffness stops (the cursor left where it is: split() moves it on when asked), their
      // forcing parts first, then the serial recursion.
      const Index most = std::min(kPlainRun, end - n);
      if (most <= 0) break;
      const Index stop = firstSplit(scan, bp_end, t0, dt, n, n + most);
      len = sameProducts(p.k + p.begin + n, stop - n, p.inv_me, K);
      plainForcing(p, inv_h, h2, now[1], now[2], now[5], now[4], p.begin + n, len, g1, g2);
      for (Index i = 0; i < len; ++i) {
        s = {m.m11 * s.y + m.m12 * s.v + g1[i], m.m21 * s.y + m.m22 * s.v + g2[i]};
        y_out[++n] = s.y;
      }
    }
  }
  return {};
}

}  // namespace

namespace {

// The identified state at sample `at` (the start of segment `seg`): the window estimate that
// starts there; else, with `at_rest`, the observed DTE at rest (an identifiable first segment
// without a window estimate), else NaN (no state to start from).
gear_sim::SdofState segmentState(const SignalView& s, const IdentificationResult& r,
                                 const SegmentEstimate& seg, Index at, bool at_rest) {
  for (const WindowEstimate& w : r.windows) {
    if (std::abs(w.t_start - seg.t_start) <= 0.5 * s.dt && std::isfinite(w.y_T)) {
      return {w.y_T, std::isfinite(w.velocity) ? w.velocity : 0.0};
    }
  }
  return at_rest ? gear_sim::SdofState{s.dte[at], 0.0} : gear_sim::SdofState{kNaN, kNaN};
}

// The first of y[0, n) that is not finite or exceeds the plausible |DTE| (a re-simulation that
// diverges passes through huge finite values first); n when there is none. Blocks of 64 counted
// branch-free (vectorised; AVX2 clone), then one by one in the block that fails.
GEAR_AVX2_CLONES
Index firstImplausible(const double* y, Index n) {
  constexpr double kMaxAbs = gear_sim::kPlausibleRanges[0].high;  // |dte| [m]
  Index i = 0;
  for (; i + 64 <= n; i += 64) {
    long good = 0;
    for (int j = 0; j < 64; ++j) good += std::abs(y[i + j]) <= kMaxAbs;
    if (good != 64) break;
  }
  while (i < n && std::abs(y[i]) <= kMaxAbs) ++i;
  return i;
}

// Eq. (4) re-simulated over samples [begin, end) through the segments `seg` (the first starting
// at `begin`) from `init`, into y_out[0, end - begin).
gear_sim::Status simulateSegments(const SignalView& s, const GearConstants& gear,
                                  const IdentificationResult& r,
                                  const std::vector<SegmentEstimate>& seg, Index begin, Index end,
                                  gear_sim::SdofState init, double* y_out) {
  // Each segment's samples [lo, hi): the interpolation stencils stay inside it, as in the
  // integral method and the refinement.
  auto sampleOf = [&](double t) {
    return std::clamp<Index>(static_cast<Index>(std::llround((t - s.t0) / s.dt)), 0, s.n);
  };
  ForwardModel::Ranges ranges;
  for (const auto& e : seg) {
    ranges.emplace_back(sampleOf(e.t_start), std::max(sampleOf(e.t_end), sampleOf(e.t_start)));
  }
  const ForwardModel fm(s, gear, r.formulation, ranges);
  const int substeps = substepsFor(r.omega0, s.dt);
  ResponseCoefficients rc(s, gear, r, seg, ranges, fm, substeps, begin);
  const std::vector<double> bps = responseBreakpoints(s, fm, rc.shape(), r, seg, begin, end);
  auto coeffs = [&rc](double t, double t_ref) { return rc.generic(t, t_ref); };
  HeldKnownStages held(s, gear, r, seg, ranges, fm, substeps, begin);
  auto stages = [&](Index n0, Index n1, const char* split, double* c, double* k, double* f,
                    size_t stride) {
    for (Index i = n0; i < n1; ++i) {
      const size_t q = static_cast<size_t>(i - n0);
      if (split[q] || held.fill(i, c + q, k + q, f + q, stride)) continue;
      for (int u = 0; u <= 2 * substeps; ++u) {
        const gear_sim::SdofCoefficients v = rc.stage(i, u);
        const size_t at = static_cast<size_t>(u) * stride + q;
        c[at] = v.C;
        k[at] = v.K;
        f[at] = v.F;
      }
    }
  };
  const Index n = end - begin;
  if (const gear_sim::Status e =
          held.on() ? heldResponse(coeffs, held, stages, bps, s.time(begin), s.dt, n, init, y_out)
                    : gear_sim::integrateSdofAffineBlocks(coeffs, stages, bps, s.time(begin), s.dt,
                                                          n, init, gear_sim::Integrator::Rk4,
                                                          substeps, y_out, nullptr);
      !e.ok())
    return e.withContext("modeled response");
  return {};
}

}  // namespace

gear_sim::Status modeledResponse(const SignalView& s, const GearConstants& gear,
                                 const IdentificationResult& r, ModeledResponse* out,
                                 bool fit_metrics) {
  if (r.segments.empty()) {
    return gear_sim::Status::notIdentifiable("modeled response: no segments");
  }
  std::vector<SegmentEstimate> seg;
  if (!segmentsWithFallbacks(r, &seg)) {
    return gear_sim::Status::notIdentifiable("modeled response: no identifiable segment");
  }
  const Index begin = static_cast<Index>(std::llround((seg.front().t_start - s.t0) / s.dt));
  const Index end =
      std::min<Index>(s.n, static_cast<Index>(std::llround((seg.back().t_end - s.t0) / s.dt)));
  if (begin < 0 || end - begin < 2) {
    return gear_sim::Status::notIdentifiable(
        "modeled response: the segments do not lie in the record");
  }
  const Index n = end - begin;
  out->begin = begin;
  out->observed = Eigen::Map<const Eigen::VectorXd>(s.dte + begin, n);
  out->modeled.resize(n);
  out->unmodeled = 0;
  // One simulation through every segment from the first one's identified state, as before
  // restarts existed. Where it turns non-finite or implausible (a NaN or absurd input sample, a
  // diverging estimate) the samples from there to the next segment with an identified state are
  // left NaN and the simulation starts again there, so one bad sample costs its segment's tail,
  // not the rest of the record. After the first such failure each part runs at most through the
  // next segment that could fail again (non-finite driving input, a damping that is not positive
  // or beyond RK4's stability, a greybox stiffness that is not positive), so restarts cost no
  // more than simulating the record twice.
  const auto startOf = [&](size_t k) {
    return k < seg.size()
               ? std::clamp<Index>(static_cast<Index>(std::llround((seg[k].t_start - s.t0) / s.dt)),
                                   begin, end)
               : end;
  };
  std::vector<char> risky;  // per segment, filled at the first failure
  const auto markRisky = [&] {
    risky.assign(seg.size(), 0);
    const double* driving[] = {s.stiffness, s.torque, s.mesh_state, s.mesh_phase};
    for (size_t k = 0; k < seg.size(); ++k) {
      const SegmentEstimate& e = seg[k];
      bool bad = !(e.C > 0.0) || !(e.C * s.dt < 2.5) ||
                 (r.formulation == Formulation::Greybox && !(e.k_min > 0.0));
      for (const double* x : driving)
        if (x != nullptr && !bad)
          bad = !Eigen::Map<const Eigen::VectorXd>(x + startOf(k), startOf(k + 1) - startOf(k))
                     .allFinite();
      risky[k] = bad ? 1 : 0;
    }
  };
  double* y = out->modeled.data();
  for (size_t first = 0; first < seg.size();) {
    const Index from = startOf(first);
    const gear_sim::SdofState init =
        segmentState(s, r, seg[first], from, first == 0 && r.segments[0].identifiable);
    if (!std::isfinite(init.y) || !std::isfinite(init.v)) {  // no state: try the next segment
      const Index next_start = startOf(first + 1);
      std::fill(y + (from - begin), y + (next_start - begin), kNaN);
      out->unmodeled += next_start - from;
      ++first;
      continue;
    }
    size_t stop = seg.size();  // the part: segments [first, stop)
    if (!risky.empty()) {
      stop = first;
      while (stop < seg.size() && !risky[stop]) ++stop;
      stop = std::min(stop + 1, seg.size());
    }
    const Index to = startOf(stop);
    if (to - from == 1) {
      y[from - begin] = init.y;
    } else if (to > from) {
      std::vector<SegmentEstimate> part;  // (copied only when the part is not every segment)
      if (first > 0 || stop < seg.size())
        part.assign(seg.begin() + static_cast<std::ptrdiff_t>(first),
                    seg.begin() + static_cast<std::ptrdiff_t>(stop));
      if (const gear_sim::Status e = simulateSegments(s, gear, r, part.empty() ? seg : part, from,
                                                      to, init, y + (from - begin));
          !e.ok())
        return e;
    }
    const Index bad = from + firstImplausible(y + (from - begin), to - from);
    if (bad == to) {
      first = stop;
      continue;
    }
    if (risky.empty()) markRisky();
    // Start again at the first later segment that starts at or after the bad sample.
    size_t next = first + 1;
    while (next < stop && startOf(next) < bad) ++next;
    std::fill(y + (bad - begin), y + (startOf(next) - begin), kNaN);
    out->unmodeled += startOf(next) - bad;
    first = next;
  }
  if (out->unmodeled >= n) {
    return gear_sim::Status::notIdentifiable(
        "modeled response: the re-simulation diverged (non-finite values)");
  }
  out->nrmse = out->fit_percent = kNaN;
  if (fit_metrics) fitMetrics(out->observed, out->modeled, &out->nrmse, &out->fit_percent);
  return {};
}

}  // namespace gear_damping_id
