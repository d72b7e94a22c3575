// Explicit Runge-Kutta integration of the normalised single-degree-of-freedom equation (paper
// eq. 4)
//
//     y'' + C(t) y' + K(t) y = F(t)
//
// with coefficients that are smooth between known breakpoint instants and may jump at them
// (mesh-stiffness switches, load steps, damping segment boundaries). Stepping across a jump with
// an explicit RK method loses its order, so the driver splits every step exactly at each
// breakpoint. Header-only; no ROS; SI units.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "gear_sim/status.hpp"

namespace gear_sim {

enum class Integrator {
  Rk2,  ///< explicit midpoint rule, order 2 (the paper's "second-order Runge-Kutta")
  Rk4   ///< classical fourth-order Runge-Kutta (default)
};

/// Coefficients of eq. (4) at one instant: C [1/s], K [1/s^2], F [m/s^2].
struct SdofCoefficients {
  double C = 0.0;
  double K = 0.0;
  double F = 0.0;
};

/// State (y [m], y' [m/s]).
struct SdofState {
  double y = 0.0;
  double v = 0.0;
};

/// One RK4 step of length h from `s`, given the coefficients at the start (c0), the midpoint
/// (cm) and the end (c1) of the step, all taken from the same smooth piece (no jump inside).
inline SdofState rk4Step(const SdofState& s, double h, const SdofCoefficients& c0,
                         const SdofCoefficients& cm, const SdofCoefficients& c1) {
  const double a1 = c0.F - c0.C * s.v - c0.K * s.y;
  const double y2 = s.y + 0.5 * h * s.v, v2 = s.v + 0.5 * h * a1;
  const double a2 = cm.F - cm.C * v2 - cm.K * y2;
  const double y3 = s.y + 0.5 * h * v2, v3 = s.v + 0.5 * h * a2;
  const double a3 = cm.F - cm.C * v3 - cm.K * y3;
  const double y4 = s.y + h * v3, v4 = s.v + h * a3;
  const double a4 = c1.F - c1.C * v4 - c1.K * y4;
  return {s.y + h / 6.0 * (s.v + 2.0 * v2 + 2.0 * v3 + v4),
          s.v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)};
}

/// One explicit-midpoint (RK2) step: coefficients at the start (c0) and midpoint (cm).
inline SdofState rk2Step(const SdofState& s, double h, const SdofCoefficients& c0,
                         const SdofCoefficients& cm) {
  const double a1 = c0.F - c0.C * s.v - c0.K * s.y;
  const double ym = s.y + 0.5 * h * s.v, vm = s.v + 0.5 * h * a1;
  const double am = cm.F - cm.C * vm - cm.K * ym;
  return {s.y + h * vm, s.v + h * am};
}

/// Calls `step(a, e, t_ref)` for each piece [a, e] of the interval [t_begin, t_end] divided
/// into `substeps` equal steps, each split at the breakpoints strictly inside it; t_ref is the
/// piece's midpoint (so a coefficient lookup at t_ref finds the piece being integrated).
/// `bp` is the caller's cursor into sorted breakpoints (advanced past those <= the current
/// step start); `bp_end` their end.
template <class It, class StepFn>
void forEachStep(double t_begin, double t_end, int substeps, It& bp, It bp_end, StepFn&& step) {
  const double h_nominal = (t_end - t_begin) / substeps;
  for (int m = 0; m < substeps; ++m) {
    double a = t_begin + m * h_nominal;
    const double b = (m + 1 == substeps) ? t_end : a + h_nominal;
    while (bp != bp_end && *bp <= a) ++bp;
    while (true) {
      const bool split = bp != bp_end && *bp < b;
      const double e = split ? *bp : b;
      if (e > a) step(a, e, a + 0.5 * (e - a));
      if (!split) break;
      a = e;
      ++bp;
    }
  }
}

/// Advances the state `s` of eq. (4) from t_begin to t_end (see forEachStep for the stepping
/// and integrateSdof for the meaning of `coeffs`).
template <class It, class CoeffFn>
SdofState advanceSdof(const CoeffFn& coeffs, SdofState s, double t_begin, double t_end,
                      int substeps, It& bp, It bp_end, Integrator method) {
  forEachStep(t_begin, t_end, substeps, bp, bp_end, [&](double a, double e, double mid) {
    if (method == Integrator::Rk4) {
      s = rk4Step(s, e - a, coeffs(a, mid), coeffs(mid, mid), coeffs(e, mid));
    } else {
      s = rk2Step(s, e - a, coeffs(a, mid), coeffs(mid, mid));
    }
  });
  return s;
}

/// The argument checks of integrateSdof and integrateSdofAffine: ok, or InvalidArgument naming
/// the argument as Status::field().
inline Status checkSdofArguments(double dt, Eigen::Index n_samples, SdofState initial,
                                 int substeps) {
  if (!(dt > 0.0))
    return Status::invalidArgument("dt = " + std::to_string(dt) + ": must be > 0 [s]", "dt");
  if (substeps < 1)
    return Status::invalidArgument("substeps = " + std::to_string(substeps) + ": must be >= 1",
                                   "substeps");
  if (n_samples < 1) return Status::invalidArgument("n_samples must be >= 1", "n_samples");
  if (!std::isfinite(initial.y) || !std::isfinite(initial.v))
    return Status::invalidArgument("initial state is not finite", "initial");
  return {};
}

/// One RK4 step of eq. (4) as the affine map s' = M s + g of the state (M, g independent of it).
struct AffineStep {
  double m11 = 1, m12 = 0, m21 = 0, m22 = 1, g1 = 0, g2 = 0;
};

/// The homogeneous part (m11, m12, m21, m22) of rk4AffineScaled into *s: it depends on the
/// damping and stiffness stages only (held over many steps between stiffness switches).
inline void rk4AffineHomogeneous(double h, double inv_h, double a, double b, double c, double k0,
                                 double km, double k1, AffineStep* s) {
  constexpr double k3 = 1.0 / 3.0, k6 = 1.0 / 6.0, k12 = 1.0 / 12.0, k24 = 1.0 / 24.0;
  s->m11 = 1.0 - km * k3 + k0 * (km * k24 - k6) + b * (k0 * k12 + km * k12 - b * k0 * k24);
  s->m12 = h * (1.0 - km * k6 + b * (b * k12 + km * k24 - k3) +
                a * (b * (k12 - b * k24) + km * k24 - k6));
  s->m21 =
      inv_h *
      (b * (b * (c * k0 * k24 - k0 * k12) - c * km * k12 + k0 * (k6 - k1 * k24) + km * k6) +
       c * (km * k6 - k0 * km * k24) + k0 * (km * k12 - k6) + k1 * (km * k12 - k6) - 2.0 * km * k3);
  s->m22 = 1.0 - km * k3 +
           a * (b * (b * (c * k24 - k12) - k1 * k24 + k6) - c * km * k24 + km * k12 - k6) +
           b * (b * (k6 - c * k12) + c * (k6 - km * k24) + k1 * k12 + km * k12 - 2.0 * k3) +
           c * (km * k12 - k6) + k1 * (km * k24 - k6);
}

/// The forcing part (g1, g2) of rk4AffineScaled into *s.
inline void rk4AffineForcing(double inv_h, double b, double c, double k1, double km, double f0,
                             double fm, double f1, AffineStep* s) {
  constexpr double k3 = 1.0 / 3.0, k6 = 1.0 / 6.0, k12 = 1.0 / 12.0, k24 = 1.0 / 24.0;
  s->g1 = fm * k3 + f0 * (k6 - km * k24) + b * (b * f0 * k24 - f0 * k12 - fm * k12);
  s->g2 =
      inv_h * (b * (b * (f0 * k12 - c * f0 * k24) + c * fm * k12 + f0 * (k1 * k24 - k6) - fm * k6) +
               c * (f0 * km * k24 - fm * k6) + f0 * (k6 - km * k12) + f1 * k6 - fm * k1 * k12 +
               2.0 * fm * k3);
}

/// Closed form of rk4Step as an affine map (derived symbolically from rk4Step in the scaled
/// variables V = h v, a = h C, k = h^2 K, f = h^2 F; Horner form), from the scaled stage values
/// at the step's start (a, k0, f0), midpoint (b, km, fm) and end (c, k1, f1). Straight-line code:
/// called in a loop over arrays it pipelines and vectorises.
inline AffineStep rk4AffineScaled(double h, double inv_h, double a, double b, double c, double k0,
                                  double km, double k1, double f0, double fm, double f1) {
  AffineStep s;
  rk4AffineHomogeneous(h, inv_h, a, b, c, k0, km, k1, &s);
  rk4AffineForcing(inv_h, b, c, k1, km, f0, fm, f1, &s);
  return s;
}

/// `next` applied after `prev`: the map of the two steps.
inline AffineStep composeAffine(const AffineStep& next, const AffineStep& p) {
  AffineStep a;
  a.m11 = next.m11 * p.m11 + next.m12 * p.m21;
  a.m12 = next.m11 * p.m12 + next.m12 * p.m22;
  a.m21 = next.m21 * p.m11 + next.m22 * p.m21;
  a.m22 = next.m21 * p.m12 + next.m22 * p.m22;
  a.g1 = next.m11 * p.g1 + next.m12 * p.g2 + next.g1;
  a.g2 = next.m21 * p.g1 + next.m22 * p.g2 + next.g2;
  return a;
}

/// The affine map of one step of `method` with the stage coefficients c0 (start), cm (midpoint)
/// and c1 (end; unused by RK2): RK4 in closed form, RK2 by applying rk2Step to the basis states
/// and to the zero state.
inline AffineStep affineOfStep(Integrator method, double h, double inv_h,
                               const SdofCoefficients& c0, const SdofCoefficients& cm,
                               const SdofCoefficients& c1) {
  if (method == Integrator::Rk4) {
    const double h2 = h * h;
    return rk4AffineScaled(h, inv_h, h * c0.C, h * cm.C, h * c1.C, h2 * c0.K, h2 * cm.K, h2 * c1.K,
                           h2 * c0.F, h2 * cm.F, h2 * c1.F);
  }
  const SdofCoefficients u0{c0.C, c0.K, 0.0}, um{cm.C, cm.K, 0.0};
  const SdofState e1 = rk2Step({1.0, 0.0}, h, u0, um), e2 = rk2Step({0.0, 1.0}, h, u0, um);
  const SdofState g = rk2Step({0.0, 0.0}, h, c0, cm);
  return {e1.y, e2.y, e1.v, e2.v, g.y, g.v};
}

/// integrateSdof computed with per-interval affine maps, with the same steps and stages: for
/// every output interval [t_n, t_n+1] without a breakpoint inside, `stages(n, n + 1, split, c, k,
/// f, 1)` (split[0] == 0) fills the coefficients at t_n + q dt / (2 substeps), q = 0..2 substeps,
/// into c[q] (C), k[q] (K) and f[q] (F); the interval's steps become one affine map, applied at
/// once (a 2x2 multiply-add). The homogeneous part of an RK4 step is reused while its damping and
/// stiffness stages are the same, bit for bit, as the previous interval's (between stiffness
/// switches), so a held stretch costs the forcing part and the multiply-add per sample. Intervals
/// with a breakpoint inside take advanceSdof with `coeffs`. With the stages equal to `coeffs` at
/// those instants, the results equal integrateSdof's to rounding. Same arguments, outputs and
/// errors otherwise. (The stages callback takes a range [n0, n1) and a split mask so a caller may
/// serve blocks; this driver asks for one interval at a time, so nothing is buffered.)
template <class CoeffFn, class StagesFn>
Status integrateSdofAffineBlocks(const CoeffFn& coeffs, const StagesFn& stages,
                                 std::vector<double> breakpoints, double t0, double dt,
                                 Eigen::Index n_samples, SdofState initial, Integrator method,
                                 int substeps, double* y_out, double* v_out) {
  if (Status e = checkSdofArguments(dt, n_samples, initial, substeps); !e.ok()) return e;
  std::sort(breakpoints.begin(), breakpoints.end());
  const auto bp_end = breakpoints.cend();
  auto bp = breakpoints.cbegin();    // the stepping cursor (advanceSdof's)
  auto scan = breakpoints.cbegin();  // first breakpoint > the interval's start
  const double h = dt / substeps, inv_h = 1.0 / h, h2 = h * h;
  constexpr int kInline = 4;  // stages held on the stack up to 4 substeps (9 stages)
  const size_t n_stages = static_cast<size_t>(2 * substeps + 1);
  std::array<double, 3 * (2 * kInline + 1)> local{};
  std::vector<double> heap(substeps > kInline ? 3 * n_stages : 0);
  double* sc = substeps > kInline ? heap.data() : local.data();
  double *sk = sc + n_stages, *sf = sk + n_stages;
  // The previous RK4 step's scaled damping and stiffness stages (a, b, c, k0, km, k1) and its
  // homogeneous part, per substep (on the stack for one substep, the common case).
  std::array<double, 6> key1{};
  AffineStep hom1;
  std::vector<std::array<double, 6>> keys(static_cast<size_t>(substeps > 1 ? substeps : 0));
  std::vector<AffineStep> homs(keys.size());
  std::vector<char> haves(keys.size(), 0);
  bool have1 = false;
  const char no_split = 0;
  SdofState s = initial;
  y_out[0] = s.y;
  if (v_out) v_out[0] = s.v;
  for (Eigen::Index n = 0; n + 1 < n_samples; ++n) {
    const double ta = t0 + n * dt, tb = t0 + (n + 1) * dt;
    while (scan != bp_end && *scan <= ta) ++scan;
    if (scan != bp_end && *scan < tb) {
      s = advanceSdof(coeffs, s, ta, tb, substeps, bp, bp_end, method);
    } else {
      stages(n, n + 1, &no_split, sc, sk, sf, size_t{1});
      AffineStep map;
      // forEachStep's substeps of [t_n, t_n+1], of the nominal length h (forEachStep's differ
      // from it by rounding).
      for (int m = 0; m < substeps; ++m) {
        const size_t k0 = static_cast<size_t>(2 * m), km = k0 + 1, k1 = km + 1;
        AffineStep one;
        if (method == Integrator::Rk4) {  // affineOfStep's RK4 case
          const std::array<double, 6> now{h * sc[k0],  h * sc[km],  h * sc[k1],
                                          h2 * sk[k0], h2 * sk[km], h2 * sk[k1]};
          std::array<double, 6>& key = substeps == 1 ? key1 : keys[static_cast<size_t>(m)];
          AffineStep& hom = substeps == 1 ? hom1 : homs[static_cast<size_t>(m)];
          char have = substeps == 1 ? have1 : haves[static_cast<size_t>(m)];
          if (!have || std::memcmp(now.data(), key.data(), sizeof(now)) != 0) {
            rk4AffineHomogeneous(h, inv_h, now[0], now[1], now[2], now[3], now[4], now[5], &hom);
            key = now;
            if (substeps == 1)
              have1 = true;
            else
              haves[static_cast<size_t>(m)] = 1;
          }
          one = hom;
          rk4AffineForcing(inv_h, now[1], now[2], now[5], now[4], h2 * sf[k0], h2 * sf[km],
                           h2 * sf[k1], &one);
        } else {
          one = affineOfStep(method, h, inv_h, {sc[k0], sk[k0], sf[k0]}, {sc[km], sk[km], sf[km]},
                             {sc[k1], sk[k1], sf[k1]});
        }
        map = m == 0 ? one : composeAffine(one, map);
      }
      s = {map.m11 * s.y + map.m12 * s.v + map.g1, map.m21 * s.y + map.m22 * s.v + map.g2};
    }
    y_out[n + 1] = s.y;
    if (v_out) v_out[n + 1] = s.v;
  }
  return {};
}

/// integrateSdofAffineBlocks with one look-up per stage: `stage(n, q)` returns the coefficients
/// at t_n + q dt / (2 substeps), q = 0..2 substeps (called for ascending n: 2 substeps + 1
/// look-ups instead of 3 per substep).
template <class CoeffFn, class StageFn>
Status integrateSdofAffine(const CoeffFn& coeffs, const StageFn& stage,
                           std::vector<double> breakpoints, double t0, double dt,
                           Eigen::Index n_samples, SdofState initial, Integrator method,
                           int substeps, double* y_out, double* v_out) {
  const size_t n_stages = static_cast<size_t>(2 * substeps + 1);
  auto stages = [&](Eigen::Index n0, Eigen::Index n1, const char* split, double* c, double* k,
                    double* f, size_t stride) {
    for (Eigen::Index n = n0; n < n1; ++n) {
      const size_t i = static_cast<size_t>(n - n0);
      if (split[i]) continue;
      for (size_t q = 0; q < n_stages; ++q) {
        const SdofCoefficients v = stage(n, static_cast<int>(q));
        c[q * stride + i] = v.C;
        k[q * stride + i] = v.K;
        f[q * stride + i] = v.F;
      }
    }
  };
  return integrateSdofAffineBlocks(coeffs, stages, std::move(breakpoints), t0, dt, n_samples,
                                   initial, method, substeps, y_out, v_out);
}

/// Integrates eq. (4) on the uniform output grid t_n = t0 + n*dt, n = 0..n_samples-1, from
/// the state `initial` at t0.
///
/// `coeffs(t, t_ref)` must return the coefficients at time t of the smooth piece that contains
/// t_ref: the driver always passes a t_ref strictly inside the (sub)step being taken, so at a
/// breakpoint the value of the interval being integrated is used (the left limit at a step's end,
/// the right limit at its start). `breakpoints` are the instants where a coefficient may jump
/// or lose smoothness, in any order; those outside (t0, t_last) are ignored. Each output interval
/// is divided into `substeps` equal steps and every step is split at the breakpoints it contains.
///
/// Outputs: y_out[n], v_out[n] (v_out may be null). Returns ok, or InvalidArgument naming the
/// invalid argument (non-positive dt or substeps, non-finite initial state, too few samples).
template <class CoeffFn>
Status integrateSdof(const CoeffFn& coeffs, std::vector<double> breakpoints, double t0, double dt,
                     Eigen::Index n_samples, SdofState initial, Integrator method, int substeps,
                     double* y_out, double* v_out) {
  if (Status e = checkSdofArguments(dt, n_samples, initial, substeps); !e.ok()) return e;
  std::sort(breakpoints.begin(), breakpoints.end());
  auto bp = breakpoints.cbegin();
  SdofState s = initial;
  y_out[0] = s.y;
  if (v_out) v_out[0] = s.v;
  for (Eigen::Index n = 0; n + 1 < n_samples; ++n) {
    s = advanceSdof(coeffs, s, t0 + n * dt, t0 + (n + 1) * dt, substeps, bp, breakpoints.cend(),
                    method);
    y_out[n + 1] = s.y;
    if (v_out) v_out[n + 1] = s.v;
  }
  return {};
}

}  // namespace gear_sim
