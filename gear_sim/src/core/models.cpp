#include "gear_sim/models.hpp"

#include <algorithm>
#include <cmath>

#include "gear_sim/simd_clones.hpp"

namespace gear_sim {

namespace {

constexpr long kAnchor = 64;  // fourierAnchored's points per exact anchor

// The Fourier series k = k_mean + sum_h (ac[h] cos(2 pi h u) + as[h] sin(2 pi h u)) at the n
// uniform phases u[0], u[0] + du, ... into out, from an exact anchor every kAnchor points rotated
// by the table's exp(2 pi i du j) (table.c/s, j < kAnchor): per point the operations of
// fillPiece's sum() in the same order, the points in the inner loop so that it vectorises (an
// AVX2 clone: wider vectors, no FMA, so the same bits).
GEAR_AVX2_CLONES void fourierAnchored(double k_mean, const double* ac, const double* as, size_t nh,
                                      const double* u, long n, const RotationTable& table,
                                      double* out) {
  const double* rc = table.c;
  const double* rs = table.s;
  double zc[kAnchor], zs[kAnchor], pc[kAnchor], ps[kAnchor], k[kAnchor];
  for (long i0 = 0; i0 < n; i0 += kAnchor) {
    const double f = u[i0] - std::floor(u[i0]);
    const double c0 = std::cos(2.0 * M_PI * f), s0 = std::sin(2.0 * M_PI * f);
    const long m = std::min(n - i0, kAnchor);
    for (long j = 0; j < m; ++j) {
      zc[j] = pc[j] = c0 * rc[j] - s0 * rs[j];
      zs[j] = ps[j] = s0 * rc[j] + c0 * rs[j];
      k[j] = k_mean;
    }
    for (size_t h = 0; h < nh; ++h) {
      const double a = ac[h], b = as[h];
      for (long j = 0; j < m; ++j) {
        k[j] += a * pc[j] + b * ps[j];
        const double qc = pc[j] * zc[j] - ps[j] * zs[j];
        ps[j] = pc[j] * zs[j] + ps[j] * zc[j];
        pc[j] = qc;
      }
    }
    std::copy(k, k + m, out + i0);
  }
}

}  // namespace

// ----------------------------------------------------------------------------- stiffness
MeshStiffness::MeshStiffness(const MeshOptions& o) : o_(o) {
  const double e = o.contact_ratio - 1.0;  // double-contact fraction of the mesh period
  switch (o.model) {
    case StiffnessModel::Square:
      mean_ = o.k_max * e + o.k_min * (1.0 - e);
      breaks_ = {0.0, e};
      piecewise_constant_ = true;
      break;
    case StiffnessModel::Trapezoid: {
      // Linear ramps of width w centred on the square wave's switch instants: same mean.
      const double w = o.transition_fraction;
      mean_ = o.k_max * e + o.k_min * (1.0 - e);
      breaks_ = {0.5 * w, e - 0.5 * w, e + 0.5 * w, 1.0 - 0.5 * w};
      break;
    }
    case StiffnessModel::Fourier:
      mean_ = o.k_mean;
      break;
    case StiffnessModel::Constant:
      mean_ = o.k_mean;
      piecewise_constant_ = true;
      break;
  }
}

double MeshStiffness::at(double u, double u_ref) const {
  const double e = o_.contact_ratio - 1.0;
  switch (o_.model) {
    case StiffnessModel::Square: {
      const double f = u_ref - std::floor(u_ref);
      return f < e ? o_.k_max : o_.k_min;
    }
    case StiffnessModel::Trapezoid: {
      // Continuous, so the piece does not matter: evaluate at u.
      const double w = o_.transition_fraction, dk = o_.k_max - o_.k_min;
      double f = u - std::floor(u);
      if (f >= 1.0 - 0.5 * w) f -= 1.0;  // the ramp up straddles the cycle start
      if (f < 0.5 * w) return o_.k_min + dk * (f + 0.5 * w) / w;
      if (f < e - 0.5 * w) return o_.k_max;
      if (f < e + 0.5 * w) return o_.k_max - dk * (f - (e - 0.5 * w)) / w;
      return o_.k_min;
    }
    case StiffnessModel::Fourier: {
      double k = o_.k_mean;
      const double f = u - std::floor(u);
      for (size_t h = 0; h < o_.fourier_cos.size(); ++h) {
        const double a = 2.0 * M_PI * static_cast<double>(h + 1) * f;
        k += o_.fourier_cos[h] * std::cos(a) + o_.fourier_sin[h] * std::sin(a);
      }
      return k;
    }
    case StiffnessModel::Constant:
      return o_.k_mean;
  }
  return o_.k_mean;
}

bool MeshStiffness::constantOnPiece(double u_ref, double* k) const {
  if (o_.model == StiffnessModel::Fourier) return false;
  if (o_.model == StiffnessModel::Trapezoid) {
    const double e = o_.contact_ratio - 1.0, w = o_.transition_fraction;
    double f = u_ref - std::floor(u_ref);
    if (f >= 1.0 - 0.5 * w) f -= 1.0;
    if (f < 0.5 * w || (f >= e - 0.5 * w && f < e + 0.5 * w)) return false;  // on a ramp
  }
  *k = at(u_ref, u_ref);
  return true;
}

void MeshStiffness::fillPiece(double u_ref, const double* u, long n, double du, double* out) const {
  RotationTable table;
  fillPiece(u_ref, u, n, du, out, &table);
}

void MeshStiffness::fillPiece(double u_ref, const double* u, long n, double du, double* out,
                              RotationTable* table) const {
  switch (o_.model) {
    case StiffnessModel::Square:
    case StiffnessModel::Constant: {
      const double k = at(u_ref, u_ref);
      std::fill(out, out + n, k);
      return;
    }
    case StiffnessModel::Trapezoid: {
      // The piece of u_ref, as in at(): k = k0 + slope * (u - base) on the whole piece.
      const double e = o_.contact_ratio - 1.0, w = o_.transition_fraction;
      const double dk = o_.k_max - o_.k_min;
      double base = std::floor(u_ref), f = u_ref - base;
      if (f >= 1.0 - 0.5 * w) {
        f -= 1.0;
        base += 1.0;
      }
      double k0, slope = 0.0;  // k = k0 + slope * (u - base)
      if (f < 0.5 * w) {
        slope = dk / w;
        k0 = o_.k_min + 0.5 * dk;
      } else if (f < e - 0.5 * w) {
        k0 = o_.k_max;
      } else if (f < e + 0.5 * w) {
        slope = -dk / w;
        k0 = o_.k_max + dk * (e - 0.5 * w) / w;
      } else {
        k0 = o_.k_min;
      }
      if (slope == 0.0) {
        std::fill(out, out + n, k0);
      } else {
        for (long i = 0; i < n; ++i) out[i] = k0 + slope * (u[i] - base);
      }
      return;
    }
    case StiffnessModel::Fourier: {
      const size_t nh = o_.fourier_cos.size();
      const double* ac = o_.fourier_cos.data();
      const double* as = o_.fourier_sin.data();
      // k = k_mean + sum_h Re((a_h - i b_h) z^h), z = exp(2 pi i u).
      auto sum = [&](double zc, double zs) {
        double k = o_.k_mean, pc = zc, ps = zs;
        for (size_t h = 0; h < nh; ++h) {
          k += ac[h] * pc + as[h] * ps;
          const double qc = pc * zc - ps * zs;
          ps = pc * zs + ps * zc;
          pc = qc;
        }
        return k;
      };
      if (du > 0.0 && n > kAnchor) {
        static_assert(kAnchor <= RotationTable::kSize, "the anchor table fits");
        if (!(table->key == du)) {
          for (long j = 0; j < kAnchor; ++j) {
            const double a = 2.0 * M_PI * (du * static_cast<double>(j));
            table->c[j] = std::cos(a);
            table->s[j] = std::sin(a);
          }
          table->key = du;
        }
        fourierAnchored(o_.k_mean, ac, as, nh, u, n, *table, out);
      } else {
        for (long i = 0; i < n; ++i) {
          const double f = u[i] - std::floor(u[i]);
          out[i] = sum(std::cos(2.0 * M_PI * f), std::sin(2.0 * M_PI * f));
        }
      }
      return;
    }
  }
}

// ----------------------------------------------------------------------------- timing
MeshTiming::MeshTiming(const SpeedOptions& s, int pinion_teeth, double initial_phase)
    : u0_(initial_phase),
      z1_(pinion_teeth),
      f0_(s.pinion_rpm / 60.0),
      f1_((s.profile == SpeedProfile::Ramp ? s.end_rpm : s.pinion_rpm) / 60.0),
      t_ramp_(s.profile == SpeedProfile::Ramp ? s.ramp_time : 1.0),
      ramp_(s.profile == SpeedProfile::Ramp) {}

double MeshTiming::rampPhase(double t) const {
  if (t <= t_ramp_) return u0_ + z1_ * (f0_ * t + 0.5 * (f1_ - f0_) / t_ramp_ * t * t);
  return u0_ + z1_ * (0.5 * (f0_ + f1_) * t_ramp_ + f1_ * (t - t_ramp_));
}

double MeshTiming::meshFrequency(double t) const {
  if (!ramp_ || t >= t_ramp_) return z1_ * (ramp_ ? f1_ : f0_);
  return z1_ * (f0_ + (f1_ - f0_) * t / t_ramp_);
}

double MeshTiming::timeOfPhase(double u) const {
  const double r = (u - u0_) / z1_;  // pinion revolutions
  if (!ramp_) return r / f0_;
  const double r_ramp = 0.5 * (f0_ + f1_) * t_ramp_;
  if (r > r_ramp) return t_ramp_ + (r - r_ramp) / f1_;
  // 0.5 a t^2 + f0 t - r = 0, a = (f1 - f0)/T: the root without cancellation.
  const double a = (f1_ - f0_) / t_ramp_;
  return 2.0 * r / (f0_ + std::sqrt(std::max(0.0, f0_ * f0_ + 2.0 * a * r)));
}

// ----------------------------------------------------------------------------- load
LoadTorque::LoadTorque(const LoadOptions& o) : o_(o) {}

double LoadTorque::at(double t) const {
  switch (o_.profile) {
    case LoadProfile::Constant:
      return o_.mean;
    case LoadProfile::Sine:
      return o_.mean + o_.amplitude * std::sin(2.0 * M_PI * o_.frequency * t + o_.phase);
    case LoadProfile::Step:
      return t < o_.step_time ? o_.initial : o_.final_value;
    case LoadProfile::Ramp:
      if (t <= o_.ramp_start) return o_.initial;
      if (t >= o_.ramp_end) return o_.final_value;
      return o_.initial +
             (o_.final_value - o_.initial) * (t - o_.ramp_start) / (o_.ramp_end - o_.ramp_start);
    case LoadProfile::Trapezoid: {
      double tau = std::fmod(t, o_.period);
      if (tau < 0) tau += o_.period;
      const double d = o_.high - o_.low;
      if (tau < o_.rise) return o_.low + d * tau / o_.rise;
      tau -= o_.rise;
      if (tau < o_.hold) return o_.high;
      tau -= o_.hold;
      if (tau < o_.fall) return o_.high - d * tau / o_.fall;
      return o_.low;
    }
    case LoadProfile::Table: {
      const auto& x = o_.times;
      if (t <= x.front()) return o_.values.front();
      if (t >= x.back()) return o_.values.back();
      const size_t i = std::upper_bound(x.begin(), x.end(), t) - x.begin();  // x[i-1] <= t < x[i]
      const double w = (t - x[i - 1]) / (x[i] - x[i - 1]);
      return o_.values[i - 1] + w * (o_.values[i] - o_.values[i - 1]);
    }
  }
  return 0.0;
}

void LoadTorque::fillUniform(double t0, double dt, long n, double* out) const {
  if (o_.profile == LoadProfile::Table && !o_.times.empty()) {
    // at() with a cursor instead of a binary search per point (the times ascend).
    const auto& x = o_.times;
    const auto& v = o_.values;
    // The slope of the current interval is computed once per interval (at() divides per
    // point; the values agree to rounding).
    // Each table interval's points are then filled by a branch-free loop (vectorised) up to
    // the first point at or past its end, found from the times' formula and checked on it.
    auto time = [t0, dt](long i) { return t0 + static_cast<double>(i) * dt; };
    size_t k = 0;  // first table time > t (upper_bound), advanced monotonically
    for (long i = 0; i < n;) {
      const double t = time(i);
      if (t <= x.front()) {
        out[i++] = v.front();
        continue;
      }
      if (t >= x.back()) {
        out[i++] = v.back();
        continue;
      }
      while (k < x.size() && x[k] <= t) ++k;
      const double slope = (v[k] - v[k - 1]) / (x[k] - x[k - 1]);
      const double xk = x[k], base = x[k - 1], v0 = v[k - 1];
      // end: the first index >= i + 1 whose time reaches x[k] (t < x[k] <= x.back() before it).
      const double guess = std::ceil((xk - t0) / dt);
      long end = guess > static_cast<double>(n) ? n : std::max(i + 1, static_cast<long>(guess));
      while (end > i + 1 && time(end - 1) >= xk) --end;
      while (end < n && time(end) < xk) ++end;
      for (long j = i; j < end; ++j) out[j] = v0 + (time(j) - base) * slope;
      i = end;
    }
    return;
  }
  if (o_.profile != LoadProfile::Sine) {
    for (long i = 0; i < n; ++i) out[i] = at(t0 + static_cast<double>(i) * dt);
    return;
  }
  RotationTable table;
  fillUniform(t0, dt, n, out, &table);
}

void LoadTorque::fillUniform(double t0, double dt, long n, double* out,
                             RotationTable* table) const {
  if (o_.profile != LoadProfile::Sine) {
    fillUniform(t0, dt, n, out);
    return;
  }
  // sin(th0 + j w dt) = sin(th0) cos(j w dt) + cos(th0) sin(j w dt): exact sin/cos once per
  // block of kBlock samples and a table of the rotations cos/sin(j w dt), so the samples of a
  // block are independent of each other (no recurrence chain, no accumulated rounding). The
  // table depends on dt only: kept in *table between calls with the same dt.
  constexpr long kBlock = RotationTable::kSize;
  const double w = 2.0 * M_PI * o_.frequency;
  if (!(table->key == w * dt)) {
    for (long j = 0; j < kBlock; ++j) {
      table->c[j] = std::cos(w * dt * j);
      table->s[j] = std::sin(w * dt * j);
    }
    table->key = w * dt;
  }
  const double* rc = table->c;
  const double* rs = table->s;
  for (long i0 = 0; i0 < n; i0 += kBlock) {
    const double th = w * (t0 + i0 * dt) + o_.phase;
    const double c = o_.amplitude * std::cos(th), s = o_.amplitude * std::sin(th);
    const long m = std::min(n - i0, kBlock);
    double* dst = out + i0;
    for (long j = 0; j < m; ++j) dst[j] = o_.mean + (s * rc[j] + c * rs[j]);
  }
}

std::vector<double> LoadTorque::breakpoints(double duration) const {
  std::vector<double> b;
  switch (o_.profile) {
    case LoadProfile::Step:
      b = {o_.step_time};
      break;
    case LoadProfile::Ramp:
      b = {o_.ramp_start, o_.ramp_end};
      break;
    case LoadProfile::Trapezoid:
      for (double c = 0.0; c < duration; c += o_.period)
        for (double d : {0.0, o_.rise, o_.rise + o_.hold, o_.rise + o_.hold + o_.fall})
          b.push_back(c + d);
      break;
    case LoadProfile::Table:
      b = o_.times;
      break;
    default:
      break;
  }
  b.erase(std::remove_if(b.begin(), b.end(), [&](double t) { return !(t > 0.0 && t < duration); }),
          b.end());
  return b;
}

double LoadTorque::mean(double duration) const {
  if (o_.profile == LoadProfile::Constant) return o_.mean;
  if (o_.profile == LoadProfile::Sine) {
    const double w = 2.0 * M_PI * o_.frequency;
    if (w * duration == 0.0) return at(0.0);
    return o_.mean +
           o_.amplitude * (std::cos(o_.phase) - std::cos(w * duration + o_.phase)) / (w * duration);
  }
  // Piecewise linear between breakpoints: the midpoint rule is exact on each piece.
  std::vector<double> pts = breakpoints(duration);
  pts.insert(pts.begin(), 0.0);
  pts.push_back(duration);
  std::sort(pts.begin(), pts.end());
  double integral = 0.0;
  for (size_t i = 0; i + 1 < pts.size(); ++i)
    integral += (pts[i + 1] - pts[i]) * at(0.5 * (pts[i] + pts[i + 1]));
  return integral / duration;
}

// ----------------------------------------------------------------------------- damping
DampingLaw::DampingLaw(const DampingOptions& o, double k_mean, double me, double t1_mean) {
  const double critical = 2.0 * std::sqrt(k_mean * me);  // c = xi * critical
  switch (o.model) {
    case DampingProfile::ConstantRatio:
      pieces_ = {{0.0, o.ratio * critical, 0.0}};
      break;
    case DampingProfile::ConstantCoefficient:
      pieces_ = {{0.0, o.coefficient, 0.0}};
      break;
    case DampingProfile::Piecewise:
      for (size_t i = 0; i < o.times.size(); ++i)
        pieces_.push_back({o.times[i], o.ratios[i] * critical, 0.0});
      break;
    case DampingProfile::LoadDependent: {
      // xi = r (1 + beta (T1/Tm - 1)) = r (1 - beta) + (r beta / Tm) T1
      const double r = o.ratio, beta = o.load_sensitivity;
      pieces_ = {{0.0, critical * r * (1.0 - beta), critical * r * beta / t1_mean}};
      break;
    }
    case DampingProfile::LoadLinear:
      pieces_ = {{0.0, o.c0, o.c1}};
      break;
  }
}

const DampingLaw::Piece& DampingLaw::piece(double t) const {
  auto it = std::upper_bound(pieces_.begin(), pieces_.end(), t,
                             [](double x, const Piece& p) { return x < p.start; });
  return it == pieces_.begin() ? pieces_.front() : *(it - 1);
}

std::vector<double> DampingLaw::breakpoints(double duration) const {
  std::vector<double> b;
  for (const Piece& p : pieces_)
    if (p.start > 0.0 && p.start < duration) b.push_back(p.start);
  return b;
}

}  // namespace gear_sim
