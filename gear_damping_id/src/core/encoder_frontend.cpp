// Encoder front end: see encoder_frontend.hpp and docs/rig.md.
#include "gear_damping_id/encoder_frontend.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "gear_damping_id/integral_method.hpp"
#include "gear_sim/models.hpp"

namespace gear_damping_id {

namespace {

constexpr double kNaNd = std::numeric_limits<double>::quiet_NaN();
constexpr double kPhaseNudge = 1e-9;  // [mesh cycles] "holds from this sample on"

std::string num(double v) {
  std::ostringstream s;
  s.precision(6);
  s << v;
  return s.str();
}

// Model-free noise estimate of a smooth signal: RMS third difference / sqrt(20).
double thirdDifferenceNoise(const std::vector<double>& y) {
  if (y.size() < 8) return kNaNd;
  double s = 0.0;
  for (size_t i = 3; i < y.size(); ++i) {
    const double d = y[i] - 3.0 * y[i - 1] + 3.0 * y[i - 2] - y[i - 3];
    s += d * d;
  }
  return std::sqrt(s / static_cast<double>(y.size() - 3) / 20.0);
}

// Sample-weighted mean square of the segments' integral (or, `refined`, output-error) residual
// RMS over the segments that have one; inf when none.
double segmentResidual(const IdentificationResult& r, bool refined) {
  double sum = 0.0;
  long used = 0;
  for (const auto& seg : r.segments) {
    const double rms = refined ? (seg.refined ? seg.residuals.rms : kNaNd)
                               : (seg.identifiable ? seg.residual_rms : kNaNd);
    if (!std::isfinite(rms)) continue;
    sum += rms * rms * static_cast<double>(seg.samples);
    used += seg.samples;
  }
  return used > 0 ? sum / static_cast<double>(used) : std::numeric_limits<double>::infinity();
}
double refinedResidual(const IdentificationResult& r) { return segmentResidual(r, true); }

// Mean squared residual per sample of `table` under `options` (integral equations, or the
// output-error residual when `refined`), over the segments that have one; inf when none.
double meanSquaredResidual(const gear_sim::SignalTable& table, const GearConstants& gear,
                           const IdentificationOptions& options, bool refined) {
  IdentificationResult r;
  if (!identify(table, gear, options, &r).ok()) return std::numeric_limits<double>::infinity();
  return refined ? refinedResidual(r) : segmentResidual(r, false);
}

// The same for the joint damping/STE identification (integral residual, or the output-error
// residual when `refined`).
double meanSquaredResidualSte(const gear_sim::SignalTable& table, const GearConstants& gear,
                              const IdentificationOptions& options, const SteModelOptions& ste,
                              bool refined) {
  IdentificationResult r;
  SteResult s;
  const double inf = std::numeric_limits<double>::infinity();
  if (!identifyWithSte(table, gear, options, ste, &r, &s).ok()) return inf;
  if (!refined) return std::isfinite(s.residual_rms) ? s.residual_rms * s.residual_rms : inf;
  return refinedResidual(r);
}

// Golden-section search for a minimum of f on [a, b] until the bracket is below `tol` or after
// `iterations`; returns the bracket's middle.
template <class F>
double goldenSection(F&& f, double a, double b, double tol, int iterations) {
  const double gr = 0.5 * (std::sqrt(5.0) - 1.0);
  double x1 = b - gr * (b - a), x2 = a + gr * (b - a);
  double f1 = f(x1), f2 = f(x2);
  for (int it = 0; it < iterations && b - a > tol; ++it) {
    if (f1 < f2) {
      b = x2, x2 = x1, f2 = f1, x1 = b - gr * (b - a), f1 = f(x1);
    } else {
      a = x1, x1 = x2, f1 = f2, x2 = a + gr * (b - a), f2 = f(x2);
    }
  }
  return 0.5 * (a + b);
}

}  // namespace

gear_sim::OptionStatus EncoderFrontEndOptions::check() const {
  auto bad = [](const char* field, const auto& value, const char* rule) {
    return gear_sim::violated("EncoderFrontEndOptions", field, value, rule);
  };
  if (!(ratio_tolerance > 0.0 && ratio_tolerance < 1.0))
    return bad("ratio_tolerance", ratio_tolerance, "must be in (0, 1)");
  if (!(reversal_allowance >= 0.0 && std::isfinite(reversal_allowance)))
    return bad("reversal_allowance", reversal_allowance, "must be finite and >= 0");
  if (!(twist_allowance >= 0.0 && std::isfinite(twist_allowance)))
    return bad("twist_allowance", twist_allowance, "must be finite and >= 0");
  if (counts_per_rev1 < 0)
    return bad("counts_per_rev1", counts_per_rev1, "must be >= 0 (0 = not quantised)");
  if (counts_per_rev2 < 0)
    return bad("counts_per_rev2", counts_per_rev2, "must be >= 0 (0 = not quantised)");
  if (!std::isnan(mesh_offset) && !std::isfinite(mesh_offset))
    return bad("mesh_offset", mesh_offset, "must be finite (or unset to estimate)");
  if (!std::isnan(dte_offset) && !std::isfinite(dte_offset))
    return bad("dte_offset", dte_offset, "must be finite (or unset to estimate)");
  if (calibration_samples < 0)
    return bad("calibration_samples", calibration_samples, "must be >= 0");
  return {};
}

DteCoefficients dteCoefficients(const gear_sim::GearPair& gp) {
  const double g = static_cast<double>(gp.pinion.teeth) / gp.gear.teeth;
  const double i1 = gp.pinion.inertia, i2 = gp.gear.inertia;
  const double r1 = gp.pinion.base_radius, r2 = gp.gear.base_radius;
  DteCoefficients c;
  c.w1 = i1 / (i1 + g * g * i2);
  c.w2 = g * i2 / (i1 + g * g * i2);
  const double m = r1 - g * r2;  // rigid-body mismatch of the radii against the teeth
  c.a1 = r1 - m * c.w1;
  c.a2 = -r2 - m * c.w2;
  return c;
}

double quantisationNoiseStd(const gear_sim::GearPair& gears, long counts1, long counts2) {
  const DteCoefficients c = dteCoefficients(gears);
  const double q1 = counts1 > 0 ? 2.0 * M_PI / static_cast<double>(counts1) : 0.0;
  const double q2 = counts2 > 0 ? 2.0 * M_PI / static_cast<double>(counts2) : 0.0;
  return std::sqrt((c.a1 * q1) * (c.a1 * q1) + (c.a2 * q2) * (c.a2 * q2)) / std::sqrt(12.0);
}

EncoderFrontEnd::EncoderFrontEnd(const gear_sim::GearModel& model,
                                 const EncoderFrontEndOptions& options)
    : model_(model), o_(options), coef_(dteCoefficients(model.gears)) {
  report_.ratio_expected = model.gears.ratio();
  report_.quantisation_noise_std =
      quantisationNoiseStd(model.gears, o_.counts_per_rev1, o_.counts_per_rev2);
  report_.resampling = "none (uniform input at the output rate)";
}

gear_sim::Status EncoderFrontEnd::check(const double* th1, const double* th2, size_t n) {
  const double q1 = o_.counts_per_rev1 > 0 ? 2.0 * M_PI / o_.counts_per_rev1 : 0.0;
  const double q2 = o_.counts_per_rev2 > 0 ? 2.0 * M_PI / o_.counts_per_rev2 : 0.0;
  const double g = 1.0 / model_.gears.ratio();
  const double slack1 = o_.reversal_allowance + 2.0 * q1,
               slack2 = o_.reversal_allowance * g + 2.0 * q2;
  auto refuse = [&](const std::string& why) {
    refused_ = true;
    refusal_ = "not a gear-pair record: " + why;
    return gear_sim::Status::invalidInput(refusal_);
  };
  for (size_t i = 0; i < n; ++i) {
    if (!std::isfinite(th1[i]) || !std::isfinite(th2[i]))
      return refuse("theta1/theta2 not finite at sample " + std::to_string(index_.size() + i));
    if (!started_) {
      started_ = true;
      th1_first_ = th1_max_ = th1[i];
      th2_first_ = th2_max_ = th2[i];
    }
    th1_max_ = std::max(th1_max_, th1[i]);
    th2_max_ = std::max(th2_max_, th2[i]);
    if (th1[i] < th1_max_ - slack1)
      return refuse("theta1 runs backwards by " + num(th1_max_ - th1[i]) +
                    " rad (a reversal, or an encoder counting against the rotation: each angle "
                    "must be positive in its own wheel's direction of rotation)");
    if (th2[i] < th2_max_ - slack2)
      return refuse("theta2 runs backwards by " + num(th2_max_ - th2[i]) +
                    " rad (a reversal, or an encoder counting against the rotation: each angle "
                    "must be positive in its own wheel's direction of rotation)");
    // Tooth ratio: the pinion rotation against Z2/Z1 times the gear rotation.
    const double r1 = th1[i] - th1_first_, r2 = th2[i] - th2_first_;
    const double mismatch = r1 - report_.ratio_expected * r2;
    if (std::abs(mismatch) > o_.ratio_tolerance * std::abs(r1) + o_.twist_allowance + 4.0 * q1 +
                                 4.0 * report_.ratio_expected * q2)
      return refuse("the rotations are in the ratio " + num(r1 / r2) + ", not Z2/Z1 = " +
                    num(report_.ratio_expected) + " (tolerance " + num(o_.ratio_tolerance) +
                    "; pinion " + num(r1) + " rad, gear " + num(r2) + " rad)");
    th1_last_ = th1[i];
    th2_last_ = th2[i];
  }
  const double r2 = th2_last_ - th2_first_;
  if (r2 != 0.0) report_.ratio_measured = (th1_last_ - th1_first_) / r2;
  return {};
}

gear_sim::Status EncoderFrontEnd::push(double sample_rate, std::uint64_t first_index,
                                       const double* theta1, const double* theta2,
                                       const double* torque, size_t n) {
  if (refused_) {
    return gear_sim::Status::invalidInput(refusal_);
  }
  if (!(sample_rate > 0.0 && std::isfinite(sample_rate))) {
    return gear_sim::Status::invalidInput("sample rate " + num(sample_rate) +
                                          ": must be finite and > 0");
  }
  if (rate_ == 0.0) rate_ = sample_rate;
  if (sample_rate != rate_) {
    return gear_sim::Status::invalidInput("sample rate changed from " + num(rate_) + " to " +
                                          num(sample_rate) + " Hz");
  }
  const bool have_last = !index_.empty() || has_last_;
  const std::uint64_t last = !index_.empty() ? index_.back() : last_index_;
  if (have_last && first_index <= last) {
    return gear_sim::Status::invalidInput("sample index " + std::to_string(first_index) +
                                          " is not after the last");
  }
  if (gear_sim::Status st = check(theta1, theta2, n); !st.ok()) return st;
  if (index_.empty() && n > 0) has_torque_ = torque != nullptr;
  for (size_t i = 0; i < n; ++i) {
    index_.push_back(first_index + i);
    th1_.push_back(theta1[i]);
    th2_.push_back(theta2[i]);
    torque_.push_back(torque && has_torque_ ? torque[i] : kNaNd);
  }
  report_.sample_rate = rate_;
  if (!calibrated_ && o_.calibration_samples > 0 &&
      index_.size() >= static_cast<size_t>(o_.calibration_samples)) {
    if (gear_sim::Status st = calibrate(); !st.ok()) return st;
  }
  if (calibrated_) convert(converted_, index_.size());
  return {};
}

gear_sim::Status EncoderFrontEnd::finish() {
  if (refused_) {
    return gear_sim::Status::invalidInput(refusal_);
  }
  if (!calibrated_) {
    if (gear_sim::Status st = calibrate(); !st.ok()) return st;
    convert(converted_, index_.size());
  }
  return {};
}

namespace {

// The search for the encoder offsets of EncoderFrontEnd::calibrate (docs/rig.md "Offsets"), one
// named step per member: the mesh phase u0 on a grid, a golden section, the middle of a flat
// plateau, the output-error sub-sample stage; the DTE constant y0 profiled at each u0.
class OffsetSearch {
 public:
  // `t`: time, dte (shifted by its mean), torque of the contiguous run; `u_raw`: its mesh phase
  // without the offset.
  OffsetSearch(gear_sim::SignalTable t, Eigen::VectorXd u_raw, const gear_sim::GearModel& model,
               const EncoderFrontEndOptions& o, bool need_y0)
      : t_(std::move(t)),
        u_raw_(std::move(u_raw)),
        stiff_(model.mesh),
        me_(model.gears.equivalentMass()),
        ff_(model.gears.forceFactor()),
        gear_(gearConstants(model)),
        o_(o),
        need_y0_(need_y0) {
    io_.formulation = Formulation::Known;
    io_.model = DampingModel::Piecewise;
    io_.refine = IdentificationOptions::Refine::Never;
    ste_ = o_.ste;
    ste_.pinion_teeth = model.gears.pinion.teeth;
    ste_.gear_teeth = model.gears.gear.teeth;
  }
  void setSegmentLength(double duration) { io_.segment_length = std::min(1e-3, duration); }
  void setShift(double y_shift) { y_shift_ = y_shift; }

  /// The mesh phase and stiffness at offset u0.
  void fill(double u0) {
    for (Eigen::Index j = 0; j < t_.time.size(); ++j) {
      t_.mesh_phase[j] = u_raw_[j] + u0;
      t_.stiffness[j] = stiff_.at(t_.mesh_phase[j] + kPhaseNudge);
    }
  }
  /// y0 profiled at the current u0 (`*rss_min` the residual there; y0Best() the offset).
  void profileY0(double* rss_min);
  double y0Best() const { return y0_best_; }
  /// The residual at u0 with y0 profiled.
  double objective(double u0) {
    fill(u0);
    double f;
    profileY0(&f);
    return f;
  }
  /// The grid of 40 offsets and a golden section on the best cell's neighbours; false when no
  /// offset gives an identifiable segment.
  bool gridAndGolden(double* u0);
  /// The middle of the objective's plateau around u0 (*lo, *hi its ends).
  double plateauMiddle(double u0, double* lo, double* hi);
  /// The output-error stage on the plateau [lo, hi] widened (returns u0 when it fails).
  double subSample(double u0, double lo, double hi);

 private:
  // Mean force balance: mean(K (y + shift - y0)) = mean(F), in units of the shifted DTE.
  double forceBalanceOffset() const {
    double ky = 0.0, k = 0.0, f = 0.0;
    for (Eigen::Index j = 0; j < t_.time.size(); ++j) {
      ky += t_.stiffness[j] * t_.dte[j];
      k += t_.stiffness[j];
      f += ff_ * me_ * t_.torque[j];
    }
    return (ky - f) / k;
  }
  // Residual of the known integral method (or the joint STE fit) of table c.
  double residual(const gear_sim::SignalTable& c, const IdentificationOptions& opt,
                  bool refined) const {
    return o_.model_ste ? meanSquaredResidualSte(c, gear_, opt, ste_, refined)
                        : meanSquaredResidual(c, gear_, opt, refined);
  }
  double rss(double y0) const {
    gear_sim::SignalTable c = t_;
    c.dte.array() -= y0;
    return residual(c, io_, false);
  }
  double step() const { return std::abs(u_raw_[1] - u_raw_[0]) / 16.0; }  // [mesh cycles]

  gear_sim::SignalTable t_;
  Eigen::VectorXd u_raw_;
  const gear_sim::MeshStiffness stiff_;
  const double me_, ff_;
  const GearConstants gear_;
  const EncoderFrontEndOptions& o_;
  const bool need_y0_;
  IdentificationOptions io_;
  SteModelOptions ste_;
  double y0_best_ = 0.0, y_shift_ = 0.0;
};

// y0 enters the known equations linearly (through int int K y0), so the RSS minimised over the
// other unknowns is a quadratic in y0: three evaluations give its minimum exactly.
void OffsetSearch::profileY0(double* rss_min) {
  const double y_fb = forceBalanceOffset();
  if (!need_y0_ || o_.model_ste) {  // given, or the STE's order-0 term takes the rest
    y0_best_ = need_y0_ ? y_fb : o_.dte_offset - y_shift_;
    *rss_min = rss(y0_best_);
    return;
  }
  const double d = 1e-3 * std::max(1e-12, std::sqrt(t_.dte.squaredNorm() / t_.dte.size()));
  const double fm = rss(y_fb - d), f0 = rss(y_fb), fp = rss(y_fb + d);
  const double curv = fp - 2.0 * f0 + fm;
  double y = y_fb;
  if (curv > 0.0 && std::isfinite(curv)) y = y_fb - 0.5 * d * (fp - fm) / curv;
  y0_best_ = y;
  *rss_min = rss(y);
  if (!(*rss_min <= f0)) y0_best_ = y_fb, *rss_min = f0;
}

bool OffsetSearch::gridAndGolden(double* u0) {
  constexpr int kGrid = 40;
  double best = std::numeric_limits<double>::infinity();
  int best_i = -1;
  std::vector<double> f(kGrid);
  for (int i = 0; i < kGrid; ++i) {
    f[static_cast<size_t>(i)] = objective(static_cast<double>(i) / kGrid);
    if (f[static_cast<size_t>(i)] < best) best = f[static_cast<size_t>(i)], best_i = i;
  }
  if (best_i < 0) return false;
  // Golden section on the neighbouring grid cells.
  auto obj = [this](double u) { return objective(u); };
  *u0 = goldenSection(obj, (best_i - 1.0) / kGrid, (best_i + 1.0) / kGrid, 1e-9, 40);
  return true;
}

// When the switches fall on samples, every offset within a sample's mesh-phase advance gives the
// same quadrature: the objective is flat there and the golden section may stop at an edge of the
// plateau, where a rounding flips a switch to the next sample. Take the middle of the plateau
// (for switches between samples it has zero width: u0 stays).
double OffsetSearch::plateauMiddle(double u0, double* lo_out, double* hi_out) {
  const double f_min = objective(u0);
  const double st = step();
  auto same = [&](double u) {
    const double f = objective(u);
    return std::abs(f - f_min) <= 1e-9 * std::abs(f_min);
  };
  double lo = u0, hi = u0;
  for (int k = 0; k < 40 && st > 0.0 && same(lo - st); ++k) lo -= st;
  for (int k = 0; k < 40 && st > 0.0 && same(hi + st); ++k) hi += st;
  *lo_out = lo;
  *hi_out = hi;
  return 0.5 * (lo + hi);
}

// Sub-sample: the output-error refinement integrates the model with the switch instants of the
// mesh phase, so its residual sees offsets the quadrature cannot. Golden section on it over the
// plateau widened by a step either side (y0 kept from the integral stage).
double OffsetSearch::subSample(double u0, double lo, double hi) {
  fill(u0);
  double f_tmp;
  profileY0(&f_tmp);
  const double y0_keep = y0_best_;
  IdentificationOptions ro = io_;
  ro.refine = IdentificationOptions::Refine::Always;
  auto refined = [&](double u) {
    fill(u);
    gear_sim::SignalTable c = t_;
    c.dte.array() -= y0_keep;
    return residual(c, ro, true);
  };
  // With coarse encoders the integral stage can miss by several samples: the bracket spans at
  // least +-0.01 mesh cycles.
  const double half = std::max(0.5 * (hi - lo) + step(), 0.01);
  const double centre = 0.5 * (lo + hi);
  const double u_ref = goldenSection(refined, centre - half, centre + half, 1e-3 * step(), 40);
  return std::isfinite(refined(u_ref)) ? u_ref : u0;
}

}  // namespace

// The contiguous run from the first sample as a table (time, DTE less its mean, torque; the
// mesh phase without offset in *u_raw); *y_shift the mean taken out; false when a torque is not
// finite.
bool EncoderFrontEnd::calibrationTable(gear_sim::SignalTable* tp, Eigen::VectorXd* u_raw,
                                       double* y_shift) const {
  const size_t n = index_.size();
  size_t m = 1;
  while (m < n && index_[m] == index_[m - 1] + 1) ++m;
  const double z1 = model_.gears.pinion.teeth;
  const double dt = 1.0 / rate_;
  gear_sim::SignalTable& t = *tp;
  t.time.resize(static_cast<Eigen::Index>(m));
  t.dte.resize(t.time.size());
  t.torque.resize(t.time.size());
  t.stiffness.resize(t.time.size());
  t.mesh_phase.resize(t.time.size());
  u_raw->resize(t.time.size());
  bool torque_ok = has_torque_;
  for (size_t i = 0; i < m; ++i) {
    const Eigen::Index j = static_cast<Eigen::Index>(i);
    t.time[j] = static_cast<double>(index_[i]) * dt;
    t.dte[j] = coef_.a1 * th1_[i] + coef_.a2 * th2_[i];
    t.torque[j] = torque_[i];
    if (!std::isfinite(torque_[i])) torque_ok = false;
    (*u_raw)[j] = z1 * (coef_.w1 * th1_[i] + coef_.w2 * th2_[i]) / (2.0 * M_PI);
  }
  // Make the raw DTE small before the sums (the encoder zeros can make it large).
  *y_shift = t.dte.mean();
  t.dte.array() -= *y_shift;
  return torque_ok;
}

gear_sim::Status EncoderFrontEnd::calibrate() {
  const size_t n = index_.size();
  if (n < 16) {
    return gear_sim::Status::invalidInput("too few samples (" + std::to_string(n) +
                                          ") for the encoder front end");
  }
  if (!(std::abs(th1_last_ - th1_first_) > 0.0)) {
    refused_ = true;
    return gear_sim::Status::invalidInput("not a gear-pair record: the shafts do not rotate");
  }
  gear_sim::SignalTable t;
  Eigen::VectorXd u_raw;
  double y_shift = 0.0;
  const bool torque_ok = calibrationTable(&t, &u_raw, &y_shift);
  const bool need_u0 = std::isnan(o_.mesh_offset), need_y0 = std::isnan(o_.dte_offset);
  if ((need_u0 || need_y0) && !torque_ok) {
    return gear_sim::Status::invalidInput(
        "the encoder front end needs a finite torque to estimate the mesh offset and the DTE "
        "offset (or give both)");
  }
  const Eigen::Index m = t.time.size();
  std::vector<double> y(t.dte.data(), t.dte.data() + m);
  OffsetSearch search(std::move(t), std::move(u_raw), model_, o_, need_y0);
  search.setShift(y_shift);
  search.setSegmentLength(static_cast<double>(m) * (1.0 / rate_));  // as dt = 1 / rate
  double u0 = o_.mesh_offset;
  if (need_u0) {
    if (model_.mesh.model == gear_sim::StiffnessModel::Constant) {
      u0 = 0.0;  // no mesh timing to find
    } else {
      if (!search.gridAndGolden(&u0))
        return gear_sim::Status::notIdentifiable(
            "the mesh offset could not be estimated (no identifiable segment); give it",
            "mesh_offset");
      double lo = u0, hi = u0;
      u0 = search.plateauMiddle(u0, &lo, &hi);
      if (o_.refine_offset) u0 = search.subSample(u0, lo, hi);
    }
    report_.mesh_offset_estimated = true;
  }
  double f_final;
  search.fill(u0);
  search.profileY0(&f_final);
  const double y0 = search.y0Best() + y_shift;
  report_.dte_offset_estimated = need_y0;
  report_.dte_offset = y0;
  report_.mesh_offset = u0 - std::floor(u0);
  o_.mesh_offset = u0;
  o_.dte_offset = y0;
  calibrated_ = true;
  report_.noise_std = thirdDifferenceNoise(y);
  return {};
}

void EncoderFrontEnd::convert(size_t begin, size_t end) {
  const double z1 = model_.gears.pinion.teeth, dt = 1.0 / rate_;
  const gear_sim::MeshStiffness stiff(model_.mesh);
  for (size_t i = begin; i < end; ++i) {
    const double u = z1 * (coef_.w1 * th1_[i] + coef_.w2 * th2_[i]) / (2.0 * M_PI) + o_.mesh_offset;
    o_idx_.push_back(index_[i]);
    o_t_.push_back(static_cast<double>(index_[i]) * dt);
    o_dte_.push_back(coef_.a1 * th1_[i] + coef_.a2 * th2_[i] - o_.dte_offset);
    o_torque_.push_back(torque_[i]);
    o_u_.push_back(u);
    o_k_.push_back(stiff.at(u + kPhaseNudge));
    o_s_.push_back(stiff.state(u + kPhaseNudge));
    o_th1_.push_back(th1_[i]);
    o_th2_.push_back(th2_[i]);
  }
  // The raw samples are converted: only the last index stays (the ordering check).
  if (!index_.empty()) last_index_ = index_.back(), has_last_ = true;
  index_.clear(), th1_.clear(), th2_.clear(), torque_.clear();
  converted_ = 0;
}

bool EncoderFrontEnd::pop(gear_sim::SignalTable* out, std::uint64_t* first_index) {
  if (o_idx_.empty()) return false;
  // The leading contiguous run (a gap in the indices ends it).
  size_t m = 1;
  while (m < o_idx_.size() && o_idx_[m] == o_idx_[m - 1] + 1) ++m;
  auto move = [m](std::vector<double>& v, Eigen::VectorXd& col) {
    col = Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(m));
    v.erase(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(m));
  };
  *out = gear_sim::SignalTable{};
  *first_index = o_idx_.front();
  o_idx_.erase(o_idx_.begin(), o_idx_.begin() + static_cast<std::ptrdiff_t>(m));
  move(o_t_, out->time);
  move(o_dte_, out->dte);
  move(o_torque_, out->torque);
  if (!has_torque_) out->torque.resize(0);
  move(o_k_, out->stiffness);
  move(o_s_, out->mesh_state);
  move(o_u_, out->mesh_phase);
  move(o_th1_, out->theta1);
  move(o_th2_, out->theta2);
  report_.samples += static_cast<long>(m);
  return true;
}

gear_sim::Status encoderToSignalTable(const gear_sim::SignalTable& rig,
                                      const gear_sim::GearModel& model,
                                      const EncoderFrontEndOptions& options,
                                      gear_sim::SignalTable* out, EncoderFrontEndReport* report) {
  if (gear_sim::Status s = options.check(); !s.ok()) return s.withContext("encoder front end");
  const Eigen::Index n = rig.size();
  if (n < 16 || rig.theta1.size() != n || rig.theta2.size() != n) {
    return gear_sim::Status::invalidInput(
        "a rig record needs the columns time, theta1, theta2 (16 samples or more)");
  }
  const double dt = (rig.time[n - 1] - rig.time[0]) / static_cast<double>(n - 1);
  for (Eigen::Index i = 1; i < n; ++i)
    if (!(std::abs(rig.time[i] - rig.time[i - 1] - dt) <= 1e-6 * dt)) {
      return gear_sim::Status::invalidInput("time is not uniform at sample " + std::to_string(i) +
                                            " (edge-time records: give the edge files instead)");
    }
  EncoderFrontEndOptions o = options;
  o.calibration_samples = 0;
  EncoderFrontEnd fe(model, o);
  const double fs = 1.0 / dt;
  const auto first = static_cast<std::uint64_t>(std::llround(rig.time[0] * fs));
  if (!(rig.time[0] >= 0.0)) {
    return gear_sim::Status::invalidInput("time must start at or after 0");
  }
  gear_sim::Status s =
      fe.push(fs, first, rig.theta1.data(), rig.theta2.data(),
              rig.torque.size() == n ? rig.torque.data() : nullptr, static_cast<size_t>(n));
  if (s.ok()) s = fe.finish();
  if (!s.ok()) return s;
  std::uint64_t f0 = 0;
  if (!fe.pop(out, &f0)) {
    return gear_sim::Status::invalidInput("the encoder front end produced no samples");
  }
  out->time = rig.time;  // the record's own stamps (identical to index / rate up to rounding)
  if (report) *report = fe.report();
  return {};
}

gear_sim::Status edgeTimesToAngles(const std::vector<double>& edges, long counts_per_rev,
                                   const Eigen::VectorXd& grid, Eigen::VectorXd* theta,
                                   double max_gap_ratio) {
  const size_t m = edges.size();
  if (counts_per_rev <= 0) {
    return gear_sim::Status::invalidInput("counts per revolution must be > 0");
  }
  if (m < 4) {
    return gear_sim::Status::invalidInput("at least 4 edges are needed (got " + std::to_string(m) +
                                          ")");
  }
  for (size_t k = 0; k < m; ++k)
    if (!std::isfinite(edges[k]) || (k > 0 && !(edges[k] > edges[k - 1]))) {
      return gear_sim::Status::invalidInput("edge " + std::to_string(k) +
                                            ": times must be finite and strictly increasing");
    }
  const double mean_gap = (edges[m - 1] - edges[0]) / static_cast<double>(m - 1);
  for (size_t k = 1; k < m; ++k)
    if (edges[k] - edges[k - 1] > max_gap_ratio * mean_gap) {
      return gear_sim::Status::invalidInput(
          "edge " + std::to_string(k) + ": a gap of " + num(edges[k] - edges[k - 1]) + " s, " +
          num((edges[k] - edges[k - 1]) / mean_gap) +
          "x the mean edge interval (a standstill or lost edges)");
    }
  const double q = 2.0 * M_PI / static_cast<double>(counts_per_rev);
  theta->resize(grid.size());
  size_t k = 0;
  for (Eigen::Index i = 0; i < grid.size(); ++i) {
    const double t = grid[i];
    if (!(t >= edges[0] && t <= edges[m - 1])) {
      return gear_sim::Status::invalidInput("grid time " + num(t) +
                                            " s is outside the edge times [" + num(edges[0]) +
                                            ", " + num(edges[m - 1]) + "] s");
    }
    if (i > 0 && t < grid[i - 1]) k = 0;
    while (k + 2 < m && edges[k + 1] <= t) ++k;
    // Four-point stencil k-1 .. k+2 around the interval [e_k, e_k+1], shifted inward at the ends.
    size_t s = k == 0 ? 0 : k - 1;
    if (s + 3 >= m) s = m - 4;
    double v = 0.0;
    for (size_t a = s; a < s + 4; ++a) {
      double l = 1.0;
      for (size_t b = s; b < s + 4; ++b)
        if (b != a) l *= (t - edges[b]) / (edges[a] - edges[b]);
      v += l * q * static_cast<double>(a);
    }
    (*theta)[i] = v;
  }
  return {};
}

gear_sim::Status edgesToRigTable(const std::vector<double>& edges1, long counts1,
                                 const std::vector<double>& edges2, long counts2,
                                 const gear_sim::SignalTable& grid, gear_sim::SignalTable* rig,
                                 std::string* resampling) {
  if (edges1.size() < 4 || edges2.size() < 4) {
    return gear_sim::Status::invalidInput("each edge-time record needs at least 4 edges");
  }
  const double lo = std::max(edges1.front(), edges2.front());
  const double hi = std::min(edges1.back(), edges2.back());
  Eigen::Index b = 0, e = grid.size();
  while (b < e && grid.time[b] < lo) ++b;
  while (e > b && grid.time[e - 1] > hi) --e;
  if (e - b < 16) {
    return gear_sim::Status::invalidInput("the edge times cover [" + num(lo) + ", " + num(hi) +
                                          "] s: fewer than 16 samples of the time grid lie inside");
  }
  *rig = gear_sim::SignalTable{};
  rig->time = grid.time.segment(b, e - b);
  if (grid.torque.size() == grid.size()) rig->torque = grid.torque.segment(b, e - b);
  if (gear_sim::Status s = edgeTimesToAngles(edges1, counts1, rig->time, &rig->theta1); !s.ok())
    return s.withContext("edge times of shaft 1");
  if (gear_sim::Status s = edgeTimesToAngles(edges2, counts2, rig->time, &rig->theta2); !s.ok())
    return s.withContext("edge times of shaft 2");
  if (resampling)
    *resampling = "edge times (" + std::to_string(edges1.size()) + " and " +
                  std::to_string(edges2.size()) + " edges at " + std::to_string(counts1) + " and " +
                  std::to_string(counts2) +
                  " counts/rev) to the time grid by local cubics through four edges";
  return {};
}

gear_sim::Status decimateRig(const gear_sim::SignalTable& in, int factor,
                             gear_sim::SignalTable* out) {
  const Eigen::Index n = in.size();
  if (factor < 1) {
    return gear_sim::Status::invalidInput("decimation factor must be >= 1");
  }
  if (factor == 1) {
    *out = in;
    return {};
  }
  const int half = 16 * factor;  // taps either side
  if (n < 2 * half + factor) {
    return gear_sim::Status::invalidInput("record too short for decimation by " +
                                          std::to_string(factor));
  }
  std::vector<double> h(static_cast<size_t>(2 * half + 1));
  const double fc = 0.4 / factor;  // cutoff [cycles per input sample]
  double sum = 0.0;
  for (int j = -half; j <= half; ++j) {
    const double x = 2.0 * M_PI * fc * j;
    const double sinc = j == 0 ? 2.0 * fc : std::sin(x) / (M_PI * j);
    const double w =
        0.42 + 0.5 * std::cos(M_PI * j / half) + 0.08 * std::cos(2.0 * M_PI * j / half);
    h[static_cast<size_t>(j + half)] = sinc * w;
    sum += sinc * w;
  }
  for (double& v : h) v /= sum;
  std::vector<Eigen::Index> centres;
  for (Eigen::Index c = half; c + half < n; c += factor) centres.push_back(c);
  auto filt = [&](const Eigen::VectorXd& x, Eigen::VectorXd* y) {
    if (x.size() != n) {
      y->resize(0);
      return;
    }
    y->resize(static_cast<Eigen::Index>(centres.size()));
    for (size_t i = 0; i < centres.size(); ++i) {
      // Relative to the centre sample: the filter is linear-phase with unit gain at DC, so the
      // large rotation passes exactly and only the small deviations are filtered.
      const double x0 = x[centres[i]];
      double acc = 0.0;
      for (int j = -half; j <= half; ++j)
        acc += h[static_cast<size_t>(j + half)] * (x[centres[i] + j] - x0);
      (*y)[static_cast<Eigen::Index>(i)] = x0 + acc;
    }
  };
  *out = gear_sim::SignalTable{};
  out->time.resize(static_cast<Eigen::Index>(centres.size()));
  for (size_t i = 0; i < centres.size(); ++i)
    out->time[static_cast<Eigen::Index>(i)] = in.time[centres[i]];
  filt(in.theta1, &out->theta1);
  filt(in.theta2, &out->theta2);
  filt(in.torque, &out->torque);
  return {};
}

}  // namespace gear_damping_id
