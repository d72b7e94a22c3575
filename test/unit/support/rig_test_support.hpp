// Shared helpers of the rig tests (docs/rig.md, docs/ste.md): simulated encoders and the front
// end's expected offsets.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "gear_damping_id/encoder_frontend.hpp"
#include "gear_sim/encoders.hpp"
#include "id_test_support.hpp"

namespace gear_id_test {

/// Encoders with `counts` per revolution (0: exact angles) and arbitrary zeros.
inline gear_sim::EncoderOptions encoder(long counts, unsigned long seed = 7) {
  gear_sim::EncoderOptions enc;
  enc.enabled = true;
  enc.counts_per_rev1 = enc.counts_per_rev2 = counts;
  enc.zero1 = 1.234;  // arbitrary encoder zeros
  enc.zero2 = -0.567;
  enc.seed = seed;
  return enc;
}

/// The mesh offset the front end must find: the simulated initial phase seen through the encoder
/// zeros (u = Z1 Theta / 2 pi + u0 with Theta the inertia-weighted encoder angle).
inline double expectedMeshOffset(const SimConfig& c, const gear_sim::EncoderOptions& enc) {
  const gear_damping_id::DteCoefficients k = gear_damping_id::dteCoefficients(c.gears);
  const double u = c.mesh.initial_phase -
                   c.gears.pinion.teeth * (k.w1 * enc.zero1 + k.w2 * enc.zero2) / (2 * M_PI);
  return u - std::floor(u);
}

}  // namespace gear_id_test
