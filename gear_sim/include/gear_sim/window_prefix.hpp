// The stiffness prefix of the default integration window (docs/method.md "Default window"): the
// window is two natural periods from the mean of the finite stiffness samples among a record's
// first kWindowPrefixSamples samples. Shared by the identification (gear_damping_id
// defaultWindowLength, a record in memory) and the bag scan (gear_sim_ros scanSignalBag and the
// one-pass read of a streamed bag), which must give the same mean to the bit.
#pragma once

#include <cstddef>
#include <cstdint>

namespace gear_sim {

/// Samples at the start of a record (gaps included: a gap's samples are missing, not finite)
/// whose mean stiffness gives the default window: 2^17, 0.13 s at 1 MHz, so known early in a
/// long record and the same however it is read or chunked. A record of at most this many
/// samples uses all of them.
constexpr std::int64_t kWindowPrefixSamples = std::int64_t{1} << 17;

/// The sum of the finite values added, added one by one in the order given, and their count:
/// the prefix's bits for any reading of the record, whole or in chunks.
struct FiniteSum {
  double sum = 0.0;  // never -0, so adding +0 for a non-finite value leaves it as it is
  long long count = 0;

  /// Adds the finite ones of x[begin, end) (x: a pointer or anything indexable by size_t).
  template <class Array>
  void add(const Array& x, size_t begin, size_t end) {
    double total = sum;
    long long n = 0;
    for (size_t i = begin; i < end; ++i) {
      const double v = x[i];
      const bool finite = v - v == 0.0;
      total += finite ? v : 0.0;
      n += finite ? 1 : 0;
    }
    sum = total;
    count += n;
  }
  /// The mean of the finite values added; 0 when there were none.
  double mean() const { return count > 0 ? sum / static_cast<double>(count) : 0.0; }
};

}  // namespace gear_sim
