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
#include <cmath>
#include <string>
#include <vector>

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
/// Outputs: y_out[n], v_out[n] (v_out may be null). Returns an empty string, or an error naming
/// the invalid argument (non-positive dt or substeps, non-finite initial state, too few samples).
template <class CoeffFn>
std::string integrateSdof(const CoeffFn& coeffs, std::vector<double> breakpoints, double t0,
                          double dt, Eigen::Index n_samples, SdofState initial, Integrator method,
                          int substeps, double* y_out, double* v_out) {
  if (!(dt > 0.0)) return "dt = " + std::to_string(dt) + ": must be > 0 [s]";
  if (substeps < 1) return "substeps = " + std::to_string(substeps) + ": must be >= 1";
  if (n_samples < 1) return "n_samples must be >= 1";
  if (!std::isfinite(initial.y) || !std::isfinite(initial.v)) return "initial state is not finite";
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
