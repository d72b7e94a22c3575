#include "gear_damping_id/output_error.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "gear_damping_id/quality_flags.hpp"
#include "gear_sim/sdof_integrator.hpp"

namespace gear_damping_id {

namespace {

using Index = Eigen::Index;

// Roles of the unknowns of one segment's output-error problem.
enum class Role { Y0, V0, Theta0, Theta1, K0, DK };

constexpr int kMaxParams = 7;              // y0, v0, theta0, theta1, K0, dK (+ spare)
constexpr int kMaxState = 2 + 2 * kMaxParams;

// Held values of a piecewise-constant channel on interval j: left value on [0, th), right value
// on [th, 1] (local coordinate). th = 1 when the value does not change.
struct Held {
  double left, right, th;
};

// Everything needed to integrate eq. (4) and its sensitivities over one damping segment.
class SegmentSimulator {
 public:
  SegmentSimulator(const SignalView& s, const GearConstants& g, Formulation f)
      : s_(s), g_(g), f_(f) {}

  // Split fraction of interval j for a channel whose held value changes (see IntegralMethod).
  double split(Index j, bool rising) const {
    if (s_.mesh_phase == nullptr || j + 1 >= s_.n) return 1.0;
    const double ua = s_.mesh_phase[j], ub = s_.mesh_phase[j + 1];
    if (!(ub > ua)) return 1.0;
    const double off = rising ? 0.0 : g_.contact_ratio - 1.0;
    const double tol = 1e-9 * std::max(1.0, std::abs(ua));
    const double c = std::ceil(ua - off - tol) + off;
    if (c > ub + (ub - ua)) return 1.0;
    return std::clamp((c - ua) / (ub - ua), 0.0, 1.0);
  }

  Held held(const double* ch, Index j) const {
    const double a = ch[j];
    const double b = j + 1 < s_.n ? ch[j + 1] : a;
    if (a == b) return {a, a, 1.0};
    return {a, b, split(j, b > a)};
  }

  // Torque at local coordinate u of interval j (cubic through the neighbouring samples).
  double torqueAt(Index j, double u) const {
    if (s_.torque == nullptr) return 0.0;
    if (u == 0.0) return s_.torque[j];
    if (u == 1.0 && j + 1 < s_.n) return s_.torque[j + 1];
    const CubicIntervalRule& r = rules_.forInterval(j, 0, s_.n);
    const auto w = r.value(u);
    const Index b = j + r.offset();
    return w[0] * s_.torque[b] + w[1] * s_.torque[b + 1] + w[2] * s_.torque[b + 2] +
           w[3] * s_.torque[b + 3];
  }

  // Parameters of one segment: roles and values.
  struct Params {
    int m = 0;
    Role role[kMaxParams];
    double theta0 = 0, theta1 = 0, K0 = 0, dK = 0, y0 = 0, v0 = 0;
  };

  // Integrates over samples [b, e) from (p.y0, p.v0). Calls visit(n, z) for each sample with the
  // state z = (y, v, z_1, z_1', ..., z_m, z_m').
  template <class Visit>
  void run(Index b, Index e, const Params& p, int substeps, Visit&& visit) const {
    const int D = 2 + 2 * p.m;
    double z[kMaxState] = {0};
    z[0] = p.y0, z[1] = p.v0;
    for (int k = 0; k < p.m; ++k) {
      if (p.role[k] == Role::Y0) z[2 + 2 * k] = 1.0;
      if (p.role[k] == Role::V0) z[3 + 2 * k] = 1.0;
    }
    visit(b, z);
    const double h = s_.dt;
    const bool grey = f_ == Formulation::Greybox;
    for (Index j = b; j + 1 < e; ++j) {
      // Stiffness pieces on this interval.
      double Kl, Kr, sl = 0, sr = 0, th;
      if (grey) {
        const Held hs = held(s_.mesh_state, j);
        sl = hs.left, sr = hs.right, th = hs.th;
        Kl = p.K0 + p.dK * sl, Kr = p.K0 + p.dK * sr;
      } else {
        const Held hk = held(s_.stiffness, j);
        Kl = hk.left / g_.equivalent_mass, Kr = hk.right / g_.equivalent_mass, th = hk.th;
        if (!g_.piecewise_constant_stiffness) th = 1.0;  // smooth: handled by interpolation
      }
      const double parts[2][2] = {{0.0, th}, {th, 1.0}};
      for (int piece = 0; piece < 2; ++piece) {
        const double u0 = parts[piece][0], u1 = parts[piece][1];
        if (!(u1 > u0)) continue;
        const double K = piece == 0 ? Kl : Kr, sv = piece == 0 ? sl : sr;
        const double du = (u1 - u0) / substeps;
        for (int q = 0; q < substeps; ++q) {
          const double ua = u0 + q * du, ub = ua + du, um = 0.5 * (ua + ub);
          step(z, D, p, K, sv, h * du, j, ua, um, ub);
        }
      }
      visit(j + 1, z);
    }
  }

 private:
  // One RK4 step of length hs over local coordinates ua -> ub (midpoint um) of interval j, with
  // K (and mesh state sv) constant on it.
  void step(double* z, int D, const Params& p, double K, double sv, double hs, Index j, double ua,
            double um, double ub) const {
    double k1[kMaxState], k2[kMaxState], k3[kMaxState], k4[kMaxState], tmp[kMaxState];
    const double Ta = torqueAt(j, ua), Tm = torqueAt(j, um), Tb = torqueAt(j, ub);
    deriv(z, D, p, K, sv, Ta, k1);
    for (int i = 0; i < D; ++i) tmp[i] = z[i] + 0.5 * hs * k1[i];
    deriv(tmp, D, p, K, sv, Tm, k2);
    for (int i = 0; i < D; ++i) tmp[i] = z[i] + 0.5 * hs * k2[i];
    deriv(tmp, D, p, K, sv, Tm, k3);
    for (int i = 0; i < D; ++i) tmp[i] = z[i] + hs * k3[i];
    deriv(tmp, D, p, K, sv, Tb, k4);
    for (int i = 0; i < D; ++i) z[i] += hs / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
  }

  void deriv(const double* z, int D, const Params& p, double K, double sv, double T1,
             double* dz) const {
    const double C = p.theta0 + p.theta1 * T1;
    const double F = g_.force_factor * T1;
    const double y = z[0], v = z[1];
    dz[0] = v;
    dz[1] = F - C * v - K * y;
    for (int k = 0, i = 2; i < D; ++k, i += 2) {
      double forcing = 0.0;
      switch (p.role[k]) {
        case Role::Theta0: forcing = -v; break;
        case Role::Theta1: forcing = -T1 * v; break;
        case Role::K0: forcing = -y; break;
        case Role::DK: forcing = -sv * y; break;
        default: break;
      }
      dz[i] = z[i + 1];
      dz[i + 1] = forcing - C * z[i + 1] - K * z[i];
    }
  }

  const SignalView& s_;
  const GearConstants& g_;
  Formulation f_;
  CubicRules rules_;
};

// Substeps per sample so that omega * h_step <= 0.1 (RK4 error well below the bars).
int substepsFor(double omega, double dt) {
  return std::max(1, static_cast<int>(std::ceil(omega * dt / 0.1)));
}

}  // namespace

bool wantsRefinement(const IdentificationOptions& o, const IdentificationResult& r) {
  if (o.formulation != Formulation::Known && o.formulation != Formulation::Greybox) return false;
  if (o.refine == IdentificationOptions::Refine::Never) return false;
  if (o.refine == IdentificationOptions::Refine::Always) return true;
  std::vector<double> rel;
  for (const auto& s : r.segments) {
    if (s.identifiable && std::isfinite(s.C_std) && s.C != 0.0) {
      rel.push_back(std::abs(s.C_std / s.C));
    }
  }
  if (r.constant && r.constant->identifiable && r.constant->C != 0.0) {
    rel.push_back(std::abs(r.constant->C_std / r.constant->C));
  }
  if (rel.empty()) return false;
  std::nth_element(rel.begin(), rel.begin() + rel.size() / 2, rel.end());
  return rel[rel.size() / 2] > o.refine_threshold;
}

bool refineOutputError(const SignalView& s, const std::vector<std::pair<Index, Index>>& ranges,
                       const GearConstants& gear, const IdentificationOptions& o,
                       IdentificationResult* res, std::string* error) {
  if (o.formulation != Formulation::Known && o.formulation != Formulation::Greybox) return true;
  if (ranges.size() != res->segments.size()) {
    *error = "refinement: segment ranges do not match the result";
    return false;
  }
  const double me = gear.equivalent_mass;
  const bool grey = o.formulation == Formulation::Greybox;
  const bool load = o.model == DampingModel::LoadLaw;
  const bool piecewise = o.model == DampingModel::Piecewise;
  const SegmentSimulator sim(s, gear, o.formulation);
  const int substeps = substepsFor(res->omega0, s.dt);

  // Unknowns: per segment locals [y0, v0, (theta0 if piecewise), (K0, dK if greybox)];
  // shared [theta0 (constant, load_law), theta1 (load_law)].
  std::vector<Role> local_roles = {Role::Y0, Role::V0};
  if (piecewise) local_roles.push_back(Role::Theta0);
  if (grey) local_roles.push_back(Role::K0), local_roles.push_back(Role::DK);
  std::vector<Role> shared_roles;
  if (!piecewise) shared_roles.push_back(Role::Theta0);
  if (load) shared_roles.push_back(Role::Theta1);
  const int nl = static_cast<int>(local_roles.size()), ns = static_cast<int>(shared_roles.size());
  const int m = nl + ns;

  const size_t nseg = ranges.size();
  std::vector<char> active(nseg, 0);
  std::vector<Eigen::VectorXd> loc(nseg, Eigen::VectorXd::Zero(nl));
  Eigen::VectorXd sh = Eigen::VectorXd::Zero(ns);
  // Start values from the integral method.
  if (!piecewise) {
    if (load && res->load_law && res->load_law->identifiable) {
      sh[0] = res->load_law->c0 / me;
      sh[1] = res->load_law->c1 / me;
    } else if (!load && res->constant && res->constant->identifiable) {
      sh[0] = res->constant->C;
    } else {
      *error = "refinement: no identifiable shared estimate to start from";
      return false;
    }
  }
  for (size_t i = 0; i < nseg; ++i) {
    const SegmentEstimate& e = res->segments[i];
    if (!e.identifiable) continue;
    active[i] = 1;
    Eigen::VectorXd& x = loc[i];
    // Initial state: the integral method's first window of the segment.
    x[0] = s.dte[ranges[i].first];
    for (const WindowEstimate& w : res->windows) {
      if (std::abs(w.t_start - e.t_start) <= 0.5 * s.dt) {
        x[0] = w.y_T, x[1] = w.velocity;
        break;
      }
    }
    int k = 2;
    if (piecewise) x[k++] = e.C;
    if (grey) {
      x[k++] = e.k_min / me;
      x[k++] = (e.k_max - e.k_min) / me;
    }
  }

  auto makeParams = [&](size_t i, const Eigen::VectorXd& x, const Eigen::VectorXd& g) {
    SegmentSimulator::Params p;
    p.m = m;
    for (int k = 0; k < nl; ++k) p.role[k] = local_roles[k];
    for (int k = 0; k < ns; ++k) p.role[nl + k] = shared_roles[k];
    auto set = [&](Role r, double v) {
      switch (r) {
        case Role::Y0: p.y0 = v; break;
        case Role::V0: p.v0 = v; break;
        case Role::Theta0: p.theta0 = v; break;
        case Role::Theta1: p.theta1 = v; break;
        case Role::K0: p.K0 = v; break;
        case Role::DK: p.dK = v; break;
      }
    };
    for (int k = 0; k < nl; ++k) set(local_roles[k], x[k]);
    for (int k = 0; k < ns; ++k) set(shared_roles[k], g[k]);
    (void)i;
    return p;
  };

  // Normal equations of one segment at (x, g): N = J^T J (m x m), rhs = J^T r, cost = r^T r.
  struct Normal {
    Eigen::MatrixXd N;
    Eigen::VectorXd rhs;
    double cost = 0;
    bool finite = true;
  };
  auto evaluate = [&](size_t i, const Eigen::VectorXd& x, const Eigen::VectorXd& g,
                      bool jacobian) {
    Normal out;
    out.N = Eigen::MatrixXd::Zero(m, m);
    out.rhs = Eigen::VectorXd::Zero(m);
    SegmentSimulator::Params p = makeParams(i, x, g);
    if (!jacobian) p.m = 0;
    double Nacc[kMaxParams][kMaxParams] = {{0}};
    double racc[kMaxParams] = {0};
    double cost = 0.0;
    const int mm = p.m;
    sim.run(ranges[i].first, ranges[i].second, p, substeps, [&](Index n, const double* z) {
      const double r = s.dte[n] - z[0];
      cost += r * r;
      for (int a = 0; a < mm; ++a) {
        const double ja = z[2 + 2 * a];
        racc[a] += ja * r;
        for (int b = 0; b <= a; ++b) Nacc[a][b] += ja * z[2 + 2 * b];
      }
    });
    for (int a = 0; a < mm; ++a) {
      out.rhs[a] = racc[a];
      for (int b = 0; b <= a; ++b) out.N(a, b) = out.N(b, a) = Nacc[a][b];
    }
    out.cost = cost;
    out.finite = std::isfinite(cost);
    return out;
  };

  // Gauss-Newton with step halving. Locals are eliminated per segment (Schur complement).
  auto solveStep = [&](const std::vector<Normal>& normals, std::vector<Eigen::VectorXd>* dl,
                       Eigen::VectorXd* dg, Eigen::MatrixXd* shared_inv,
                       std::vector<Eigen::MatrixXd>* local_inv) {
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(ns, ns);
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(ns);
    std::vector<Eigen::MatrixXd> Nll_inv(nseg);
    for (size_t i = 0; i < nseg; ++i) {
      if (!active[i]) continue;
      const Normal& nm = normals[i];
      Nll_inv[i] = nm.N.topLeftCorner(nl, nl).ldlt().solve(Eigen::MatrixXd::Identity(nl, nl));
      const Eigen::MatrixXd Nsl = nm.N.block(nl, 0, ns, nl);
      A += nm.N.bottomRightCorner(ns, ns) - Nsl * Nll_inv[i] * Nsl.transpose();
      rhs += nm.rhs.tail(ns) - Nsl * (Nll_inv[i] * nm.rhs.head(nl));
    }
    Eigen::MatrixXd Ainv = Eigen::MatrixXd::Zero(ns, ns);
    if (ns > 0) Ainv = A.ldlt().solve(Eigen::MatrixXd::Identity(ns, ns));
    *dg = Ainv * rhs;
    for (size_t i = 0; i < nseg; ++i) {
      if (!active[i]) continue;
      const Normal& nm = normals[i];
      (*dl)[i] = Nll_inv[i] * (nm.rhs.head(nl) - nm.N.block(0, nl, nl, ns) * *dg);
    }
    if (shared_inv) *shared_inv = Ainv;
    if (local_inv) *local_inv = Nll_inv;
  };

  std::vector<Normal> normals(nseg);
  double cost = 0.0;
  for (size_t i = 0; i < nseg; ++i) {
    if (!active[i]) continue;
    normals[i] = evaluate(i, loc[i], sh, true);
    cost += normals[i].cost;
  }
  if (!std::isfinite(cost)) {
    *error = "refinement: the model response is not finite at the integral-method estimate";
    return false;
  }
  int it = 0;
  bool converged = false;
  for (; it < o.max_iterations && !converged; ++it) {
    std::vector<Eigen::VectorXd> dl(nseg, Eigen::VectorXd::Zero(nl));
    Eigen::VectorXd dg;
    solveStep(normals, &dl, &dg, nullptr, nullptr);
    double step = 1.0;
    bool accepted = false;
    for (int halving = 0; halving < 30 && !accepted; ++halving, step *= 0.5) {
      std::vector<Eigen::VectorXd> x1(nseg);
      const Eigen::VectorXd g1 = sh + step * dg;
      std::vector<Normal> n1(nseg);
      double c1 = 0.0;
      for (size_t i = 0; i < nseg; ++i) {
        if (!active[i]) continue;
        x1[i] = loc[i] + step * dl[i];
        n1[i] = evaluate(i, x1[i], g1, true);
        c1 += n1[i].cost;
      }
      if (std::isfinite(c1) && c1 <= cost * (1.0 + 1e-12)) {
        accepted = true;
        // Converged when the damping unknowns moved by less than 1e-10 relative.
        double rel = 0.0;
        for (int k = 0; k < ns; ++k) {
          rel = std::max(rel, std::abs(step * dg[k]) / std::max(std::abs(g1[k]), 1e-300));
        }
        for (size_t i = 0; i < nseg; ++i) {
          if (!active[i]) continue;
          for (int k = 2; k < nl; ++k) {
            rel = std::max(rel,
                           std::abs(step * dl[i][k]) / std::max(std::abs(x1[i][k]), 1e-300));
          }
        }
        converged = rel < 1e-10 || c1 >= cost * (1.0 - 1e-14);
        for (size_t i = 0; i < nseg; ++i) {
          if (active[i]) loc[i] = x1[i];
        }
        sh = g1;
        normals = std::move(n1);
        cost = c1;
      }
    }
    if (!accepted) {
      converged = true;  // no descent left: at the minimum to rounding
    }
  }

  // Covariances at the solution.
  std::vector<Eigen::VectorXd> dl(nseg, Eigen::VectorXd::Zero(nl));
  Eigen::VectorXd dg;
  Eigen::MatrixXd Ainv;
  std::vector<Eigen::MatrixXd> Nll_inv;
  solveStep(normals, &dl, &dg, &Ainv, &Nll_inv);
  long n_total = 0;
  int n_active = 0;
  for (size_t i = 0; i < nseg; ++i) {
    if (active[i]) n_total += ranges[i].second - ranges[i].first, ++n_active;
  }
  const long dof_total = n_total - static_cast<long>(n_active) * nl - ns;
  if (dof_total < 1) {
    *error = "refinement: too few samples for the unknowns";
    return false;
  }
  const double sigma2_pooled = cost / static_cast<double>(dof_total);
  res->noise_std = std::sqrt(sigma2_pooled);
  res->estimator = "output_error";
  res->iterations = it;

  const double omega0 = res->omega0;
  auto fillC = [&](SegmentEstimate* e, double C, double var) {
    e->C = C;
    e->C_std = std::sqrt(std::max(var, 0.0));
    e->c = C * me;
    e->xi = C / (2.0 * omega0);
    e->refined = true;
  };
  res->windows.clear();
  double k_int = 0.0, dur = 0.0;
  for (size_t i = 0; i < nseg; ++i) {
    if (!active[i]) continue;
    SegmentEstimate& e = res->segments[i];
    const Eigen::VectorXd& x = loc[i];
    const long ni = ranges[i].second - ranges[i].first;
    const double sigma2 = piecewise ? normals[i].cost / static_cast<double>(ni - nl) : sigma2_pooled;
    // Full covariance of this segment's unknowns [locals, shared].
    const Eigen::MatrixXd Nsl = normals[i].N.block(nl, 0, ns, nl);
    const Eigen::MatrixXd B = Nll_inv[i] * Nsl.transpose();
    const Eigen::MatrixXd cov_ll = sigma2 * (Nll_inv[i] + B * Ainv * B.transpose());
    const Eigen::MatrixXd cov_ls = -sigma2 * B * Ainv;
    const Eigen::MatrixXd cov_ss = sigma2 * Ainv;
    int k = 2;
    if (piecewise) {
      fillC(&e, x[k], cov_ll(k, k));
      ++k;
    } else if (load) {
      const double T = e.mean_torque;
      fillC(&e, sh[0] + sh[1] * T, cov_ss(0, 0) + T * T * cov_ss(1, 1) + 2 * T * cov_ss(0, 1));
    } else {
      fillC(&e, sh[0], cov_ss(0, 0));
    }
    (void)cov_ls;
    if (grey) {
      const int a = k, b = k + 1;
      e.k_min = me * x[a];
      e.k_max = me * (x[a] + x[b]);
      e.k_min_std = me * std::sqrt(std::max(cov_ll(a, a), 0.0));
      e.k_max_std = me * std::sqrt(std::max(cov_ll(a, a) + cov_ll(b, b) + 2 * cov_ll(a, b), 0.0));
    }
    WindowEstimate w;
    w.t_start = e.t_start;
    w.t_end = e.t_end;
    w.y_T = x[0];
    w.velocity = x[1];
    w.alpha = kNaN;
    res->windows.push_back(w);
    (void)k_int, (void)dur;
  }
  if (res->constant && !piecewise && !load) {
    fillC(&*res->constant, sh[0], sigma2_pooled * Ainv(0, 0));
  }
  if (res->load_law && load) {
    res->load_law->c0 = me * sh[0];
    res->load_law->c1 = me * sh[1];
    res->load_law->c0_std = me * std::sqrt(std::max(sigma2_pooled * Ainv(0, 0), 0.0));
    res->load_law->c1_std = me * std::sqrt(std::max(sigma2_pooled * Ainv(1, 1), 0.0));
  }
  if (!converged) {
    res->warnings.push_back({quality_code::kRefineNotConverged,
                             "output-error refinement stopped after " + std::to_string(it) +
                                 " iterations without converging to 1e-10"});
  }
  return true;
}

// ----------------------------------------------------------------------------------------------
// Modeled response

void fitMetrics(const Eigen::VectorXd& y, const Eigen::VectorXd& yh, double* nrmse, double* fit) {
  // Over the samples where both series are finite (a NaN sample of the record must not turn
  // the whole record's fit into NaN); NaN when there are none or y is constant there.
  double n = 0.0, sum = 0.0;
  for (Eigen::Index i = 0; i < y.size(); ++i)
    if (std::isfinite(y[i]) && std::isfinite(yh[i])) sum += y[i], n += 1.0;
  const double mean = n > 0.0 ? sum / n : 0.0;
  double den = 0.0, num = 0.0;
  for (Eigen::Index i = 0; i < y.size(); ++i) {
    if (!std::isfinite(y[i]) || !std::isfinite(yh[i])) continue;
    den += (y[i] - mean) * (y[i] - mean);
    num += (y[i] - yh[i]) * (y[i] - yh[i]);
  }
  *nrmse = den > 0.0 ? std::sqrt(num / den) : kNaN;
  *fit = 100.0 * (1.0 - *nrmse);
}

bool modeledResponse(const SignalView& s, const GearConstants& gear, const IdentificationResult& r,
                     ModeledResponse* out, std::string* error) {
  if (r.segments.empty()) {
    *error = "modeled response: no segments";
    return false;
  }
  const double me = gear.equivalent_mass;
  // Segment lookup with a fallback for non-identifiable segments (the previous identifiable
  // one's values, else the next one's).
  std::vector<SegmentEstimate> seg = r.segments;
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
  if (last < 0) {
    *error = "modeled response: no identifiable segment";
    return false;
  }
  for (int i = static_cast<int>(seg.size()) - 1, next = -1; i >= 0; --i) {
    if (r.segments[i].identifiable) next = i;
    else if (next >= 0 && !std::isfinite(seg[i].C)) {
      const double t0 = seg[i].t_start, t1 = seg[i].t_end;
      seg[i] = seg[next];
      seg[i].t_start = t0, seg[i].t_end = t1;
    }
  }
  const Index begin = static_cast<Index>(std::llround((seg.front().t_start - s.t0) / s.dt));
  const Index end = std::min<Index>(
      s.n, static_cast<Index>(std::llround((seg.back().t_end - s.t0) / s.dt)));
  if (begin < 0 || end - begin < 2) {
    *error = "modeled response: the segments do not lie in the record";
    return false;
  }
  // Initial state: the first window/segment estimate at the first sample.
  gear_sim::SdofState init{s.dte[begin], 0.0};
  for (const WindowEstimate& w : r.windows) {
    if (std::abs(w.t_start - seg.front().t_start) <= 0.5 * s.dt && std::isfinite(w.y_T)) {
      init = {w.y_T, std::isfinite(w.velocity) ? w.velocity : 0.0};
      break;
    }
  }
  const bool load = r.model == DampingModel::LoadLaw && r.load_law && r.load_law->identifiable;
  const double th0 = load ? r.load_law->c0 / me : 0.0, th1 = load ? r.load_law->c1 / me : 0.0;
  const Formulation f = r.formulation;
  const SegmentSimulator sim(s, gear, f);
  CubicRules rules;
  // Breakpoints: switch instants of the stiffness/mesh-state channel, and segment boundaries.
  std::vector<double> bps;
  const double* ch = f == Formulation::Known     ? s.stiffness
                     : f == Formulation::Greybox ? s.mesh_state
                                                 : nullptr;
  if (ch != nullptr) {
    for (Index j = begin; j + 1 < end; ++j) {
      if (ch[j] != ch[j + 1]) bps.push_back(s.time(j) + sim.held(ch, j).th * s.dt);
    }
  }
  for (const auto& e : seg) bps.push_back(e.t_start);
  auto segmentAt = [&](double t) -> const SegmentEstimate& {
    size_t lo = 0, hi = seg.size();
    while (hi - lo > 1) {
      const size_t mid = (lo + hi) / 2;
      if (seg[mid].t_start <= t) lo = mid;
      else hi = mid;
    }
    return seg[lo];
  };
  auto coeffs = [&](double t, double t_ref) {
    double u = (t - s.t0) / s.dt;
    const double uref = (t_ref - s.t0) / s.dt;
    Index j = std::clamp<Index>(static_cast<Index>(std::floor(uref)), 0, s.n - 2);
    u -= static_cast<double>(j);
    const double T1 = s.torque ? sim.torqueAt(j, std::clamp(u, 0.0, 1.0)) : 0.0;
    const SegmentEstimate& e = segmentAt(t_ref);
    gear_sim::SdofCoefficients c;
    c.C = load ? th0 + th1 * T1 : e.C;
    const double uref_local = uref - static_cast<double>(j);
    switch (f) {
      case Formulation::Known: {
        const Held hk = sim.held(s.stiffness, j);
        c.K = (uref_local < hk.th ? hk.left : hk.right) / me;
        c.F = gear.force_factor * T1;
        break;
      }
      case Formulation::Greybox: {
        const Held hs = sim.held(s.mesh_state, j);
        const double sv = uref_local < hs.th ? hs.left : hs.right;
        c.K = (e.k_min + (e.k_max - e.k_min) * sv) / me;
        c.F = gear.force_factor * T1;
        break;
      }
      case Formulation::Paper:
      case Formulation::Legacy:
        c.K = e.k_min / me;
        c.F = std::isfinite(e.forcing) ? e.forcing : 0.0;
        break;
    }
    return c;
  };
  const Index n = end - begin;
  out->begin = begin;
  out->observed = Eigen::Map<const Eigen::VectorXd>(s.dte + begin, n);
  out->modeled.resize(n);
  const int substeps = substepsFor(r.omega0, s.dt);
  const std::string e =
      gear_sim::integrateSdof(coeffs, bps, s.time(begin), s.dt, n, init, gear_sim::Integrator::RK4,
                              substeps, out->modeled.data(), nullptr);
  if (!e.empty()) {
    *error = "modeled response: " + e;
    return false;
  }
  if (!out->modeled.allFinite()) {
    *error = "modeled response: the re-simulation diverged (non-finite values)";
    return false;
  }
  fitMetrics(out->observed, out->modeled, &out->nrmse, &out->fit_percent);
  return true;
}

}  // namespace gear_damping_id
