#include "gear_damping_id/quadrature.hpp"

namespace gear_damping_id {

namespace {

// integral_0^u of sum_p c[p] v^p and of sum_p c[p] (1 - v) v^p.
double polyArea(const double* c, double u) {
  double s = 0.0, up = u;
  for (int p = 0; p < 4; ++p, up *= u) s += c[p] * up / (p + 1);
  return s;
}

double polyMoment(const double* c, double u) {
  double s = 0.0, up = u;
  for (int p = 0; p < 4; ++p, up *= u) s += c[p] * (up / (p + 1) - up * u / (p + 2));
  return s;
}

}  // namespace

CubicIntervalRule::CubicIntervalRule(int offset) : offset_(offset) {
  // Lagrange basis on the nodes x_m = offset + m, expanded into monomial coefficients.
  for (int k = 0; k < 4; ++k) {
    double c[4] = {1.0, 0.0, 0.0, 0.0};  // running product, degree grows by one per factor
    double denom = 1.0;
    const double xk = offset + k;
    for (int m = 0; m < 4; ++m) {
      if (m == k) continue;
      const double xm = offset + m;
      denom *= xk - xm;
      // multiply c by (u - xm)
      for (int p = 3; p >= 1; --p) c[p] = c[p - 1] - xm * c[p];
      c[0] = -xm * c[0];
    }
    for (int p = 0; p < 4; ++p) coef_[k][p] = c[p] / denom;
  }
  full_area_ = area(0.0, 1.0);
  full_moment_ = moment(0.0, 1.0);
}

CubicIntervalRule::Weights CubicIntervalRule::area(double u0, double u1) const {
  Weights w;
  for (int k = 0; k < 4; ++k) w[k] = polyArea(coef_[k], u1) - polyArea(coef_[k], u0);
  return w;
}

CubicIntervalRule::Weights CubicIntervalRule::moment(double u0, double u1) const {
  Weights w;
  for (int k = 0; k < 4; ++k) w[k] = polyMoment(coef_[k], u1) - polyMoment(coef_[k], u0);
  return w;
}

CubicIntervalRule::Weights CubicIntervalRule::value(double u) const {
  Weights w;
  for (int k = 0; k < 4; ++k) {
    w[k] = coef_[k][0] + u * (coef_[k][1] + u * (coef_[k][2] + u * coef_[k][3]));
  }
  return w;
}

}  // namespace gear_damping_id
