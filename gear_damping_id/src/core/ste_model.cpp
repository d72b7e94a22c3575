// Joint damping + STE identification (ste_model.hpp, docs/ste.md).
#include "gear_damping_id/ste_model.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "gear_damping_id/output_error.hpp"
#include "gear_damping_id/quadrature.hpp"
#include "gear_damping_id/quality_flags.hpp"

namespace gear_damping_id {

gear_sim::SteBasis SteModelOptions::basis() const {
  gear_sim::SteBasis b;
  b.mesh_orders = mesh_orders;
  b.pinion_orders = pinion_orders;
  b.gear_orders = gear_orders;
  b.z1 = std::max(1, pinion_teeth);
  b.z2 = std::max(1, gear_teeth);
  b.with_offset = offset;
  return b;
}

gear_sim::OptionStatus SteModelOptions::check() const {
  auto bad = [](const char* field, const auto& value, const std::string& rule) {
    return gear_sim::violated("SteModelOptions", field, value, rule);
  };
  if (mesh_orders < 0 || mesh_orders > 32)
    return bad("mesh_orders", mesh_orders, "must be in [0, 32]");
  if (pinion_orders < 0 || pinion_orders > 32)
    return bad("pinion_orders", pinion_orders, "must be in [0, 32]");
  if (gear_orders < 0 || gear_orders > 32)
    return bad("gear_orders", gear_orders, "must be in [0, 32]");
  if (!active())
    return bad("offset", offset,
               "the STE model needs a term (give mesh:H, shaft:S or keep the offset)");
  if ((pinion_orders > 0 || gear_orders > 0) && (pinion_teeth < 1 || gear_teeth < 1))
    return bad(pinion_teeth < 1 ? "pinion_teeth" : "gear_teeth",
               pinion_teeth < 1 ? pinion_teeth : gear_teeth,
               "shaft-order STE terms need the tooth counts Z1, Z2 (from --params)");
  if (max_iterations < 1) return bad("max_iterations", max_iterations, "must be >= 1");
  return {};
}

bool parseSteSpec(const std::string& spec, SteModelOptions* out, std::string* error) {
  SteModelOptions o = *out;
  o.mesh_orders = o.pinion_orders = o.gear_orders = 0;
  o.offset = true;
  std::stringstream ss(spec);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty() || item == "none" || item == "offset") continue;
    if (item == "nooffset") {
      o.offset = false;
      continue;
    }
    const size_t colon = item.find(':');
    const std::string key = item.substr(0, colon);
    int v = -1;
    if (colon != std::string::npos) {
      try {
        size_t used = 0;
        v = std::stoi(item.substr(colon + 1), &used);
        if (used != item.size() - colon - 1) v = -1;
      } catch (...) {
        v = -1;
      }
    }
    if (v < 0 || v > 32 || (key != "mesh" && key != "shaft" && key != "pinion" && key != "gear")) {
      if (error)
        *error =
            "--ste: '" + item +
            "' is not one of mesh:H, shaft:S, pinion:S, gear:S (0..32), offset, nooffset, none";
      return false;
    }
    if (key == "mesh") o.mesh_orders = v;
    if (key == "shaft" || key == "pinion") o.pinion_orders = v;
    if (key == "shaft" || key == "gear") o.gear_orders = v;
  }
  *out = o;
  return true;
}

namespace {

double dot4(const CubicIntervalRule::Weights& w, const double* g) {
  return w[0] * g[0] + w[1] * g[1] + w[2] * g[2] + w[3] * g[3];
}

// Fraction in (0, 1] of interval [u0, u1] (mesh phases) at which the square-wave stiffness
// switches: rising = into double contact (integer phase), else to single contact (n + eps - 1).
double switchFraction(double u0, double u1, double eps, bool rising) {
  if (!(u1 > u0)) return 1.0;
  const double off = rising ? 0.0 : eps - 1.0;
  double c = std::floor(u0 - off) + 1.0 + off;
  if (c - 1.0 >= u0) c -= 1.0;  // u0 - off exactly integer after rounding
  const double th = (c - u0) / (u1 - u0);
  if (th >= 0.0 && th <= 1.0) return th;
  return th > 1.0 && th <= 1.0 + 1e-6 ? 1.0 : -1.0;  // -1: not in this interval
}

// Cumulative single (P) and double (Q) integrals from sample w0 over samples w0..w1-1 of g * W.
// W == null: weight 1. held: W piecewise constant (value of sample j from the switch instant
// theta[j] of interval j on, W[j] before it); else W is smooth and the product is interpolated.
void cumulate(const double* g, const double* W, bool held, const double* theta, Eigen::Index w0,
              Eigen::Index w1, Eigen::Index n, double h, const CubicRules& rules, double* P,
              double* Q, double* scratch) {
  P[0] = Q[0] = 0.0;
  double G = 0.0, Qv = 0.0;
  for (Eigen::Index j = w0; j + 1 < w1; ++j) {
    const CubicIntervalRule& r = rules.forInterval(j, 0, n);
    const Eigen::Index s0 = j + r.offset();
    double area, mom;
    if (W == nullptr) {
      area = dot4(r.area(), g + s0);
      mom = dot4(r.moment(), g + s0);
    } else if (!held) {
      for (int k = 0; k < 4; ++k) scratch[k] = W[s0 + k] * g[s0 + k];
      area = dot4(r.area(), scratch);
      mom = dot4(r.moment(), scratch);
    } else {
      const double th = theta[j];
      if (th >= 1.0 || W[j + 1] == W[j]) {
        area = W[j] * dot4(r.area(), g + s0);
        mom = W[j] * dot4(r.moment(), g + s0);
      } else {
        area = W[j] * dot4(r.area(0.0, th), g + s0) + W[j + 1] * dot4(r.area(th, 1.0), g + s0);
        mom = W[j] * dot4(r.moment(0.0, th), g + s0) + W[j + 1] * dot4(r.moment(th, 1.0), g + s0);
      }
    }
    Qv += h * G + h * h * mom;
    G += h * area;
    P[j + 1 - w0] = G;
    Q[j + 1 - w0] = Qv;
  }
}

// Multipliers a of the bilinear terms a * (Y_a - sum_j theta_j B_aj).
struct Multiplier {
  bool coupled;  // has B_aj columns
};

// The terms of ste->theta, ste->theta_std (offset, then cos/sin pairs).
void fillTerms(const gear_sim::SteBasis& basis, SteResult* ste) {
  ste->terms.clear();
  for (int j = 0; j < basis.size(); ++j) {
    std::string kind;
    int order;
    bool sine;
    basis.describe(j, &kind, &order, &sine);
    if (!sine) {
      SteTerm t;
      t.kind = kind;
      t.order = order;
      t.cos = ste->theta[j];
      t.cos_std = ste->theta_std[j];
      if (kind == "offset") {
        t.sin = 0.0;
        t.sin_std = 0.0;
      }
      ste->terms.push_back(t);
    } else {
      ste->terms.back().sin = ste->theta[j];
      ste->terms.back().sin_std = ste->theta_std[j];
    }
  }
}

// The output-error refinement of a separable joint result (as the segment driver refines the
// plain identification): the noise-robust estimator of C and the STE, and its standard errors.
// Segments the integral fit finds below the noise are refined too: the output error's standard
// error is several times smaller (16-bit encoders, docs/rig.md: all 300 segments significant
// after the refinement, 142 of them below the noise by the integral fit alone). Only a segment
// whose integral C is not positive (no stable start for the forward model) keeps the integral
// fit's flags. Every flag is applied again after the refinement.
void refineWithSte(const SignalView& view,
                   const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges,
                   const GearConstants& gear, const IdentificationOptions& options,
                   const gear_sim::SteBasis& basis, bool relative, IdentificationResult* res,
                   SteResult* st) {
  IdentificationResult flagged = *res;
  applyQualityFlags(options, &flagged);
  if (!st->separable || !wantsRefinement(options, flagged)) {
    *res = std::move(flagged);
    return;
  }
  for (size_t i = 0; i < res->segments.size(); ++i)
    if (!(res->segments[i].C > 0.0)) res->segments[i] = flagged.segments[i];
  SteRefinement sr;
  sr.basis = basis;
  sr.relative = relative;
  sr.theta = st->theta;
  IdentificationResult refined = *res;
  std::string why;
  if (refineOutputError(view, ranges, gear, options, &refined, &why, false, &sr)) {
    keepIntegralEstimates(*res, &refined);
    *res = std::move(refined);
    res->estimator = "output_error_ste";
    st->theta = sr.theta;
    st->theta_std = sr.theta_std;
    fillTerms(basis, st);
    st->refined = true;
  } else {
    res->warnings.push_back(
        {quality_code::kRefineFailed,
         "output-error refinement failed (" + why + "): integral-method estimates reported"});
  }
  applyQualityFlags(options, res);
}

}  // namespace

bool identifyWithSte(const gear_sim::SignalTable& table, const GearConstants& gear,
                     const IdentificationOptions& options, const SteModelOptions& so,
                     IdentificationResult* result, SteResult* ste, std::string* error) {
  auto fail = [&](const std::string& e) {
    if (error) *error = e;
    return false;
  };
  if (auto e = options.validate(); !e.empty()) return fail(e);
  if (auto e = gear.validate(); !e.empty()) return fail(e);
  if (auto e = so.validate(); !e.empty()) return fail(e);
  const bool greybox = options.formulation == Formulation::Greybox;
  if (options.formulation != Formulation::Known && !greybox)
    return fail("--ste: only the known and greybox formulations model the STE");
  if (options.model == DampingModel::LoadLaw)
    return fail(
        "--ste: the load_law damping model is not available with the STE (use piecewise "
        "or constant)");
  if (greybox && options.stiffness_shape.kind != StiffnessShape::Kind::Square)
    return fail("--ste: greybox needs the square stiffness shape");
  using gear_sim::SignalTable;
  if (!SignalTable::has(table.mesh_phase))
    return fail("--ste needs the mesh_phase column (the STE is a function of the mesh phase)");
  if (!SignalTable::has(table.torque)) return fail("--ste needs the torque column");
  if (!greybox && !SignalTable::has(table.stiffness))
    return fail("--ste with the known formulation needs the stiffness column");
  if (greybox && !SignalTable::has(table.mesh_state))
    return fail("--ste with the greybox formulation needs the mesh_state column");
  if (auto e = checkSignalTable(table, options.formulation, options.model, options.time_tolerance);
      !e.empty())
    return fail(e);

  const SignalView view = SignalView::of(table);
  const Eigen::Index n = view.n;
  const double h = view.dt, me = gear.equivalent_mass;
  for (Eigen::Index i = 0; i < n; ++i)
    if (!std::isfinite(view.dte[i]) || !std::isfinite(view.mesh_phase[i]) ||
        !std::isfinite(view.torque[i]) || (!greybox && !std::isfinite(view.stiffness[i])) ||
        (greybox && !std::isfinite(view.mesh_state[i])))
      return fail("--ste: non-finite input at sample " + std::to_string(i) +
                  " (the joint STE solve needs a clean record)");
  const auto ranges = segmentRanges(view, options);
  if (ranges.empty()) return fail("no samples in the analysed time range");
  double window =
      options.window_length > 0.0 ? options.window_length : defaultWindowLength(view, gear);

  // Sampled inputs.
  const gear_sim::SteBasis basis = so.basis();
  const int J = basis.size();
  Eigen::MatrixXd B(J, n);  // basis values, one column per sample
  for (Eigen::Index i = 0; i < n; ++i) basis.eval(view.mesh_phase[i], B.col(i).data());
  Eigen::MatrixXd Bt = B.transpose();  // n x J: contiguous per basis function
  std::vector<double> F(n), W(n), theta(n, 1.0);
  for (Eigen::Index i = 0; i < n; ++i) F[i] = gear.force_factor * view.torque[i];
  const bool held = greybox || gear.piecewise_constant_stiffness;
  for (Eigen::Index i = 0; i < n; ++i) W[i] = greybox ? view.mesh_state[i] : view.stiffness[i] / me;
  long unlocated = 0;
  if (held)
    for (Eigen::Index j = 0; j + 1 < n; ++j)
      if (W[j + 1] != W[j]) {
        theta[j] = switchFraction(view.mesh_phase[j], view.mesh_phase[j + 1], gear.contact_ratio,
                                  W[j + 1] > W[j]);
        if (theta[j] < 0.0) {  // not located: the new value holds from sample j + 1 on
          theta[j] = 1.0;
          ++unlocated;
        }
      }

  // Multipliers: C (coupled in the relative form), and K0, dK for greybox (always coupled).
  const bool relative = so.damping == gear_sim::SteDamping::Relative;
  std::vector<Multiplier> mult{{relative}};
  if (greybox) mult.insert(mult.end(), {{true}, {true}});
  const int n_a = static_cast<int>(mult.size());
  // Raw column layout: 0 = b0; per multiplier: Y_a then (coupled) B_a1..J; known: IIKb_1..J.
  std::vector<int> col_Y(n_a), col_B(n_a, -1);
  int R = 1;
  for (int a = 0; a < n_a; ++a) {
    col_Y[a] = R++;
    if (mult[a].coupled) {
      col_B[a] = R;
      R += J;
    }
  }
  const int col_Kb = greybox ? -1 : R;
  if (!greybox) R += J;

  const CubicRules rules;
  struct Seg {
    Eigen::Index begin, end;
    Eigen::MatrixXd gram;
    long rows = 0;
    int windows = 0;
    double mean_torque = 0, mean_state = 0, k_sum = 0;
  };
  std::vector<Seg> segs;
  Eigen::MatrixXd Z;
  std::vector<double> P1, Q1, P2, Q2;
  double scratch[4];
  long total_rows = 0, total_windows = 0;
  // The raw columns of window [w0, w1), nuisance {1, t - T} projected out, into Z.
  auto buildWindow = [&](Eigen::Index w0, Eigen::Index w1) {
    const Eigen::Index m = w1 - w0;
    Z.resize(m, R);
    P1.resize(m);
    Q1.resize(m);
    P2.resize(m);
    Q2.resize(m);
    // b0 = y - IIF (+ IIKy for known)
    cumulate(F.data(), nullptr, false, nullptr, w0, w1, n, h, rules, P1.data(), Q1.data(), scratch);
    for (Eigen::Index i = 0; i < m; ++i) Z(i, 0) = view.dte[w0 + i] - Q1[i];
    // y integrals
    cumulate(view.dte, nullptr, false, nullptr, w0, w1, n, h, rules, P1.data(), Q1.data(),
             scratch);  // P_y, IIy
    if (!greybox) {
      cumulate(view.dte, W.data(), held, theta.data(), w0, w1, n, h, rules, P2.data(), Q2.data(),
               scratch);  // IIKy
      for (Eigen::Index i = 0; i < m; ++i) Z(i, 0) += Q2[i];
    }
    for (Eigen::Index i = 0; i < m; ++i) Z(i, col_Y[0]) = P1[i];
    if (greybox) {
      for (Eigen::Index i = 0; i < m; ++i) Z(i, col_Y[1]) = Q1[i];
      cumulate(view.dte, W.data(), true, theta.data(), w0, w1, n, h, rules, P2.data(), Q2.data(),
               scratch);  // IIsy
      for (Eigen::Index i = 0; i < m; ++i) Z(i, col_Y[2]) = Q2[i];
    }
    // basis integrals
    for (int j = 0; j < J; ++j) {
      const double* b = Bt.col(j).data();
      cumulate(b, nullptr, false, nullptr, w0, w1, n, h, rules, P1.data(), Q1.data(), scratch);
      if (col_B[0] >= 0)
        for (Eigen::Index i = 0; i < m; ++i) Z(i, col_B[0] + j) = P1[i];
      if (greybox) {
        for (Eigen::Index i = 0; i < m; ++i) Z(i, col_B[1] + j) = Q1[i];
        cumulate(b, W.data(), true, theta.data(), w0, w1, n, h, rules, P2.data(), Q2.data(),
                 scratch);
        for (Eigen::Index i = 0; i < m; ++i) Z(i, col_B[2] + j) = Q2[i];
      } else {
        cumulate(b, W.data(), held, theta.data(), w0, w1, n, h, rules, P2.data(), Q2.data(),
                 scratch);
        for (Eigen::Index i = 0; i < m; ++i) Z(i, col_Kb + j) = Q2[i];
      }
    }
    // Project out the window's nuisance {1, t - T} (two passes: no cancellation).
    const double tbar = 0.5 * static_cast<double>(m - 1);
    double p1p1 = 0.0;
    for (Eigen::Index i = 0; i < m; ++i) p1p1 += (i - tbar) * (i - tbar);
    for (int c = 0; c < R; ++c) {
      auto z = Z.col(c);
      z.array() -= z.mean();
      if (p1p1 > 0.0) {
        double zp = 0.0;
        for (Eigen::Index i = 0; i < m; ++i) zp += z[i] * (i - tbar);
        const double k = zp / p1p1;
        for (Eigen::Index i = 0; i < m; ++i) z[i] -= k * (i - tbar);
      }
    }
  };
  auto windowCount = [&](Eigen::Index len) {
    return std::max<Eigen::Index>(1,
                                  std::min<Eigen::Index>(len / 8, std::llround(len * h / window)));
  };
  for (const auto& rg : ranges) {
    Seg s;
    s.begin = rg.first;
    s.end = rg.second;
    s.gram = Eigen::MatrixXd::Zero(R, R);
    const Eigen::Index len = s.end - s.begin;
    if (len < 8) continue;
    const auto nw = windowCount(len);
    for (Eigen::Index w = 0; w < nw; ++w) {
      const Eigen::Index w0 = s.begin + len * w / nw, w1 = s.begin + len * (w + 1) / nw;
      const Eigen::Index m = w1 - w0;
      buildWindow(w0, w1);
      s.gram.selfadjointView<Eigen::Lower>().rankUpdate(Z.transpose());
      s.rows += m;
      ++s.windows;
    }
    s.gram = s.gram.selfadjointView<Eigen::Lower>();
    for (Eigen::Index i = s.begin; i < s.end; ++i) {
      s.mean_torque += view.torque[i];
      s.mean_state += greybox ? W[i] : 0.0;
      s.k_sum += greybox ? 0.0 : W[i];
    }
    s.mean_torque /= static_cast<double>(len);
    s.mean_state /= static_cast<double>(len);
    total_rows += s.rows;
    total_windows += s.windows;
    segs.push_back(std::move(s));
  }
  if (segs.empty()) return fail("--ste: no segment with enough samples");
  const int S = static_cast<int>(segs.size());

  // Unknowns: per segment its local multipliers; shared C (constant model); theta.
  const bool shared_c = options.model == DampingModel::Constant;
  const int n_local = n_a - (shared_c ? 1 : 0);
  const int off_shared = S * n_local;
  const int off_theta = off_shared + (shared_c ? 1 : 0);
  const int Pn = off_theta + J;
  auto index = [&](int s, int a) {  // global index of multiplier a in segment s
    if (a == 0 && shared_c) return off_shared;
    return s * n_local + (a - (shared_c ? 1 : 0));
  };
  std::vector<double> a0(static_cast<size_t>(Pn), 0.0);  // current estimate (all unknowns)

  // Map from segment s's raw columns to its design columns [x_a (a < n_a), x_theta_j, b],
  // linearised about the current estimate a0; idx: their global unknown indices (b: Pn).
  auto designMap = [&](int s, bool with_theta, Eigen::MatrixXd* Mp, std::vector<int>* idxp) {
    Eigen::MatrixXd& M = *Mp;
    // M: R x (n_a + J + 1): columns x_a (a = 0..n_a-1), x_theta_j, b.
    M = Eigen::MatrixXd::Zero(R, n_a + J + 1);
    const int cb = n_a + J;
    M(0, cb) = 1.0;
    for (int a = 0; a < n_a; ++a) {
      const double av = a0[index(s, a)];
      M(col_Y[a], a) = -1.0;
      if (col_B[a] < 0) continue;
      for (int j = 0; j < J; ++j) {
        const double th = with_theta ? a0[off_theta + j] : 0.0;
        M(col_B[a] + j, a) += th;
        M(col_B[a] + j, n_a + j) += av;
        M(col_B[a] + j, cb) += av * th;
      }
    }
    if (!greybox)
      for (int j = 0; j < J; ++j) M(col_Kb + j, n_a + j) = 1.0;
    std::vector<int>& idx = *idxp;
    idx.resize(n_a + J + 1);
    for (int a = 0; a < n_a; ++a) idx[a] = index(s, a);
    for (int j = 0; j < J; ++j) idx[n_a + j] = off_theta + j;
    idx[cb] = Pn;
  };

  Eigen::MatrixXd N(Pn + 1, Pn + 1), M;
  std::vector<int> idx;
  Eigen::VectorXd p;
  Eigen::MatrixXd cov;
  double rss = 0.0, cond = kNaN;
  int iterations = 0;
  bool solved = false;
  const int max_it = so.max_iterations;
  for (int it = 0; it <= max_it; ++it) {
    const bool with_theta = !(greybox && it == 0);  // greybox starts from the no-STE solution
    N.setZero();
    for (int s = 0; s < S; ++s) {
      designMap(s, with_theta, &M, &idx);
      const int cb = n_a + J;
      const Eigen::MatrixXd g = M.transpose() * segs[s].gram * M;
      for (int r = 0; r <= cb; ++r)
        for (int c = 0; c <= cb; ++c) N(idx[r], idx[c]) += g(r, c);
    }
    // Active unknowns of this iteration.
    const int Pa = with_theta ? Pn : off_theta;
    const Eigen::MatrixXd A = N.topLeftCorner(Pa, Pa);
    const Eigen::VectorXd rhs = N.col(Pn).head(Pa);
    Eigen::VectorXd d = A.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
    const Eigen::MatrixXd Ae = d.asDiagonal() * A * d.asDiagonal();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Ae);
    Eigen::VectorXd lam = es.eigenvalues();
    // A rank-deficient problem (e.g. shaft orders on a fraction of a revolution) is solved in the
    // minimum-norm sense and reported as not separable, its numbers blanked (below).
    cond = lam.minCoeff() > 0.0 ? std::sqrt(lam.maxCoeff() / lam.minCoeff())
                                : std::numeric_limits<double>::infinity();
    const double floor_lam = lam.maxCoeff() * 1e-14;
    for (Eigen::Index k = 0; k < lam.size(); ++k)
      if (!(lam[k] > floor_lam)) lam[k] = std::numeric_limits<double>::infinity();
    const Eigen::MatrixXd Ainv_e =
        es.eigenvectors() * lam.cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
    p = d.asDiagonal() * (Ainv_e * (d.asDiagonal() * rhs));
    rss = N(Pn, Pn) - 2.0 * p.dot(rhs) + p.dot(A * p);
    // Converged when no unknown's step changes the fit by more than 1e-10 of the data's norm.
    double change = 0.0;
    for (int k = 0; k < Pa; ++k) {
      change = std::max(change, std::abs(p[k] - a0[k]) * std::sqrt(std::max(A(k, k), 0.0)));
      a0[k] = p[k];
    }
    const double scale = std::sqrt(std::max(N(Pn, Pn), 0.0));
    iterations = it + 1;
    const bool linear = !greybox && !relative;
    if (with_theta && (linear || change <= 1e-10 * scale)) {
      cov = d.asDiagonal() * Ainv_e * d.asDiagonal();
      solved = true;
      break;
    }
    if (with_theta && it == max_it) {
      cov = d.asDiagonal() * Ainv_e * d.asDiagonal();
      solved = true;
      result->warnings.push_back(
          {quality_code::kRefineNotConverged, "the joint STE Gauss-Newton did not converge in " +
                                                  std::to_string(max_it) + " iterations"});
    }
  }
  if (!solved)
    return fail("--ste: the joint damping/STE problem is rank deficient (condition " +
                std::to_string(cond) + ")");

  // Standard errors robust to the correlation of the integral equations' residuals within a
  // window (they integrate the noise): the cluster sandwich A^-1 (sum_w g_w g_w^T) A^-1, g_w the
  // window's score X_w^T r_w; a second pass over the data at the solution. The plain
  // sigma^2 A^-1 (rows treated as independent) is the fallback when it is larger.
  Eigen::MatrixXd meat = Eigen::MatrixXd::Zero(Pn, Pn);
  {
    Eigen::VectorXd g(Pn);
    for (int s = 0; s < S; ++s) {
      designMap(s, true, &M, &idx);
      const int cb = n_a + J;
      Eigen::VectorXd coef(cb + 1);  // residual = X coef
      for (int k = 0; k < cb; ++k) coef[k] = -p[idx[k]];
      coef[cb] = 1.0;
      const Seg& sg = segs[s];
      const Eigen::Index len = sg.end - sg.begin, nw = windowCount(len);
      for (Eigen::Index w = 0; w < nw; ++w) {
        buildWindow(sg.begin + len * w / nw, sg.begin + len * (w + 1) / nw);
        const Eigen::MatrixXd X = Z * M;
        const Eigen::VectorXd r = X * coef;
        const Eigen::VectorXd sc = X.leftCols(cb).transpose() * r;
        g.setZero();
        for (int k = 0; k < cb; ++k) g[idx[k]] += sc[k];
        meat.noalias() += g * g.transpose();
      }
    }
  }
  const Eigen::MatrixXd cov_robust = cov * meat * cov;
  const double dof = static_cast<double>(total_rows - Pn - 2 * total_windows);
  const double sigma2 = dof > 0 ? std::max(rss, 0.0) / dof : kNaN;
  // Correlations come from the unscaled inverse (scale-free; defined on noise-free data too).
  const Eigen::MatrixXd inv_unscaled = cov;
  cov *= sigma2;
  for (int k = 0; k < Pn; ++k)
    if (cov_robust(k, k) > cov(k, k)) {
      cov = cov_robust;
      break;
    }

  // Fill the damping result.
  IdentificationResult& res = *result;
  res.formulation = options.formulation;
  res.model = options.model;
  res.equivalent_mass = me;
  res.window_length = window;
  res.estimator = "integral_ste";
  res.iterations = iterations;
  res.segments.clear();
  double k_total = 0.0;
  long n_total = 0;
  for (const Seg& s : segs) {
    k_total += s.k_sum;
    n_total += s.end - s.begin;
  }
  const double omega0_known = std::sqrt(k_total / static_cast<double>(n_total));
  double omega_sum = 0.0;
  for (int s = 0; s < S; ++s) {
    const Seg& sg = segs[s];
    SegmentEstimate e;
    e.t_start = view.time(sg.begin);
    e.t_end = view.time(sg.end - 1);
    const int ic = index(s, 0);
    e.C = p[ic];
    e.C_std = std::sqrt(cov(ic, ic));
    e.c = e.C * me;
    double omega0 = omega0_known;
    if (greybox) {
      const int i0 = index(s, 1), i1 = index(s, 2);
      e.k_min = p[i0] * me;
      e.k_max = (p[i0] + p[i1]) * me;
      e.k_min_std = std::sqrt(cov(i0, i0)) * me;
      e.k_max_std = std::sqrt(cov(i0, i0) + cov(i1, i1) + 2.0 * cov(i0, i1)) * me;
      omega0 = std::sqrt(std::max(0.0, p[i0] + p[i1] * sg.mean_state));
    }
    omega_sum += omega0;
    e.xi = e.C / (2.0 * omega0);
    e.samples = sg.rows;
    e.windows = sg.windows;
    e.identifiable = true;
    e.mean_torque = sg.mean_torque;
    e.condition = cond;
    e.residual_rms = std::sqrt(std::max(rss, 0.0) / static_cast<double>(total_rows));
    res.segments.push_back(e);
  }
  res.omega0 = omega_sum / S;
  if (shared_c) {
    SegmentEstimate c = res.segments.front();
    c.t_end = res.segments.back().t_end;
    c.samples = total_rows;
    c.windows = static_cast<int>(total_windows);
    res.constant = c;
  }
  if (unlocated > 0)
    res.warnings.push_back(
        {quality_code::kSwitchesUnlocated,
         std::to_string(unlocated) + " stiffness switches could not be located from mesh_phase"});

  // STE result and separability.
  SteResult& st = *ste;
  st = SteResult{};
  st.options = so;
  st.theta.resize(J);
  st.theta_std.resize(J);
  for (int j = 0; j < J; ++j) {
    st.theta[j] = p[off_theta + j];
    st.theta_std[j] = std::sqrt(cov(off_theta + j, off_theta + j));
  }
  fillTerms(basis, &st);
  double max_corr = 0.0;
  for (int s = 0; s < S; ++s)
    for (int j = 0; j < J; ++j) {
      const int ic = index(s, 0), it = off_theta + j;
      const double r =
          inv_unscaled(ic, it) / std::sqrt(inv_unscaled(ic, ic) * inv_unscaled(it, it));
      if (std::isfinite(r)) max_corr = std::max(max_corr, std::abs(r));
    }
  st.condition = cond;
  st.max_correlation = max_corr;
  st.separable = cond <= options.max_condition && max_corr <= so.max_correlation;
  st.iterations = iterations;
  st.rows = total_rows;
  st.residual_rms = std::sqrt(std::max(rss, 0.0) / static_cast<double>(total_rows));
  if (!st.separable) {
    std::ostringstream os;
    os << "damping and STE are not separately identifiable on this record: condition " << cond
       << " (limit " << options.max_condition << "), largest damping-STE correlation " << max_corr
       << " (limit " << so.max_correlation << ")";
    res.warnings.push_back({quality_code::kSteNotSeparable, os.str()});
    for (auto& e : res.segments) e.warnings.push_back({quality_code::kSteNotSeparable, os.str()});
    if (!(cond <= 1e7)) {  // numerically rank deficient: no numbers at all
      for (auto& e : res.segments) {
        const SegmentEstimate blank;
        e.C = e.C_std = e.c = e.xi = e.k_min = e.k_max = e.k_min_std = e.k_max_std = blank.C;
        e.identifiable = false;
        e.reason = "damping and STE not separable (rank deficient joint problem)";
      }
      if (res.constant) *res.constant = res.segments.front();
      for (double& v : st.theta) v = kNaN;
      for (double& v : st.theta_std) v = kNaN;
      for (auto& t : st.terms) t.cos = t.sin = t.cos_std = t.sin_std = kNaN;
    }
  }
  std::vector<std::pair<Eigen::Index, Eigen::Index>> seg_ranges;
  for (const Seg& sg : segs) seg_ranges.emplace_back(sg.begin, sg.end);
  refineWithSte(view, seg_ranges, gear, options, basis, relative, &res, &st);
  return true;
}

}  // namespace gear_damping_id
