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

gear_sim::Status parseSteSpec(const std::string& spec, SteModelOptions* out) {
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
    if (v < 0 || v > 32 || (key != "mesh" && key != "shaft" && key != "pinion" && key != "gear"))
      return gear_sim::Status::invalidArgument(
          "'" + item +
          "' is not one of mesh:H, shaft:S, pinion:S, gear:S (0..32), offset, nooffset, none");
    if (key == "mesh") o.mesh_orders = v;
    if (key == "shaft" || key == "pinion") o.pinion_orders = v;
    if (key == "shaft" || key == "gear") o.gear_orders = v;
  }
  *out = o;
  return {};
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
  if (!st->separable || !wantsRefinement(options)) {
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
  const gear_sim::Status refine =
      refineOutputError(view, ranges, gear, options, &refined, false, &sr);
  if (refine.ok()) {
    keepIntegralEstimates(*res, &refined);
    *res = std::move(refined);
    res->estimator = "output_error_ste";
    // The refinement gives standard errors only: the covariance keeps the integral fit's
    // correlations, scaled to them (the held-STE path propagates it).
    for (int j = 0; j < basis.size(); ++j) {
      const double s0 = st->theta_std[j];
      const double f = s0 > 0.0 ? sr.theta_std[j] / s0 : 0.0;
      st->theta_cov.row(j) *= f;
      st->theta_cov.col(j) *= f;
    }
    st->theta = sr.theta;
    st->theta_std = sr.theta_std;
    fillTerms(basis, st);
    st->refined = true;
  } else {
    res->warnings.push_back(
        {quality_code::kRefineFailed, "output-error refinement failed (" + refine.message() +
                                          "): integral-method estimates reported"});
  }
  applyQualityFlags(options, res);
}

// The joint damping/STE fit of a set of segments of one view (docs/ste.md), one named step per
// member: the sampled inputs, the raw integral columns of each window, the per-segment Gram
// matrices, the Gauss-Newton solve, the standard errors, and the damping and STE results.
class SteFit {
 public:
  SteFit(const SignalView& view, const GearConstants& gear, const IdentificationOptions& options,
         const SteModelOptions& so)
      : v_(view),
        gear_(gear),
        o_(options),
        so_(so),
        greybox_(options.formulation == Formulation::Greybox),
        relative_(so.damping == gear_sim::SteDamping::Relative),
        n_(view.n),
        h_(view.dt),
        basis_(so.basis()),
        J_(basis_.size()) {
    window_ = options.window_length > 0.0 ? options.window_length : defaultWindowLength(view, gear);
    sampleInputs();
    layoutColumns();
  }

  /// Step 1: the raw columns' Gram matrix of every segment of `ranges` (segments shorter than 8
  /// samples are skipped). False when none is left.
  bool addSegments(const SampleRanges& ranges) {
    for (const auto& rg : ranges) {
      Seg s;
      s.begin = rg.first;
      s.end = rg.second;
      if (s.end - s.begin < 8) continue;
      accumulateSegment(&s);
      total_rows_ += s.rows;
      total_windows_ += s.windows;
      segs_.push_back(std::move(s));
    }
    layoutUnknowns();
    return !segs_.empty();
  }

  /// Step 2: the joint Gauss-Newton solve. NotIdentifiable when rank deficient.
  gear_sim::Status solve(IdentificationResult* res);
  /// Step 3: standard errors (window-clustered sandwich or sigma^2 A^-1, the larger).
  void covariance();
  /// Step 4: the damping estimates in the usual shape.
  void fillDamping(IdentificationResult* res) const;
  /// Step 5: the STE, its separability (flags `res` when not separable).
  void fillSte(SteResult* st, IdentificationResult* res) const;

  SampleRanges segmentRanges() const {
    SampleRanges r;
    for (const Seg& sg : segs_) r.emplace_back(sg.begin, sg.end);
    return r;
  }
  const gear_sim::SteBasis& basis() const { return basis_; }
  bool relative() const { return relative_; }

  /// The held-STE fit of segment 0 (addSegments with one range): the local unknowns given
  /// theta, their covariance (theta's propagated) and the sensitivity of C to theta.
  gear_sim::Status solveHeld(const SteResult& ste);
  /// Held: theta's share of the variance of C [1/s^2].
  double thetaVarianceOfC() const { return theta_var_of_C_; }

 private:
  struct Seg {
    Eigen::Index begin = 0, end = 0;
    Eigen::MatrixXd gram;
    long rows = 0;
    int windows = 0;
    double mean_torque = 0, mean_state = 0, k_sum = 0;
  };

  void sampleInputs();
  void layoutColumns();
  void layoutUnknowns();
  void buildWindow(Eigen::Index w0, Eigen::Index w1);
  void accumulateSegment(Seg* s);
  Eigen::Index windowCount(Eigen::Index len) const {
    return std::max<Eigen::Index>(
        1, std::min<Eigen::Index>(len / 8, std::llround(len * h_ / window_)));
  }
  int index(int s, int a) const {  // global index of multiplier a in segment s
    if (a == 0 && shared_c_) return off_shared_;
    return s * n_local_ + (a - (shared_c_ ? 1 : 0));
  }
  void designMap(int s, bool with_theta, Eigen::MatrixXd* Mp, std::vector<int>* idxp) const;
  Eigen::MatrixXd clusterMeat(const Eigen::VectorXd& p) const;

  const SignalView& v_;
  const GearConstants& gear_;
  const IdentificationOptions& o_;
  const SteModelOptions& so_;
  const bool greybox_, relative_;
  const Eigen::Index n_;
  const double h_;
  const gear_sim::SteBasis basis_;
  const int J_;
  double window_ = 0.0;
  // Sampled inputs.
  Eigen::MatrixXd Bt_;  // n x J: basis values, contiguous per basis function
  std::vector<double> F_, W_, theta_;
  bool held_ = false;
  long unlocated_ = 0;
  // Raw column layout: 0 = b0; per multiplier: Y_a then (coupled) B_a1..J; known: IIKb_1..J.
  // Multipliers: C (coupled in the relative form), and K0, dK for greybox (always coupled).
  int n_a_ = 0, R_ = 1, col_Kb_ = -1;
  std::vector<int> col_Y_, col_B_;
  const CubicRules rules_;
  std::vector<Seg> segs_;
  long total_rows_ = 0, total_windows_ = 0;
  // Window scratch.
  Eigen::MatrixXd Z_;
  std::vector<double> P1_, Q1_, P2_, Q2_;
  double scratch_[4];
  // Unknowns: per segment its local multipliers; shared C (constant model); theta.
  bool shared_c_ = false;
  int n_local_ = 0, off_shared_ = 0, off_theta_ = 0, Pn_ = 0;
  std::vector<double> a0_;  // current estimate (all unknowns)
  // Solution.
  Eigen::VectorXd p_;
  Eigen::MatrixXd cov_, inv_unscaled_;
  double rss_ = 0.0, cond_ = kNaN;
  int iterations_ = 0;
  int unknowns_ = -1;            // for sigma^2's degrees of freedom (-1: Pn_)
  double theta_var_of_C_ = 0.0;  // held: theta's covariance propagated into C
};

void SteFit::sampleInputs() {
  const double me = gear_.equivalent_mass;
  Eigen::MatrixXd B(J_, n_);  // basis values, one column per sample
  for (Eigen::Index i = 0; i < n_; ++i) basis_.eval(v_.mesh_phase[i], B.col(i).data());
  Bt_ = B.transpose();
  F_.resize(n_);
  W_.resize(n_);
  theta_.assign(n_, 1.0);
  for (Eigen::Index i = 0; i < n_; ++i) F_[i] = gear_.force_factor * v_.torque[i];
  held_ = greybox_ || gear_.piecewise_constant_stiffness;
  for (Eigen::Index i = 0; i < n_; ++i) W_[i] = greybox_ ? v_.mesh_state[i] : v_.stiffness[i] / me;
  if (!held_) return;
  for (Eigen::Index j = 0; j + 1 < n_; ++j)
    if (W_[j + 1] != W_[j]) {
      theta_[j] = switchFraction(v_.mesh_phase[j], v_.mesh_phase[j + 1], gear_.contact_ratio,
                                 W_[j + 1] > W_[j]);
      if (theta_[j] < 0.0) {  // not located: the new value holds from sample j + 1 on
        theta_[j] = 1.0;
        ++unlocated_;
      }
    }
}

void SteFit::layoutColumns() {
  std::vector<Multiplier> mult{{relative_}};
  if (greybox_) mult.insert(mult.end(), {{true}, {true}});
  n_a_ = static_cast<int>(mult.size());
  col_Y_.assign(n_a_, 0);
  col_B_.assign(n_a_, -1);
  R_ = 1;
  for (int a = 0; a < n_a_; ++a) {
    col_Y_[a] = R_++;
    if (mult[a].coupled) {
      col_B_[a] = R_;
      R_ += J_;
    }
  }
  col_Kb_ = greybox_ ? -1 : R_;
  if (!greybox_) R_ += J_;
}

void SteFit::layoutUnknowns() {
  const int S = static_cast<int>(segs_.size());
  shared_c_ = o_.model == DampingModel::Constant;
  n_local_ = n_a_ - (shared_c_ ? 1 : 0);
  off_shared_ = S * n_local_;
  off_theta_ = off_shared_ + (shared_c_ ? 1 : 0);
  Pn_ = off_theta_ + J_;
  a0_.assign(static_cast<size_t>(Pn_), 0.0);
}

// The raw columns of window [w0, w1), nuisance {1, t - T} projected out, into Z_.
void SteFit::buildWindow(Eigen::Index w0, Eigen::Index w1) {
  const Eigen::Index m = w1 - w0;
  Eigen::MatrixXd& Z = Z_;
  Z.resize(m, R_);
  P1_.resize(m);
  Q1_.resize(m);
  P2_.resize(m);
  Q2_.resize(m);
  double *P1 = P1_.data(), *Q1 = Q1_.data(), *P2 = P2_.data(), *Q2 = Q2_.data();
  // b0 = y - IIF (+ IIKy for known)
  cumulate(F_.data(), nullptr, false, nullptr, w0, w1, n_, h_, rules_, P1, Q1, scratch_);
  for (Eigen::Index i = 0; i < m; ++i) Z(i, 0) = v_.dte[w0 + i] - Q1[i];
  // y integrals: P_y, IIy
  cumulate(v_.dte, nullptr, false, nullptr, w0, w1, n_, h_, rules_, P1, Q1, scratch_);
  if (!greybox_) {
    cumulate(v_.dte, W_.data(), held_, theta_.data(), w0, w1, n_, h_, rules_, P2, Q2,
             scratch_);  // IIKy
    for (Eigen::Index i = 0; i < m; ++i) Z(i, 0) += Q2[i];
  }
  for (Eigen::Index i = 0; i < m; ++i) Z(i, col_Y_[0]) = P1[i];
  if (greybox_) {
    for (Eigen::Index i = 0; i < m; ++i) Z(i, col_Y_[1]) = Q1[i];
    cumulate(v_.dte, W_.data(), true, theta_.data(), w0, w1, n_, h_, rules_, P2, Q2,
             scratch_);  // IIsy
    for (Eigen::Index i = 0; i < m; ++i) Z(i, col_Y_[2]) = Q2[i];
  }
  // basis integrals
  for (int j = 0; j < J_; ++j) {
    const double* b = Bt_.col(j).data();
    cumulate(b, nullptr, false, nullptr, w0, w1, n_, h_, rules_, P1, Q1, scratch_);
    if (col_B_[0] >= 0)
      for (Eigen::Index i = 0; i < m; ++i) Z(i, col_B_[0] + j) = P1[i];
    if (greybox_) {
      for (Eigen::Index i = 0; i < m; ++i) Z(i, col_B_[1] + j) = Q1[i];
      cumulate(b, W_.data(), true, theta_.data(), w0, w1, n_, h_, rules_, P2, Q2, scratch_);
      for (Eigen::Index i = 0; i < m; ++i) Z(i, col_B_[2] + j) = Q2[i];
    } else {
      cumulate(b, W_.data(), held_, theta_.data(), w0, w1, n_, h_, rules_, P2, Q2, scratch_);
      for (Eigen::Index i = 0; i < m; ++i) Z(i, col_Kb_ + j) = Q2[i];
    }
  }
  // Project out the window's nuisance {1, t - T} (two passes: no cancellation).
  const double tbar = 0.5 * static_cast<double>(m - 1);
  double p1p1 = 0.0;
  for (Eigen::Index i = 0; i < m; ++i) p1p1 += (i - tbar) * (i - tbar);
  for (int c = 0; c < R_; ++c) {
    auto z = Z.col(c);
    z.array() -= z.mean();
    if (p1p1 > 0.0) {
      double zp = 0.0;
      for (Eigen::Index i = 0; i < m; ++i) zp += z[i] * (i - tbar);
      const double k = zp / p1p1;
      for (Eigen::Index i = 0; i < m; ++i) z[i] -= k * (i - tbar);
    }
  }
}

void SteFit::accumulateSegment(Seg* sp) {
  Seg& s = *sp;
  s.gram = Eigen::MatrixXd::Zero(R_, R_);
  const Eigen::Index len = s.end - s.begin;
  const auto nw = windowCount(len);
  for (Eigen::Index w = 0; w < nw; ++w) {
    const Eigen::Index w0 = s.begin + len * w / nw, w1 = s.begin + len * (w + 1) / nw;
    buildWindow(w0, w1);
    s.gram.selfadjointView<Eigen::Lower>().rankUpdate(Z_.transpose());
    s.rows += w1 - w0;
    ++s.windows;
  }
  s.gram = s.gram.selfadjointView<Eigen::Lower>();
  for (Eigen::Index i = s.begin; i < s.end; ++i) {
    s.mean_torque += v_.torque[i];
    s.mean_state += greybox_ ? W_[i] : 0.0;
    s.k_sum += greybox_ ? 0.0 : W_[i];
  }
  s.mean_torque /= static_cast<double>(len);
  s.mean_state /= static_cast<double>(len);
}

// Map from segment s's raw columns to its design columns [x_a (a < n_a), x_theta_j, b],
// linearised about the current estimate a0_; idx: their global unknown indices (b: Pn).
void SteFit::designMap(int s, bool with_theta, Eigen::MatrixXd* Mp, std::vector<int>* idxp) const {
  Eigen::MatrixXd& M = *Mp;
  M = Eigen::MatrixXd::Zero(R_, n_a_ + J_ + 1);
  const int cb = n_a_ + J_;
  M(0, cb) = 1.0;
  for (int a = 0; a < n_a_; ++a) {
    const double av = a0_[index(s, a)];
    M(col_Y_[a], a) = -1.0;
    if (col_B_[a] < 0) continue;
    for (int j = 0; j < J_; ++j) {
      const double th = with_theta ? a0_[off_theta_ + j] : 0.0;
      M(col_B_[a] + j, a) += th;
      M(col_B_[a] + j, n_a_ + j) += av;
      M(col_B_[a] + j, cb) += av * th;
    }
  }
  if (!greybox_)
    for (int j = 0; j < J_; ++j) M(col_Kb_ + j, n_a_ + j) = 1.0;
  std::vector<int>& idx = *idxp;
  idx.resize(n_a_ + J_ + 1);
  for (int a = 0; a < n_a_; ++a) idx[a] = index(s, a);
  for (int j = 0; j < J_; ++j) idx[n_a_ + j] = off_theta_ + j;
  idx[cb] = Pn_;
}

gear_sim::Status SteFit::solve(IdentificationResult* res) {
  const int S = static_cast<int>(segs_.size()), Pn = Pn_;
  Eigen::MatrixXd N(Pn + 1, Pn + 1), M;
  std::vector<int> idx;
  bool solved = false;
  const int max_it = so_.max_iterations;
  for (int it = 0; it <= max_it; ++it) {
    const bool with_theta = !(greybox_ && it == 0);  // greybox starts from the no-STE solution
    N.setZero();
    for (int s = 0; s < S; ++s) {
      designMap(s, with_theta, &M, &idx);
      const int cb = n_a_ + J_;
      const Eigen::MatrixXd g = M.transpose() * segs_[s].gram * M;
      for (int r = 0; r <= cb; ++r)
        for (int c = 0; c <= cb; ++c) N(idx[r], idx[c]) += g(r, c);
    }
    // Active unknowns of this iteration.
    const int Pa = with_theta ? Pn : off_theta_;
    const Eigen::MatrixXd A = N.topLeftCorner(Pa, Pa);
    const Eigen::VectorXd rhs = N.col(Pn).head(Pa);
    Eigen::VectorXd d = A.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
    const Eigen::MatrixXd Ae = d.asDiagonal() * A * d.asDiagonal();
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Ae);
    Eigen::VectorXd lam = es.eigenvalues();
    // A rank-deficient problem (e.g. shaft orders on a fraction of a revolution) is solved in the
    // minimum-norm sense and reported as not separable, its numbers blanked (fillSte).
    cond_ = lam.minCoeff() > 0.0 ? std::sqrt(lam.maxCoeff() / lam.minCoeff())
                                 : std::numeric_limits<double>::infinity();
    const double floor_lam = lam.maxCoeff() * 1e-14;
    for (Eigen::Index k = 0; k < lam.size(); ++k)
      if (!(lam[k] > floor_lam)) lam[k] = std::numeric_limits<double>::infinity();
    const Eigen::MatrixXd Ainv_e =
        es.eigenvectors() * lam.cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
    p_ = d.asDiagonal() * (Ainv_e * (d.asDiagonal() * rhs));
    rss_ = N(Pn, Pn) - 2.0 * p_.dot(rhs) + p_.dot(A * p_);
    // Converged when no unknown's step changes the fit by more than 1e-10 of the data's norm.
    double change = 0.0;
    for (int k = 0; k < Pa; ++k) {
      change = std::max(change, std::abs(p_[k] - a0_[k]) * std::sqrt(std::max(A(k, k), 0.0)));
      a0_[k] = p_[k];
    }
    const double scale = std::sqrt(std::max(N(Pn, Pn), 0.0));
    iterations_ = it + 1;
    const bool linear = !greybox_ && !relative_;
    if (with_theta && (linear || change <= 1e-10 * scale)) {
      cov_ = d.asDiagonal() * Ainv_e * d.asDiagonal();
      solved = true;
      break;
    }
    if (with_theta && it == max_it) {
      cov_ = d.asDiagonal() * Ainv_e * d.asDiagonal();
      solved = true;
      res->warnings.push_back(
          {quality_code::kRefineNotConverged, "the joint STE Gauss-Newton did not converge in " +
                                                  std::to_string(max_it) + " iterations"});
    }
  }
  if (!solved)
    return gear_sim::Status::notIdentifiable(
        "--ste: the joint damping/STE problem is rank deficient (condition " +
        std::to_string(cond_) + ")");
  return {};
}

// The window-clustered "meat" sum_w g_w g_w^T of the sandwich, g_w = X_w^T r_w the window's
// score at the solution p (a second pass over the data).
Eigen::MatrixXd SteFit::clusterMeat(const Eigen::VectorXd& p) const {
  SteFit& self = const_cast<SteFit&>(*this);  // window scratch only
  Eigen::MatrixXd meat = Eigen::MatrixXd::Zero(Pn_, Pn_);
  Eigen::VectorXd g(Pn_);
  Eigen::MatrixXd M;
  std::vector<int> idx;
  for (int s = 0; s < static_cast<int>(segs_.size()); ++s) {
    designMap(s, true, &M, &idx);
    const int cb = n_a_ + J_;
    Eigen::VectorXd coef(cb + 1);  // residual = X coef
    for (int k = 0; k < cb; ++k) coef[k] = -p[idx[k]];
    coef[cb] = 1.0;
    const Seg& sg = segs_[s];
    const Eigen::Index len = sg.end - sg.begin, nw = windowCount(len);
    for (Eigen::Index w = 0; w < nw; ++w) {
      self.buildWindow(sg.begin + len * w / nw, sg.begin + len * (w + 1) / nw);
      const Eigen::MatrixXd X = Z_ * M;
      const Eigen::VectorXd r = X * coef;
      const Eigen::VectorXd sc = X.leftCols(cb).transpose() * r;
      g.setZero();
      for (int k = 0; k < cb; ++k) g[idx[k]] += sc[k];
      meat.noalias() += g * g.transpose();
    }
  }
  return meat;
}

// Standard errors robust to the correlation of the integral equations' residuals within a
// window (they integrate the noise): the cluster sandwich A^-1 (sum_w g_w g_w^T) A^-1. The plain
// sigma^2 A^-1 (rows treated as independent) is the fallback when it is larger.
void SteFit::covariance() {
  const Eigen::MatrixXd meat = clusterMeat(p_);
  const Eigen::MatrixXd cov_robust = cov_ * meat * cov_;
  const int unknowns = unknowns_ >= 0 ? unknowns_ : Pn_;
  const double dof = static_cast<double>(total_rows_ - unknowns - 2 * total_windows_);
  const double sigma2 = dof > 0 ? std::max(rss_, 0.0) / dof : kNaN;
  // Correlations come from the unscaled inverse (scale-free; defined on noise-free data too).
  inv_unscaled_ = cov_;
  cov_ *= sigma2;
  for (int k = 0; k < Pn_; ++k)
    if (cov_robust(k, k) > cov_(k, k)) {
      cov_ = cov_robust;
      break;
    }
}

void SteFit::fillDamping(IdentificationResult* result) const {
  const double me = gear_.equivalent_mass;
  const int S = static_cast<int>(segs_.size());
  IdentificationResult& res = *result;
  res.formulation = o_.formulation;
  res.model = o_.model;
  res.equivalent_mass = me;
  res.window_length = window_;
  res.estimator = "integral_ste";
  res.iterations = iterations_;
  res.segments.clear();
  double k_total = 0.0;
  long n_total = 0;
  for (const Seg& s : segs_) {
    k_total += s.k_sum;
    n_total += s.end - s.begin;
  }
  const double omega0_known = std::sqrt(k_total / static_cast<double>(n_total));
  double omega_sum = 0.0;
  for (int s = 0; s < S; ++s) {
    const Seg& sg = segs_[s];
    SegmentEstimate e;
    e.t_start = v_.time(sg.begin);
    e.t_end = v_.time(sg.end - 1);
    const int ic = index(s, 0);
    e.C = p_[ic];
    e.C_std = std::sqrt(cov_(ic, ic));
    e.c = e.C * me;
    double omega0 = omega0_known;
    if (greybox_) {
      const int i0 = index(s, 1), i1 = index(s, 2);
      e.k_min = p_[i0] * me;
      e.k_max = (p_[i0] + p_[i1]) * me;
      e.k_min_std = std::sqrt(cov_(i0, i0)) * me;
      e.k_max_std = std::sqrt(cov_(i0, i0) + cov_(i1, i1) + 2.0 * cov_(i0, i1)) * me;
      omega0 = std::sqrt(std::max(0.0, p_[i0] + p_[i1] * sg.mean_state));
    }
    omega_sum += omega0;
    e.xi = e.C / (2.0 * omega0);
    e.samples = sg.rows;
    e.windows = sg.windows;
    e.identifiable = true;
    e.mean_torque = sg.mean_torque;
    e.condition = cond_;
    e.residual_rms = std::sqrt(std::max(rss_, 0.0) / static_cast<double>(total_rows_));
    res.segments.push_back(e);
  }
  res.omega0 = omega_sum / S;
  if (shared_c_) {
    SegmentEstimate c = res.segments.front();
    c.t_end = res.segments.back().t_end;
    c.samples = total_rows_;
    c.windows = static_cast<int>(total_windows_);
    res.constant = c;
  }
  if (unlocated_ > 0)
    res.warnings.push_back(
        {quality_code::kSwitchesUnlocated,
         std::to_string(unlocated_) + " stiffness switches could not be located from mesh_phase"});
}

void SteFit::fillSte(SteResult* ste, IdentificationResult* result) const {
  SteResult& st = *ste;
  IdentificationResult& res = *result;
  st = SteResult{};
  st.options = so_;
  st.theta.resize(J_);
  st.theta_std.resize(J_);
  for (int j = 0; j < J_; ++j) {
    st.theta[j] = p_[off_theta_ + j];
    st.theta_std[j] = std::sqrt(cov_(off_theta_ + j, off_theta_ + j));
  }
  st.theta_cov = cov_.bottomRightCorner(J_, J_);
  fillTerms(basis_, &st);
  double max_corr = 0.0;
  for (int s = 0; s < static_cast<int>(segs_.size()); ++s)
    for (int j = 0; j < J_; ++j) {
      const int ic = index(s, 0), it = off_theta_ + j;
      const double r =
          inv_unscaled_(ic, it) / std::sqrt(inv_unscaled_(ic, ic) * inv_unscaled_(it, it));
      if (std::isfinite(r)) max_corr = std::max(max_corr, std::abs(r));
    }
  st.condition = cond_;
  st.max_correlation = max_corr;
  st.separable = cond_ <= o_.max_condition && max_corr <= so_.max_correlation;
  st.iterations = iterations_;
  st.rows = total_rows_;
  st.residual_rms = std::sqrt(std::max(rss_, 0.0) / static_cast<double>(total_rows_));
  if (st.separable) return;
  std::ostringstream os;
  os << "damping and STE are not separately identifiable on this record: condition " << cond_
     << " (limit " << o_.max_condition << "), largest damping-STE correlation " << max_corr
     << " (limit " << so_.max_correlation << ")";
  res.warnings.push_back({quality_code::kSteNotSeparable, os.str()});
  for (auto& e : res.segments) e.warnings.push_back({quality_code::kSteNotSeparable, os.str()});
  if (cond_ <= 1e7) return;
  // Numerically rank deficient: no numbers at all.
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
  st.theta_cov.setConstant(kNaN);
}

// The held-STE fit of the one segment: with theta fixed the problem is linear in the segment's
// multipliers (the b column less the theta columns is the target). The covariance is the larger
// of sigma^2 A^-1 and the window-clustered sandwich, plus theta's covariance propagated through
// dC/dtheta = -A^-1 X^T x_theta (the design linearised at the solution).
gear_sim::Status SteFit::solveHeld(const SteResult& ste) {
  const int cb = n_a_ + J_;
  for (int j = 0; j < J_; ++j) a0_[off_theta_ + j] = ste.theta[j];
  Eigen::MatrixXd M;
  std::vector<int> idx;
  designMap(0, true, &M, &idx);
  const Eigen::MatrixXd G = M.transpose() * segs_[0].gram * M;
  Eigen::VectorXd target = Eigen::VectorXd::Zero(cb + 1);  // b - sum_j theta_j x_theta_j
  target[cb] = 1.0;
  for (int j = 0; j < J_; ++j) target[n_a_ + j] = -ste.theta[j];
  const Eigen::MatrixXd A = G.topLeftCorner(n_a_, n_a_);
  const Eigen::VectorXd rhs = G.topRows(n_a_) * target;
  const Eigen::VectorXd d = A.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(d.asDiagonal() * A * d.asDiagonal());
  const Eigen::VectorXd lam = es.eigenvalues();
  cond_ = lam.minCoeff() > 0.0 ? std::sqrt(lam.maxCoeff() / lam.minCoeff())
                               : std::numeric_limits<double>::infinity();
  if (!(cond_ <= 1e7))
    return gear_sim::Status::notIdentifiable("the held-STE fit of the segment is rank deficient");
  const Eigen::MatrixXd Ainv = d.asDiagonal() * es.eigenvectors() *
                               lam.cwiseInverse().asDiagonal() * es.eigenvectors().transpose() *
                               d.asDiagonal();
  const Eigen::VectorXd x = Ainv * rhs;
  rss_ = target.dot(G * target) - 2.0 * x.dot(rhs) + x.dot(A * x);
  iterations_ = 1;
  // Full-size solution and covariance (fillDamping reads them).
  p_ = Eigen::VectorXd::Zero(Pn_);
  for (int a = 0; a < n_a_; ++a) p_[idx[a]] = a0_[idx[a]] = x[a];
  for (int j = 0; j < J_; ++j) p_[off_theta_ + j] = ste.theta[j];
  cov_ = Eigen::MatrixXd::Zero(Pn_, Pn_);
  for (int a = 0; a < n_a_; ++a)
    for (int b = 0; b < n_a_; ++b) cov_(idx[a], idx[b]) = Ainv(a, b);
  unknowns_ = n_a_;
  covariance();  // sigma^2 A^-1 or the sandwich (the theta rows of the meat are unused)
  // Theta's covariance propagated: dx/dtheta at the solution.
  designMap(0, true, &M, &idx);
  const Eigen::MatrixXd G2 = M.transpose() * segs_[0].gram * M;
  const Eigen::MatrixXd dx = -Ainv * G2.block(0, n_a_, n_a_, J_);
  const Eigen::MatrixXd prop = dx * ste.theta_cov * dx.transpose();
  for (int a = 0; a < n_a_; ++a)
    for (int b = 0; b < n_a_; ++b) cov_(idx[a], idx[b]) += prop(a, b);
  theta_var_of_C_ = prop(0, 0);
  if (!prop.allFinite())
    return gear_sim::Status::notIdentifiable(
        "the held-STE fit: the STE covariance propagated into C is not finite");
  return {};
}

// The input checks of identifyWithSte, in order; ok when the record can be used.
gear_sim::Status checkSteInput(const gear_sim::SignalTable& table, const GearConstants& gear,
                               const IdentificationOptions& options, const SteModelOptions& so) {
  using gear_sim::Status;
  if (Status s = options.check(); !s.ok()) return s;
  if (Status s = gear.check(); !s.ok()) return s;
  if (Status s = so.check(); !s.ok()) return s;
  if (Status s = checkSteOptions(options); !s.ok()) return s.withContext("--ste");
  using gear_sim::SignalTable;
  const bool greybox = options.formulation == Formulation::Greybox;
  if (!SignalTable::has(table.mesh_phase))
    return Status::invalidInput(
        "--ste needs the mesh_phase column (the STE is a function of the mesh phase)",
        "mesh_phase");
  if (!SignalTable::has(table.torque))
    return Status::invalidInput("--ste needs the torque column", "torque");
  if (!greybox && !SignalTable::has(table.stiffness))
    return Status::invalidInput("--ste with the known formulation needs the stiffness column",
                                "stiffness");
  if (greybox && !SignalTable::has(table.mesh_state))
    return Status::invalidInput("--ste with the greybox formulation needs the mesh_state column",
                                "mesh_state");
  return checkSignalTable(table, options.formulation, options.model, options.time_tolerance);
}

}  // namespace

gear_sim::Status checkSteOptions(const IdentificationOptions& options) {
  using gear_sim::Status;
  const bool greybox = options.formulation == Formulation::Greybox;
  if (options.formulation != Formulation::Known && !greybox)
    return Status::invalidArgument("only the known and greybox formulations model the STE",
                                   "formulation");
  if (options.model == DampingModel::LoadLaw)
    return Status::invalidArgument(
        "the load_law damping model is not available with the STE (use piecewise or constant)",
        "model");
  if (greybox && options.stiffness_shape.kind != StiffnessShape::Kind::Square)
    return Status::invalidArgument("greybox needs the square stiffness shape", "stiffness_shape");
  return {};
}

Eigen::Index nonFiniteSteInput(const SignalView& view, Formulation formulation) {
  const bool greybox = formulation == Formulation::Greybox;
  for (Eigen::Index i = 0; i < view.n; ++i)
    if (!std::isfinite(view.dte[i]) || !std::isfinite(view.mesh_phase[i]) ||
        !std::isfinite(view.torque[i]) || (!greybox && !std::isfinite(view.stiffness[i])) ||
        (greybox && !std::isfinite(view.mesh_state[i])))
      return i;
  return -1;
}

gear_sim::Status identifySteSegments(const SignalView& view, const SampleRanges& ranges,
                                     const GearConstants& gear,
                                     const IdentificationOptions& options,
                                     const SteModelOptions& so, IdentificationResult* result,
                                     SteResult* ste) {
  SteFit fit(view, gear, options, so);
  if (!fit.addSegments(ranges))
    return gear_sim::Status::notIdentifiable("--ste: no segment with enough samples");
  if (gear_sim::Status s = fit.solve(result); !s.ok()) return s;
  fit.covariance();
  fit.fillDamping(result);
  fit.fillSte(ste, result);
  refineWithSte(view, fit.segmentRanges(), gear, options, fit.basis(), fit.relative(), result, ste);
  return {};
}

gear_sim::Status identifyWithSte(const gear_sim::SignalTable& table, const GearConstants& gear,
                                 const IdentificationOptions& options, const SteModelOptions& so,
                                 IdentificationResult* result, SteResult* ste) {
  using gear_sim::Status;
  if (Status s = checkSteInput(table, gear, options, so); !s.ok()) return s;
  const SignalView view = SignalView::of(table);
  if (const Eigen::Index i = nonFiniteSteInput(view, options.formulation); i >= 0)
    return Status::invalidInput("--ste: non-finite input at sample " + std::to_string(i) +
                                " (the joint STE solve needs a clean record)");
  const auto ranges = segmentRanges(view, options);
  if (ranges.empty()) return Status::notIdentifiable("no samples in the analysed time range");
  return identifySteSegments(view, ranges, gear, options, so, result, ste);
}

namespace {

// The record with the held STE taken out, for the plain output-error model: the deflection
// z = y - e, and the torque less the STE forcing's remainder, from
//   relative: z'' + C z' + K z = F - e''          dte: z'' + C z' + K z = F - e'' - C e'
// e' and e'' with the phase rate of the chord over up to 16 samples on either side within the
// segment (as the joint refinement's e'), the rigid rotation's acceleration neglected.
struct HeldSteRecord {
  std::vector<double> z, torque;
  SignalView view;
  HeldSteRecord(const SignalView& v, Eigen::Index begin, Eigen::Index end,
                const GearConstants& gear, const SteResult& ste, double C) {
    const gear_sim::SteBasis basis = ste.options.basis();
    const int J = basis.size();
    std::vector<double> omega2(J, 0.0), E(J), dE(J);  // -b_j'' / b_j per (mesh cycle)^2
    for (int j = 0; j < J; ++j) {
      std::string kind;
      int order = 0;
      bool sine = false;
      basis.describe(j, &kind, &order, &sine);
      const double per_cycle = kind == "mesh"     ? 1.0
                               : kind == "pinion" ? 1.0 / basis.z1
                               : kind == "gear"   ? 1.0 / basis.z2
                                                  : 0.0;
      omega2[j] = std::pow(2.0 * M_PI * order * per_cycle, 2);
    }
    const bool relative = ste.options.damping == gear_sim::SteDamping::Relative;
    z.assign(v.dte, v.dte + v.n);
    torque.assign(v.torque, v.torque + v.n);
    const double* ph = v.mesh_phase;
    for (Eigen::Index i = 0; i < v.n; ++i) {
      const Eigen::Index b = std::min(begin, i), e = std::max(end, i + 1);
      const Eigen::Index lo = std::max<Eigen::Index>(b, i - 16),
                         hi = std::min<Eigen::Index>(e - 1, i + 17);
      const double rate = hi > lo ? (ph[hi] - ph[lo]) / (static_cast<double>(hi - lo) * v.dt) : 0.0;
      basis.eval(ph[i], E.data(), dE.data());
      double e0 = 0.0, e1 = 0.0, e2 = 0.0;
      for (int j = 0; j < J; ++j) {
        e0 += ste.theta[j] * E[j];
        e1 += ste.theta[j] * dE[j] * rate;
        e2 -= ste.theta[j] * omega2[j] * E[j] * rate * rate;
      }
      z[i] -= e0;
      torque[i] -= (e2 + (relative ? 0.0 : C * e1)) / gear.force_factor;
    }
    view = v;
    view.dte = z.data();
    view.torque = torque.data();
  }
};

}  // namespace

gear_sim::Status identifySegmentWithHeldSte(const SignalView& view, Eigen::Index begin,
                                            Eigen::Index end, const GearConstants& gear,
                                            const IdentificationOptions& options,
                                            const SteResult& ste, IdentificationResult* result) {
  SteFit fit(view, gear, options, ste.options);
  if (!fit.addSegments({{begin, end}}))
    return gear_sim::Status::notIdentifiable("--ste: the segment has too few samples");
  if (gear_sim::Status s = fit.solveHeld(ste); !s.ok()) return s;
  fit.fillDamping(result);
  IdentificationResult& seg = *result;
  seg.estimator = "integral_ste_held";
  IdentificationResult flagged = seg;
  applyQualityFlags(options, &flagged);
  if (!(seg.segments[0].C > 0.0) || !wantsRefinement(options)) {
    seg = std::move(flagged);
    return {};
  }
  // Output error on the record with the held STE taken out; the dte form's C e' term uses the
  // current C, iterated until C moves by less than 1e-3 of its standard error.
  const double prop_var = fit.thetaVarianceOfC();
  IdentificationResult refined = seg;
  double C = seg.segments[0].C;
  const bool relative = ste.options.damping == gear_sim::SteDamping::Relative;
  gear_sim::Status refine;
  for (int pass = 0; pass < (relative ? 1 : 4); ++pass) {
    const HeldSteRecord rec(view, begin, end, gear, ste, C);
    refined = seg;
    refine = refineOutputError(rec.view, {{begin, end}}, gear, options, &refined);
    if (!refine.ok()) break;
    const double moved = std::abs(refined.segments[0].C - C);
    C = refined.segments[0].C;
    if (moved <= 1e-3 * refined.segments[0].C_std) break;
  }
  if (refine.ok()) {
    keepIntegralEstimates(seg, &refined);
    SegmentEstimate& e = refined.segments[0];
    e.C_std = std::sqrt(e.C_std * e.C_std + std::max(prop_var, 0.0));
    seg = std::move(refined);
    seg.estimator = "output_error_ste_held";
  } else {
    seg.warnings.push_back(
        {quality_code::kRefineFailed, "output-error refinement failed (" + refine.message() +
                                          "): integral-method estimates reported"});
  }
  applyQualityFlags(options, &seg);
  return {};
}

}  // namespace gear_damping_id
