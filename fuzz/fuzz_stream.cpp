// libFuzzer target: the chunk sequencing of the live nodes (StreamAssembler) on arbitrary chunk
// sequences: first indices (small steps, jumps, restarts, values near 2^64), lengths, sample
// rates (including NaN, Inf, 0, negative, huge), channel sets, and sample values (raw bit
// patterns: NaN, Inf, 1e308). The input is a little program: an options header, then one
// operation per step (push a chunk, end of stream, reset). Every emitted segment must be
// self-consistent; the assembler must never throw.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "gear_damping_id/stream_assembler.hpp"

namespace {

class Reader {
 public:
  Reader(const std::uint8_t* d, size_t n) : d_(d), n_(n) {}
  bool empty() const { return i_ >= n_; }
  std::uint8_t byte() { return i_ < n_ ? d_[i_++] : 0; }
  std::uint64_t u64() {
    std::uint64_t v = 0;
    for (int k = 0; k < 8; ++k) v = (v << 8) | byte();
    return v;
  }
  double raw() {
    const std::uint64_t b = u64();
    double x;
    std::memcpy(&x, &b, sizeof x);
    return x;
  }

 private:
  const std::uint8_t* d_;
  size_t n_, i_ = 0;
};

const double kInf = std::numeric_limits<double>::infinity();
const double kNaN = std::numeric_limits<double>::quiet_NaN();

double pickRate(Reader& r) {
  static const double rates[] = {1e6,  1e6,   1e6,    5e5, 1e6 * (1 + 1e-12), 0.0, -1e6, kNaN,
                                 kInf, 1e300, 1e-300, 4.0};
  const std::uint8_t b = r.byte();
  return b < 240 ? rates[b % 12] : r.raw();
}

double pickValue(Reader& r, std::uint8_t mode) {
  switch (mode % 8) {
    case 0:
      return r.raw();
    case 1:
      return kNaN;
    case 2:
      return 1e308;
    case 3:
      return static_cast<double>(r.byte() & 1);
    default:
      return 1e-6 * static_cast<double>(static_cast<std::int8_t>(r.byte()));
  }
}

void check(bool condition) {
  if (!condition) std::abort();
}

void drain(gear_damping_id::StreamAssembler& a) {
  gear_damping_id::StreamSegment s;
  while (a.nextSegment(&s)) {
    const Eigen::Index n = static_cast<Eigen::Index>(s.dte.size());
    check(0 <= s.begin && s.begin <= s.end && s.end <= n);
    for (const auto* c : {&s.stiffness, &s.torque, &s.mesh_state, &s.mesh_phase})
      check(c->empty() || c->size() == s.dte.size());
    check(s.sample_rate > 0.0 && std::isfinite(s.sample_rate));
    (void)s.view();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  Reader r(data, size);
  gear_damping_id::StreamOptions o;
  static const double lengths[] = {1e-3, 1e-4, 0.0, kInf, 3e-6, 1e-2, 2.5e-4, 1.0};
  o.segment_length = lengths[r.byte() % 8];
  o.reorder_chunks = r.byte() % 17;
  const std::uint8_t range = r.byte();
  if (range & 1) o.t_start = 1e-6 * static_cast<double>(r.byte()) * 10.0;
  if (range & 2) o.t_end = o.t_start + 1e-6 * static_cast<double>(1 + r.byte()) * 40.0;
  if (!o.check().message().empty()) return 0;
  gear_damping_id::StreamAssembler a(o);
  std::uint64_t next = 0;
  std::vector<double> ch[5];
  std::string detail;
  int ops = 0;
  while (!r.empty() && ops++ < 512) {
    const std::uint8_t op = r.byte();
    if (op < 8) {
      a.endOfStream();
    } else if (op < 10) {
      a.reset();
      next = 0;
    } else {
      gear_damping_id::ChunkData c;
      // Where the chunk starts: in sequence, a small step back or ahead, a restart or raw.
      const std::uint8_t where = r.byte();
      if (where < 160)
        c.first_index = next;
      else if (where < 200)
        c.first_index = next - std::min<std::uint64_t>(next, r.byte());
      else if (where < 230)
        c.first_index = next + r.byte() * (where & 7 ? 1 : 1000);
      else if (where < 240)
        c.first_index = 0;
      else
        c.first_index = r.u64();
      c.sample_rate = pickRate(r);
      c.n = static_cast<size_t>(r.byte()) * ((op & 1) ? 4 : 1);
      const std::uint8_t mask = r.byte(), value_mode = r.byte();
      for (int k = 0; k < 5; ++k) {
        ch[k].assign(c.n, 0.0);
        const bool exotic = (value_mode >> 4) == k;  // one channel gets the odd values
        for (size_t i = 0; i < c.n; ++i)
          ch[k][i] = exotic ? pickValue(r, value_mode) : 1e-6 * static_cast<double>(i % 7);
      }
      c.dte = (mask & 32) ? nullptr : ch[0].data();
      c.stiffness = (mask & 1) ? ch[1].data() : nullptr;
      c.torque = (mask & 2) ? ch[2].data() : nullptr;
      c.mesh_state = (mask & 4) ? ch[3].data() : nullptr;
      c.mesh_phase = (mask & 8) ? ch[4].data() : nullptr;
      a.push(c, &detail);  // huge rates with an analysed range: refused (regression test)
      if (c.first_index + c.n > c.first_index) next = c.first_index + c.n;
    }
    drain(a);
  }
  a.endOfStream();
  drain(a);
  return 0;
}
