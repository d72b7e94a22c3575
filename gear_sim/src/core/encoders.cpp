// Simulated shaft encoders: see encoders.hpp and docs/rig.md.
#include "gear_sim/encoders.hpp"

#include <cmath>
#include <random>

#include "gear_sim/message_text.hpp"
#include "gear_sim/models.hpp"

namespace gear_sim {

namespace {

// Twist shares: theta1 = Theta + b1 y, theta2 = g Theta + b2 y.
void twistShares(const GearPair& gp, double* g, double* b1, double* b2) {
  *g = static_cast<double>(gp.pinion.teeth) / gp.gear.teeth;
  const double i1 = gp.pinion.inertia, i2 = gp.gear.inertia;
  const double d = *g * i2 * gp.pinion.base_radius + i1 * gp.gear.base_radius;
  *b1 = *g * i2 / d;
  *b2 = -i1 / d;
}

double quantise(double theta, long counts) {
  if (counts <= 0) return theta;
  const double q = 2.0 * M_PI / static_cast<double>(counts);
  return q * std::floor(theta / q);
}

}  // namespace

OptionStatus EncoderOptions::check() const {
  auto bad = [](const char* key, auto value, const char* rule) {
    return violated("EncoderOptions", key, value, rule);
  };
  if (counts_per_rev1 < 0)
    return bad("counts_per_rev1", counts_per_rev1, "must be >= 0 (0 = exact angles)");
  if (counts_per_rev2 < 0)
    return bad("counts_per_rev2", counts_per_rev2, "must be >= 0 (0 = exact angles)");
  if (!std::isfinite(zero1)) return bad("zero1", zero1, "must be finite [rad]");
  if (!std::isfinite(zero2)) return bad("zero2", zero2, "must be finite [rad]");
  if (!(torque_noise >= 0.0 && std::isfinite(torque_noise)))
    return bad("torque_noise", torque_noise, "must be finite and >= 0 [N*m]");
  if (!(edge_clock >= 0.0 && std::isfinite(edge_clock)))
    return bad("edge_clock", edge_clock, "must be finite and >= 0 [Hz] (0 = exact)");
  return {};
}

void encoderAngles(const SimConfig& c, const EncoderOptions& enc, const SignalTable& sim,
                   Eigen::VectorXd* theta1, Eigen::VectorXd* theta2) {
  double g, b1, b2;
  twistShares(c.gears, &g, &b1, &b2);
  const MeshTiming timing(c.speed, c.gears.pinion.teeth, c.mesh.initial_phase);
  const double u_start = timing.phase(0.0), z1 = c.gears.pinion.teeth;
  const Eigen::Index n = sim.size();
  theta1->resize(n);
  theta2->resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double rigid = 2.0 * M_PI * (timing.phase(sim.time[i]) - u_start) / z1;
    (*theta1)[i] = quantise(enc.zero1 + rigid + b1 * sim.dte[i], enc.counts_per_rev1);
    (*theta2)[i] = quantise(enc.zero2 + g * rigid + b2 * sim.dte[i], enc.counts_per_rev2);
  }
}

SignalTable rigRecord(const SimConfig& c, const EncoderOptions& enc, const SignalTable& sim) {
  SignalTable r;
  r.time = sim.time;
  encoderAngles(c, enc, sim, &r.theta1, &r.theta2);
  r.torque = sim.torque;
  if (enc.torque_noise > 0.0) {
    std::mt19937_64 rng(enc.seed);
    std::normal_distribution<double> nd(0.0, enc.torque_noise);
    for (Eigen::Index i = 0; i < r.torque.size(); ++i) r.torque[i] += nd(rng);
  }
  return r;
}

std::vector<double> encoderEdges(const SimConfig& c, const EncoderOptions& enc,
                                 const SignalTable& sim, int shaft, long counts) {
  std::vector<double> edges;
  const Eigen::Index n = sim.size();
  if (n < 2 || counts <= 0 || sim.dte_velocity.size() != n) return edges;
  double g, b1, b2;
  twistShares(c.gears, &g, &b1, &b2);
  const double ratio = shaft == 1 ? 1.0 : g, b = shaft == 1 ? b1 : b2;
  const double zero = shaft == 1 ? enc.zero1 : enc.zero2;
  const MeshTiming timing(c.speed, c.gears.pinion.teeth, c.mesh.initial_phase);
  const double u_start = timing.phase(0.0), z1 = c.gears.pinion.teeth;
  const double h = (sim.time[n - 1] - sim.time[0]) / static_cast<double>(n - 1);
  const double t0 = sim.time[0];
  // y and y' at t by cubic Hermite interpolation of the samples (fourth order).
  auto yAt = [&](double t, double* dy) {
    Eigen::Index i = static_cast<Eigen::Index>(std::floor((t - t0) / h));
    i = std::max<Eigen::Index>(0, std::min(n - 2, i));
    const double s = (t - sim.time[i]) / h, s2 = s * s, s3 = s2 * s;
    const double y0 = sim.dte[i], y1 = sim.dte[i + 1];
    const double v0 = sim.dte_velocity[i] * h, v1 = sim.dte_velocity[i + 1] * h;
    *dy = ((6 * s2 - 6 * s) * y0 + (3 * s2 - 4 * s + 1) * v0 + (-6 * s2 + 6 * s) * y1 +
           (3 * s2 - 2 * s) * v1) /
          h;
    return (2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * v0 + (-2 * s3 + 3 * s2) * y1 +
           (s3 - s2) * v1;
  };
  auto theta = [&](double t, double* rate) {
    double dy;
    const double y = yAt(t, &dy);
    *rate = ratio * 2.0 * M_PI * timing.meshFrequency(t) / z1 + b * dy;
    return zero + ratio * 2.0 * M_PI * (timing.phase(t) - u_start) / z1 + b * y;
  };
  const double q = 2.0 * M_PI / static_cast<double>(counts);
  double rate;
  const double th_first = theta(sim.time[0], &rate), th_last = theta(sim.time[n - 1], &rate);
  for (double k = std::ceil(th_first / q); k * q <= th_last; k += 1.0) {
    const double target = k * q;
    // Start from the rigid rotation, then Newton on the full angle.
    const double u = u_start + (target - zero) / ratio * z1 / (2.0 * M_PI);
    double t = u >= u_start ? timing.timeOfPhase(u) : sim.time[0];
    for (int it = 0; it < 6; ++it) {
      const double f = theta(t, &rate) - target;
      t -= f / rate;
    }
    t = std::min(std::max(t, sim.time[0]), sim.time[n - 1]);
    if (enc.edge_clock > 0.0) t = std::round(t * enc.edge_clock) / enc.edge_clock;
    if (edges.empty() || t > edges.back()) edges.push_back(t);
  }
  return edges;
}

}  // namespace gear_sim
