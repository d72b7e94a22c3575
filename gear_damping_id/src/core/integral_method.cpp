#include "gear_damping_id/integral_method.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <atomic>
#include <cassert>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <thread>

#include "gear_damping_id/damping_units.hpp"
#include "gear_damping_id/forward_model.hpp"
#include "gear_damping_id/output_error.hpp"
#include "gear_damping_id/quality_flags.hpp"
#include "gear_sim/models.hpp"
#include "gear_sim/simd_clones.hpp"
#include "gear_sim/window_prefix.hpp"

// Hot loops compiled for AVX2 as well as the baseline, chosen at load time. GEAR_AVX2_CLONES
// (gear_sim/simd_clones.hpp): without FMA contraction or reassociation both clones compute the
// same bits (each loop's accumulators are independent lanes, summed in the same order by either).
// GEAR_FMA_CLONES (the row scans and the projected Gram): x86-64-v3 (AVX2 + FMA, contracted
// multiply-adds; on AVX-512 processors the x86-64-v4 clone of the same code, the same bits) or
// the baseline; the clones agree to rounding, not in every bit
// (docs/method.md §5, numeric contract), and on one machine every run takes the same clone, so
// any thread count gives the same bits.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define GD_ALWAYS_INLINE __attribute__((always_inline))
#else
#define GD_ALWAYS_INLINE
#endif

namespace gear_damping_id {

// ----------------------------------------------------------------------------------------------
// Inputs

namespace {

// The sums of nch <= 4 channels x[c][lo, hi) in one loop, each with eight accumulators
// (independent add chains keep the adder pipelines full; a non-finite term makes the sum
// non-finite) reduced in a fixed order, the same for every channel count: the channels stream
// from memory together (several independent miss streams at once) instead of one after another.
typedef double SumV __attribute__((vector_size(32)));  // four lanes of the eight accumulators

// Samples i .. i + 7 of every channel into its accumulators a[c] (lanes 0-3 and 4-7 of the eight,
// per channel: explicit vectors keep them in registers for several channels at once).
template <int NCH>
GD_ALWAYS_INLINE inline void addEight(const double* const* x, Eigen::Index i, SumV (*a)[2]) {
  for (int c = 0; c < NCH; ++c) {
    SumV v0, v1;
    std::memcpy(&v0, x[c] + i, sizeof v0);
    std::memcpy(&v1, x[c] + i + 4, sizeof v1);
    a[c][0] += v0;
    a[c][1] += v1;
  }
}

// channelSums from sample i on, with the accumulators a over the samples before it: the rest in
// steps of eight, the last ones into accumulator 0, then each channel's eight reduced in a fixed
// order into out[c].
template <int NCH>
GD_ALWAYS_INLINE inline void finishSums(const double* const* x, Eigen::Index i, Eigen::Index hi,
                                        SumV (*a)[2], double* out) {
  for (; i + 8 <= hi; i += 8) addEight<NCH>(x, i, a);
  for (int c = 0; c < NCH; ++c) {
    double t[8];
    std::memcpy(t, &a[c][0], sizeof(SumV));
    std::memcpy(t + 4, &a[c][1], sizeof(SumV));
    for (Eigen::Index j = i; j < hi; ++j) t[0] += x[c][j];
    out[c] = ((t[0] + t[1]) + (t[2] + t[3])) + ((t[4] + t[5]) + (t[6] + t[7]));
  }
}

template <int NCH>
GD_ALWAYS_INLINE inline void channelSumsOf(const double* const* x, Eigen::Index lo, Eigen::Index hi,
                                           double* out) {
  SumV a[NCH][2];
  for (int c = 0; c < NCH; ++c) a[c][0] = a[c][1] = SumV{0.0, 0.0, 0.0, 0.0};
  finishSums<NCH>(x, lo, hi, a, out);
}

GEAR_AVX2_CLONES
void channelSums(const double* const* x, int nch, Eigen::Index lo, Eigen::Index hi, double* out) {
  switch (nch) {
    case 1:
      return channelSumsOf<1>(x, lo, hi, out);
    case 2:
      return channelSumsOf<2>(x, lo, hi, out);
    case 3:
      return channelSumsOf<3>(x, lo, hi, out);
    default:
      return channelSumsOf<4>(x, lo, hi, out);
  }
}

// A segment's first read (IntegralMethod::checkFiniteInputs): channelSums of the nch channels x
// and, in the same loop over blocks of 16 samples, what is computed from the samples next: the
// DTE's (x[0]) third differences, squared and summed in segmentLevels' four accumulators and
// order (d3: its accumulators over the groups of four before *end - lo), and the search of the
// channel x[held] (held < 0: none) for blocks of 16 intervals where the value changes
// (heldChangesAfter; the starts of those go to *flagged, and the samples of `phase` around them,
// which the switch location reads next, are prefetched). *end: where the fused loop stopped
// (lo plus a multiple of 16); the sums are complete, in channelSums' accumulators and order.
// The loads of the sums bring the samples in from memory; the other work fills the time spent
// waiting for them. AVX2 + FMA clone (segmentLevels' contraction of the third differences).
template <int NCH>
GD_ALWAYS_INLINE inline void firstTouchOf(const double* const* x, int held, const double* phase,
                                          Eigen::Index lo, Eigen::Index hi, double* out, double* d3,
                                          Eigen::Index* end, std::vector<long>* flagged) {
  SumV a[NCH][2];
  for (int c = 0; c < NCH; ++c) a[c][0] = a[c][1] = SumV{0.0, 0.0, 0.0, 0.0};
  SumV dd = {0.0, 0.0, 0.0, 0.0};
  const double* y = x[0];
  const double* k = held >= 0 ? x[held] : nullptr;
  Eigen::Index i = lo;
  for (; i + 32 <= hi; i += 16) {
    addEight<NCH>(x, i, a);
    addEight<NCH>(x, i + 8, a);
    for (int g = 0; g < 16; g += 4) {
      SumV y0, y1, y2, y3;
      std::memcpy(&y0, y + i + g, sizeof(SumV));
      std::memcpy(&y1, y + i + g + 1, sizeof(SumV));
      std::memcpy(&y2, y + i + g + 2, sizeof(SumV));
      std::memcpy(&y3, y + i + g + 3, sizeof(SumV));
      const SumV d = y3 - 3.0 * y2 + 3.0 * y1 - y0;
      dd += d * d;
    }
    if (k != nullptr && changesIn16(k + i)) {
      flagged->push_back(i);
      if (phase != nullptr) {  // (a hint only: phase[i .. i + 16])
        __builtin_prefetch(phase + i, 0, 3);
        __builtin_prefetch(phase + i + 8, 0, 3);
        __builtin_prefetch(phase + i + 16, 0, 3);
      }
    }
  }
  *end = i;
  std::memcpy(d3, &dd, sizeof dd);
  finishSums<NCH>(x, i, hi, a, out);
}

GEAR_FMA_CLONES
void firstTouch(const double* const* x, int nch, int held, const double* phase, Eigen::Index lo,
                Eigen::Index hi, double* out, double* d3, Eigen::Index* end,
                std::vector<long>* flagged) {
  switch (nch) {
    case 1:
      return firstTouchOf<1>(x, held, phase, lo, hi, out, d3, end, flagged);
    case 2:
      return firstTouchOf<2>(x, held, phase, lo, hi, out, d3, end, flagged);
    case 3:
      return firstTouchOf<3>(x, held, phase, lo, hi, out, d3, end, flagged);
    default:
      return firstTouchOf<4>(x, held, phase, lo, hi, out, d3, end, flagged);
  }
}

// Sum of x[lo, hi): channelSums of one channel.
double blockSum(const double* x, Eigen::Index lo, Eigen::Index hi) {
  double sum = 0.0;
  channelSums(&x, 1, lo, hi, &sum);
  return sum;
}

// A share of the default window's prefix sum (defaultWindowLength: the finite values of
// k[lo, hi), one by one in order, into *sum) done by stepsAndSum between its step checks: the
// sum is a chain of dependent additions, bound by their latency, which the step checks'
// independent work and memory reads hide.
struct PrefixShare {
  const double* k = nullptr;
  Eigen::Index lo = 0, hi = 0;
  gear_sim::FiniteSum* sum = nullptr;
  // The values of the part'th of `parts` near-equal parts of [lo, hi), in order.
  GD_ALWAYS_INLINE void add(Eigen::Index part, Eigen::Index parts) const {
    const Eigen::Index n = hi - lo;
    sum->add(k, static_cast<size_t>(lo + n * part / parts),
             static_cast<size_t>(lo + n * (part + 1) / parts));
  }
};

// checkRecord's work on one block [lo, hi) of the record: the first step i in [max(lo, 1), hi)
// not within tol of ref (hi when there is none) and, when that is hi and k is given, *sum = the
// block's sum of k (blockSum's accumulators and order, so its bits). In chunks of 512 samples,
// the steps of a chunk checked (blocks of 64 branch-free, vectorised; then one by one from the
// block that failed), then its stiffness summed: both columns stream from memory together
// instead of one pass each. share (may be nullptr): its values added in order, an eighth of
// them after each block of 64 steps of the chunk (the rest after the chunk).
GEAR_AVX2_CLONES
Eigen::Index stepsAndSum(const double* tt, const double* k, Eigen::Index lo, Eigen::Index hi,
                         double ref, double tol, double* sum, const PrefixShare* share) {
  constexpr Eigen::Index kChunk = 512;
  double a[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  const Eigen::Index chunks = (hi - lo + kChunk - 1) / kChunk;
  for (Eigen::Index c0 = lo; c0 < hi; c0 += kChunk) {
    const Eigen::Index c1 = std::min(hi, c0 + kChunk);
    const Eigen::Index chunk = (c0 - lo) / kChunk;
    Eigen::Index i = std::max<Eigen::Index>(c0, 1);
    int part = 0;
    for (; i + 64 <= c1; i += 64) {
      long good = 0;  // an integer count vectorises (a bool reduction does not)
      for (int j = 0; j < 64; ++j) good += std::abs(tt[i + j] - tt[i + j - 1] - ref) <= tol;
      if (good != 64) break;
      if (share != nullptr) share->add(chunk * 8 + part++, chunks * 8);
    }
    if (share != nullptr) {
      for (; part < 8; ++part) share->add(chunk * 8 + part, chunks * 8);
    }
    for (; i < c1; ++i) {
      if (!(std::abs(tt[i] - tt[i - 1] - ref) <= tol)) return i;
    }
    if (k == nullptr) continue;
    Eigen::Index j = c0;
    for (; j + 8 <= c1; j += 8) {
      for (int c = 0; c < 8; ++c) a[c] += k[j + c];
    }
    for (; j < c1; ++j) a[0] += k[j];
  }
  *sum = ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7]));
  return hi;
}

// Whole-record passes go in blocks of this many samples; a whole-record sum is the sum of the
// block sums in block order, whatever the number of threads.
constexpr Eigen::Index kRecordBlock = 8192;

// The sum of x[0, n) in that order.
double recordSum(const double* x, Eigen::Index n) {
  double total = 0.0;
  for (Eigen::Index lo = 0; lo < n; lo += kRecordBlock)
    total += blockSum(x, lo, std::min(n, lo + kRecordBlock));
  return total;
}

// checkSignalTable's checks of everything but the individual time steps; *ref receives the
// reference step and *tol the tolerance of a step against it (rel_tolerance of it, widened to
// the stamps' rounding: gear_sim::stepTolerance).
gear_sim::Status checkColumns(const gear_sim::SignalTable& t, Formulation f, DampingModel m,
                              double rel_tolerance, double* ref, double* tol) {
  std::ostringstream e;
  const Eigen::Index n = t.size();
  if (n < 2)
    return gear_sim::Status::invalidInput("the record has " + std::to_string(n) +
                                          " samples: need at least 2");
  if (t.dte.size() != n)
    return gear_sim::Status::invalidInput("column 'dte' is missing or has the wrong length", "dte");
  if (gear_sim::Status missing = checkChannels(ChannelSet::of(t), f, m); !missing.ok())
    return missing;
  auto length = [&](const Eigen::VectorXd& c, const char* name) {
    if (c.size() == 0 || c.size() == n) return true;
    e << "column '" << name << "' has " << c.size() << " values for " << n << " time stamps";
    return false;
  };
  // Every column the analysis may read (SignalView), needed or not: a present column of another
  // length would be read past its end (the default window sums any stiffness column).
  if (!length(t.stiffness, "stiffness"))
    return gear_sim::Status::invalidInput(e.str(), "stiffness");
  if (!length(t.mesh_state, "mesh_state"))
    return gear_sim::Status::invalidInput(e.str(), "mesh_state");
  if (!length(t.torque, "torque")) return gear_sim::Status::invalidInput(e.str(), "torque");
  if (!length(t.mesh_phase, "mesh_phase"))
    return gear_sim::Status::invalidInput(e.str(), "mesh_phase");
  const double dt = (t.time[n - 1] - t.time[0]) / static_cast<double>(n - 1);
  if (!(dt > 0.0) || !std::isfinite(dt))
    return gear_sim::Status::invalidInput("time is not increasing", "time");
  const double t_abs_max = std::max(std::abs(t.time[0]), std::abs(t.time[n - 1]));
  if (gear_sim::Status s = gear_sim::checkTimeResolution(t_abs_max, dt); !s.ok()) return s;
  // Reference step: the median of the first three steps (a record whose very first step is the
  // odd one is then reported there, not at every later step).
  *ref = t.time[1] - t.time[0];
  if (n >= 4) {
    double d[3] = {t.time[1] - t.time[0], t.time[2] - t.time[1], t.time[3] - t.time[2]};
    std::sort(d, d + 3);
    *ref = d[1];
  }
  *tol = gear_sim::stepTolerance(rel_tolerance, *ref, t_abs_max);
  return {};
}

// The error for the non-uniform step i.
gear_sim::Status badStep(const gear_sim::SignalTable& t, Eigen::Index i, double ref,
                         double rel_tolerance, Eigen::Index first_line) {
  std::ostringstream e;
  const double d = t.time[i] - t.time[i - 1];
  e << "time is not uniformly sampled at ";
  if (first_line >= 0)
    e << "line " << first_line + i << " (sample " << i << ", ";
  else
    e << "sample " << i << " (";
  e << "t = " << t.time[i] << " s): step " << d << " s differs from the sampling step " << ref
    << " s by more than the tolerance " << rel_tolerance << " (relative)"
    << (d > ref ? ": a gap or a dropped sample" : "");
  return gear_sim::Status::invalidInput(e.str(), "time");
}

// Default window from the sum of the finite stiffness samples and their count.
double windowFromStiffness(double total, double count, const GearConstants& gear) {
  const double kbar = count > 0.0 && total > 0.0 ? total / count : gear.mean_stiffness;
  const double omega0 = std::sqrt(kbar / gear.equivalent_mass);
  return 2.0 * 2.0 * M_PI / omega0;
}

}  // namespace

gear_sim::Status checkSignalTable(const gear_sim::SignalTable& t, Formulation f, DampingModel m,
                                  double rel_tolerance, Eigen::Index first_line) {
  double ref = 0.0, tol = 0.0;
  if (gear_sim::Status s = checkColumns(t, f, m, rel_tolerance, &ref, &tol); !s.ok()) return s;
  const Eigen::Index n = t.size();
  double unused = 0.0;
  const Eigen::Index i = stepsAndSum(t.time.data(), nullptr, 0, n, ref, tol, &unused, nullptr);
  return i < n ? badStep(t, i, ref, rel_tolerance, first_line) : gear_sim::Status();
}

gear_sim::Status checkRecord(const gear_sim::SignalTable& t, const GearConstants& gear,
                             const IdentificationOptions& o, int threads, double* window_length) {
  double ref = 0.0, tol = 0.0;
  if (gear_sim::Status s = checkColumns(t, o.formulation, o.model, o.time_tolerance, &ref, &tol);
      !s.ok())
    return s;
  const SignalView view = SignalView::of(t);
  const Eigen::Index n = t.size();
  // (a record longer than the window's prefix: its prefix is summed apart, share_prefix below)
  const double* k =
      o.window_length > 0.0 || n > gear_sim::kWindowPrefixSamples ? nullptr : view.stiffness;
  const Eigen::Index blocks = (n + kRecordBlock - 1) / kRecordBlock;
  std::vector<double> sums(static_cast<size_t>(blocks), 0.0);
  std::vector<Eigen::Index> bad(static_cast<size_t>(blocks), n);
  // A longer record's default window: its prefix summed by the calling thread during its steps
  // (defaultWindowLength's sum, the same additions in the same order).
  gear_sim::FiniteSum prefix;
  const bool share_prefix = !(o.window_length > 0.0) && k == nullptr && view.stiffness != nullptr;
  // Blocks claimed in order by the threads (a thread that starts late or shares its core does
  // fewer); a thread stops at its first bad step, and no block after a known bad one is started.
  const Eigen::Index parts = std::max<Eigen::Index>(1, std::min<Eigen::Index>(threads, blocks));
  std::atomic<Eigen::Index> next{0}, first_bad{blocks};
  // The calling thread's prefix in `shares` near-equal parts, one during each block it checks
  // (its expected number of blocks), the rest after them.
  const Eigen::Index shares = (blocks + parts - 1) / parts, p = gear_sim::kWindowPrefixSamples;
  auto run = [&](bool with_prefix) {
    Eigen::Index done = 0;
    for (Eigen::Index b = next++; b < blocks && b < first_bad.load(); b = next++) {
      const Eigen::Index lo = b * kRecordBlock, hi = std::min(n, lo + kRecordBlock);
      double sum = 0.0;
      const bool with_share = with_prefix && done < shares;
      const PrefixShare share{view.stiffness, p * done / shares, p * (done + 1) / shares, &prefix};
      const Eigen::Index i =
          stepsAndSum(t.time.data(), k, lo, hi, ref, tol, &sum, with_share ? &share : nullptr);
      if (i < hi) {
        bad[static_cast<size_t>(b)] = i;
        for (Eigen::Index f = first_bad.load(); b < f && !first_bad.compare_exchange_weak(f, b);) {
        }
        return;
      }
      if (k != nullptr) sums[static_cast<size_t>(b)] = sum;
      done += with_share ? 1 : 0;
    }
    if (with_prefix && done < shares)
      prefix.add(view.stiffness, static_cast<size_t>(p * done / shares), static_cast<size_t>(p));
  };
  std::vector<std::thread> pool;
  for (Eigen::Index w = 1; w < parts; ++w) pool.emplace_back(run, false);
  run(share_prefix);
  for (auto& th : pool) th.join();
  for (const Eigen::Index i : bad) {
    if (i < n) return badStep(t, i, ref, o.time_tolerance, -1);
  }
  if (o.window_length > 0.0) {
    *window_length = o.window_length;
  } else if (share_prefix) {
    *window_length = windowFromStiffness(prefix.sum, static_cast<double>(prefix.count), gear);
  } else if (k == nullptr) {
    *window_length = defaultWindowLength(view, gear);
  } else {
    double total = 0.0;
    for (const double v : sums) total += v;
    // (recordSum's order, so this equals defaultWindowLength, which handles non-finite samples)
    *window_length = std::isfinite(total) ? windowFromStiffness(total, static_cast<double>(n), gear)
                                          : defaultWindowLength(view, gear);
  }
  return {};
}

std::vector<std::pair<Eigen::Index, Eigen::Index>> segmentRanges(const SignalView& s,
                                                                 const IdentificationOptions& o) {
  std::vector<std::pair<Eigen::Index, Eigen::Index>> out;
  if (s.n < 1 || !(s.dt > 0.0)) return out;
  // Samples with t in [t_start, t_end] (inclusive within a thousandth of a step).
  const double eps = 1e-3;
  const double ta = std::max(o.t_start, s.t0);
  const double tb = std::min(o.t_end, s.time(s.n - 1));
  // (clamped as doubles: a range far beyond a record of tiny steps is no integer overflow)
  const double n_d = static_cast<double>(s.n);
  const auto first =
      static_cast<Eigen::Index>(std::clamp(std::ceil((ta - s.t0) / s.dt - eps), -1.0, n_d));
  const auto last = static_cast<Eigen::Index>(
      std::clamp(std::floor((tb - s.t0) / s.dt + eps), -1.0, n_d));  // incl.
  const Eigen::Index lo = std::max<Eigen::Index>(0, first);
  const Eigen::Index hi = std::min<Eigen::Index>(s.n, last + 1);
  if (hi <= lo) return out;
  const bool whole = !(o.segment_length > 0.0) || !std::isfinite(o.segment_length);
  if (whole) {
    out.emplace_back(lo, hi);
    return out;
  }
  const double t_first = s.time(lo);
  // Boundary indices are clamped to [0, hi] as doubles before the conversion: a segment of
  // 1e297 sample steps (a time step of 1e-300 s) ends at the record's end, not at an
  // out-of-range integer.
  const double hi_d = static_cast<double>(hi);
  auto boundary = [&](double t) {
    return std::clamp(std::ceil((t - s.t0) / s.dt - eps), 0.0, hi_d);
  };
  for (long i = 0;; ++i) {
    const double seg_t = t_first + static_cast<double>(i) * o.segment_length;
    const auto b = static_cast<Eigen::Index>(boundary(seg_t));
    if (b >= hi) break;
    const auto e = static_cast<Eigen::Index>(boundary(seg_t + o.segment_length));
    if (e <= b) break;
    out.emplace_back(b, e);
  }
  // A final partial segment shorter than half a segment joins the previous one.
  if (out.size() >= 2) {
    const double full = o.segment_length / s.dt;
    const auto& tail = out.back();
    if (static_cast<double>(tail.second - tail.first) < 0.5 * full) {
      const Eigen::Index e = tail.second;
      out.pop_back();
      out.back().second = e;
    }
  }
  return out;
}

double defaultWindowLength(const SignalView& s, const GearConstants& gear) {
  if (s.stiffness == nullptr || s.n <= 0) return windowFromStiffness(0.0, 0.0, gear);
  if (s.n > gear_sim::kWindowPrefixSamples) {
    // A long record: its prefix, summed in order as a bag's scan sums it (the same bits).
    gear_sim::FiniteSum prefix;
    prefix.add(s.stiffness, 0, static_cast<size_t>(gear_sim::kWindowPrefixSamples));
    return windowFromStiffness(prefix.sum, static_cast<double>(prefix.count), gear);
  }
  // Mean over the finite samples: one vectorised sum when all are finite (the usual case; in
  // checkRecord's block order), else an element-wise pass that skips the non-finite ones.
  double total = recordSum(s.stiffness, s.n), count = static_cast<double>(s.n);
  if (!std::isfinite(total)) {
    const Eigen::Map<const Eigen::ArrayXd> k(s.stiffness, s.n);
    const auto finite = k.abs() <= std::numeric_limits<double>::max();
    total = finite.select(k, 0.0).sum();
    count = static_cast<double>(finite.count());
  }
  return windowFromStiffness(total, count, gear);
}

// ----------------------------------------------------------------------------------------------
// Small dense solves

namespace {

// Noise and signal levels of a segment's DTE y[0, n) (sum: its sum): the noise standard
// deviation from the RMS of the third differences (for white noise their variance is 20 sigma^2;
// the smooth dynamics contribute (omega0 dt)^3 of the amplitude, negligible at the sampling rates
// the method needs), and the standard deviation about the mean.
// Four independent accumulators per sum (a single add chain per sum is latency-bound; the sums
// agree with the sequential ones to ~1e-16 relative). The third differences' accumulators start
// from d3_in, their sums over the groups of four before sample `from` (a multiple of 4: the
// segment's first read computes those, firstTouch). AVX2 + FMA clone.
GEAR_FMA_CLONES
void segmentLevels(const double* y, Eigen::Index n, double sum, const double* d3_in,
                   Eigen::Index from, double* noise, double* signal) {
  if (n < 4) return;
  // Lane k of the vectors is accumulator k (a GCC vector: one AVX register, or two SSE2 ones).
  typedef double V4 __attribute__((vector_size(32)));
  const double mean = sum / static_cast<double>(n);
  V4 d3, var = {0, 0, 0, 0};
  std::memcpy(&d3, d3_in, sizeof d3);
  const Eigen::Index m = n - 3;  // third differences d_i, i in [0, m)
  Eigen::Index i = 0;
  for (; i + 4 <= m; i += 4) {
    V4 y0;
    std::memcpy(&y0, y + i, sizeof(V4));
    const V4 c = y0 - mean;
    var += c * c;
  }
  for (i = from; i + 4 <= m; i += 4) {
    V4 y0, y1, y2, y3;
    std::memcpy(&y0, y + i, sizeof(V4));
    std::memcpy(&y1, y + i + 1, sizeof(V4));
    std::memcpy(&y2, y + i + 2, sizeof(V4));
    std::memcpy(&y3, y + i + 3, sizeof(V4));
    const V4 d = y3 - 3.0 * y2 + 3.0 * y1 - y0;
    d3 += d * d;
  }
  for (; i < m; ++i) {
    const double d = y[i + 3] - 3.0 * y[i + 2] + 3.0 * y[i + 1] - y[i];
    d3[0] += d * d;
  }
  for (Eigen::Index j = (m / 4) * 4; j < n; ++j) var[0] += (y[j] - mean) * (y[j] - mean);
  const double d3_sum = (d3[0] + d3[1]) + (d3[2] + d3[3]);
  const double var_sum = (var[0] + var[1]) + (var[2] + var[3]);
  *noise = std::sqrt(d3_sum / (20.0 * static_cast<double>(n - 3)));
  *signal = std::sqrt(var_sum / static_cast<double>(n));
}

// Relative rounding level of a residual sum of squares computed as b'b - b'X x.
constexpr double kRssFloor = 64.0 * std::numeric_limits<double>::epsilon();

// solveEquilibrated's eigendecomposition path for q >= 2 unknowns (at most MAX): run-time sizes
// with compile-time bounds, the dynamic-size algorithms, without heap allocations.
template <int MAX, typename D>
bool eigenSolve(const Eigen::Ref<const Eigen::MatrixXd>& G,
                const Eigen::Ref<const Eigen::VectorXd>& r, const D& d, double max_condition,
                Eigen::VectorXd* x, Eigen::MatrixXd* inverse, double* condition) {
  typedef Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, MAX, MAX> Small;
  const Eigen::Index q = G.rows();
  const Small S = d.asDiagonal() * G * d.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Small> es(S);
  if (es.info() != Eigen::Success) return false;
  const auto& lam = es.eigenvalues();
  const double lmax = lam[q - 1], lmin = lam[0];
  *condition = lmin > 0.0 ? std::sqrt(lmax / lmin) : std::numeric_limits<double>::infinity();
  if (!(*condition <= max_condition)) return false;
  const Small& V = es.eigenvectors();
  const Small Sinv = V * lam.cwiseInverse().asDiagonal() * V.transpose();
  *x = d.asDiagonal() * (Sinv * (d.asDiagonal() * r));
  if (inverse) *inverse = d.asDiagonal() * Sinv * d.asDiagonal();
  return true;
}

// Solves the symmetric positive semi-definite system G x = r after equilibration
// (D G D, D = diag(G)^-1/2) by a symmetric eigendecomposition. Returns false when G is not
// positive definite or its equilibrated 2-norm condition number (of the underlying design matrix,
// i.e. sqrt of the Gram's) exceeds max_condition. `inverse` (may be null) receives G^-1.
// G and r are referenced in place (blocks of a segment's Gram matrix, not copies).
bool solveEquilibrated(const Eigen::Ref<const Eigen::MatrixXd>& G,
                       const Eigen::Ref<const Eigen::VectorXd>& r, double max_condition,
                       Eigen::VectorXd* x, Eigen::MatrixXd* inverse, double* condition) {
  const Eigen::Index q = G.rows();
  if (q == 0) {
    x->resize(0);
    if (inverse) inverse->resize(0, 0);
    *condition = 1.0;
    return true;
  }
  // (at most kMaxColumns + 1 entries: no heap allocation)
  Eigen::Matrix<double, Eigen::Dynamic, 1, 0, IntegralMethod::kMaxColumns + 1, 1> d(q);
  for (Eigen::Index i = 0; i < q; ++i) {
    if (!(G(i, i) > 0.0) || !std::isfinite(G(i, i))) {
      *condition = std::numeric_limits<double>::infinity();
      return false;
    }
    d[i] = 1.0 / std::sqrt(G(i, i));
  }
  if (q == 1) {
    // One unknown (the piecewise known problem): the general path's operations without its
    // allocations (the eigendecomposition of a 1x1 matrix is itself, vector 1).
    const double s = (d[0] * G(0, 0)) * d[0];
    *condition = s > 0.0 ? std::sqrt(s / s) : std::numeric_limits<double>::infinity();
    if (!(*condition <= max_condition)) return false;
    const double sinv = 1.0 / s;
    x->resize(1);
    (*x)[0] = d[0] * (sinv * (d[0] * r[0]));
    if (inverse) inverse->setConstant(1, 1, (d[0] * sinv) * d[0]);
    return true;
  }
  return q <= 4 ? eigenSolve<4>(G, r, d, max_condition, x, inverse, condition)
                : eigenSolve<IntegralMethod::kMaxColumns>(G, r, d, max_condition, x, inverse,
                                                          condition);
}

}  // namespace

// ----------------------------------------------------------------------------------------------
// IntegralMethod

IntegralMethod::IntegralMethod(const IdentificationOptions& options, const GearConstants& gear)
    : options_(options), gear_(gear), window_length_(options.window_length) {
  shape_ = options.formulation == Formulation::Greybox &&
           options.stiffness_shape.kind != StiffnessShape::Kind::Square;
  n_basis_ = shape_ ? options.stiffness_shape.unknowns() : 0;
  buildColumns();
}

void IntegralMethod::buildColumns() {
  columns_.clear();
  std::vector<Column> local, shared;
  switch (options_.model) {
    case DampingModel::Piecewise:
      local.push_back(Column::DampC);
      break;
    case DampingModel::Constant:
      shared.push_back(Column::DampC);
      break;
    case DampingModel::LoadLaw:
      shared.push_back(Column::DampC);
      shared.push_back(Column::DampLoad);
      break;
  }
  switch (options_.formulation) {
    case Formulation::Known:
      break;
    case Formulation::Greybox:
      if (shape_) {
        for (int k = 0; k < n_basis_; ++k) local.push_back(Column::StiffBasis);
      } else {
        local.push_back(Column::StiffK0);
        local.push_back(Column::StiffDK);
      }
      break;
    case Formulation::Paper:
      local.push_back(Column::StiffK0);
      local.push_back(Column::ForceConst);
      break;
    case Formulation::Legacy:
      shared.push_back(Column::StiffK0);
      if (std::isnan(legacy_fbar_)) shared.push_back(Column::ForceConst);
      break;
  }
  n_local_ = static_cast<int>(local.size());
  n_shared_ = static_cast<int>(shared.size());
  columns_ = local;
  columns_.insert(columns_.end(), shared.begin(), shared.end());
  column_index_.fill(-1);
  for (size_t i = columns_.size(); i-- > 0;)
    column_index_[static_cast<size_t>(columns_[i])] = static_cast<int>(i);
  assert(columns_.size() <= static_cast<size_t>(kMaxColumns));
}

void IntegralMethod::setLegacyForcing(double fbar) {
  legacy_fbar_ = fbar;
  buildColumns();
}

QualityWarning switchesUnlocatedWarning(long count) {
  return {quality_code::kSwitchesUnlocated,
          std::to_string(count) +
              " stiffness switches could not be located from mesh_phase (values held from the "
              "sample instead): check contact_ratio and the phase origin"};
}

void IntegralMethod::append(IntegralMethod&& later) {
  for (auto& rec : later.segments_) segments_.push_back(std::move(rec));
  unlocated_switches_ += later.unlocated_switches_;
  if (!(window_length_ > 0.0)) window_length_ = later.window_length_;
  later.reset();
}

void IntegralMethod::reset() {
  if (!segments_.empty()) spare_.swapBuffers(&segments_.back());  // for the next addSegment
  segments_.clear();
  unlocated_switches_ = 0;
}

namespace {

// A four-point rule's weights applied to x[0..3], summed left to right (as every hot loop did
// inline: the same bits).
struct Taps4 {
  double w0, w1, w2, w3;
  explicit Taps4(const double* w) : w0(w[0]), w1(w[1]), w2(w[2]), w3(w[3]) {}
  double operator()(const double* x) const { return w0 * x[0] + w1 * x[1] + w2 * x[2] + w3 * x[3]; }
};

// Interior intervals [lo, hi) of the known formulation with held stiffness: the cubic rule's
// area increments of y (ay) and the area/moment increments of K y - F (ag, mg), with yb, Tb
// pointing one sample before the interval's left end and kb at it (the moment of y alone is not
// needed by the known rows). AVX2 + FMA clone (contracted multiply-adds) and the baseline.
GEAR_FMA_CLONES
void heldStiffnessIncrements(const double* __restrict__ yb, const double* __restrict__ kb,
                             const double* __restrict__ Tb, Eigen::Index lo, Eigen::Index hi,
                             const double* wa, const double* wm, double inv_me, double ff,
                             double* __restrict__ ay, double* __restrict__ ag,
                             double* __restrict__ mg) {
  const Taps4 a(wa), m(wm);
  for (Eigen::Index i = lo; i < hi; ++i) {
    const double A = a(yb + i), Mo = m(yb + i);
    const double K = kb[i] * inv_me;
    ay[i] = A;
    ag[i] = K * A - ff * a(Tb + i);
    mg[i] = K * Mo - ff * m(Tb + i);
  }
}

// Interior intervals [lo, hi) of the greybox formulation: the increments of y (ay, my), of -F
// (ag, mg) and of s y (as, ms), yb and Tb pointing one sample before the interval's left end and
// sb at it (the same expressions as the generic path, in one loop; clones as above).
GEAR_FMA_CLONES
void greyIncrements(const double* __restrict__ yb, const double* __restrict__ Tb,
                    const double* __restrict__ sb, Eigen::Index lo, Eigen::Index hi,
                    const double* wa, const double* wm, double ff, double* __restrict__ ay,
                    double* __restrict__ my, double* __restrict__ ag, double* __restrict__ mg,
                    double* __restrict__ as, double* __restrict__ ms) {
  const Taps4 a(wa), m(wm);
  for (Eigen::Index i = lo; i < hi; ++i) {
    const double A = a(yb + i), Mo = m(yb + i);
    const double F[4] = {ff * Tb[i], ff * Tb[i + 1], ff * Tb[i + 2], ff * Tb[i + 3]};
    ay[i] = A;
    my[i] = Mo;
    ag[i] = -a(F);
    mg[i] = -m(F);
    as[i] = sb[i] * A;
    ms[i] = sb[i] * Mo;
  }
}

// Four doubles in one vector (one AVX register; two SSE2 registers in the baseline clone), with
// unaligned loads/stores of n <= 4 lanes (the rest zero) and the in-register prefix sums of the
// blocked row scans (forcedRows) and the four-row projected Gram (projectedGram).
// The helpers pass V4 by value; they are always inlined, so no call uses the AVX argument ABI
// that GCC's -Wpsabi warns about.
typedef double V4 __attribute__((vector_size(32)));
#if !defined(__clang__)
#pragma GCC diagnostic ignored "-Wpsabi"
#endif
#if defined(__clang__)
#define GD_SHUFFLE(a, b, i0, i1, i2, i3) __builtin_shufflevector(a, b, i0, i1, i2, i3)
#else
typedef long GdI4 __attribute__((vector_size(32)));
#define GD_SHUFFLE(a, b, i0, i1, i2, i3) __builtin_shuffle(a, b, GdI4{i0, i1, i2, i3})
#endif

GD_ALWAYS_INLINE inline V4 load4(const double* x, int n = 4) {
  V4 v = {0.0, 0.0, 0.0, 0.0};
  std::memcpy(&v, x, sizeof(double) * static_cast<size_t>(n));
  return v;
}
GD_ALWAYS_INLINE inline void store4(double* x, const V4& v, int n = 4) {
  std::memcpy(x, &v, sizeof(double) * static_cast<size_t>(n));
}
GD_ALWAYS_INLINE inline V4 lastLane(const V4& v) { return GD_SHUFFLE(v, v, 3, 3, 3, 3); }
// [x0, x1, x2, x3] -> [0, x0, x1, x2]
GD_ALWAYS_INLINE inline V4 shiftLanes(const V4& v) {
  const V4 zero = {0.0, 0.0, 0.0, 0.0};
  return GD_SHUFFLE(zero, v, 0, 4, 5, 6);
}
// Inclusive prefix sums of the four lanes (two shift-and-add steps).
GD_ALWAYS_INLINE inline V4 scan4(V4 x) {
  const V4 zero = {0.0, 0.0, 0.0, 0.0};
  x += shiftLanes(x);
  return x + GD_SHUFFLE(zero, x, 0, 1, 4, 5);
}

// A running single integral G and double integral Q over blocks of four rows: for row r,
// Q_r = Q_{r-1} + h G_{r-1} + m_{r-1} and G_r = G_{r-1} + a_{r-1} (a, m: the interval's area and
// moment increments). The carries hold the previous block's last row in every lane.
struct DoubleIntegral {
  V4 G = {0.0, 0.0, 0.0, 0.0}, Q = {0.0, 0.0, 0.0, 0.0};
  // The four rows' Q from their increments a = inc[r-1 .. r+2], m likewise.
  GD_ALWAYS_INLINE V4 step(const V4& h, const V4& a, const V4& m) {
    const V4 g = scan4(a);
    const V4 q = Q + scan4(h * (G + shiftLanes(g)) + m);
    G += lastLane(g);
    Q = lastLane(q);
    return q;
  }
};

// One window's row computation (IntegralMethod::windowRows) in named steps over the state they
// share: the window, the step, the gear constants, which integrals the formulation needs, the
// channels, and the per-interval increment arrays over the L - 1 intervals j = w0 + i (columns
// of the scratch matrix inc): ay, my (y), ag, mg (K y - F or -F), as, ms (s y), dS (load law:
// (T1 - T_c) dy). The steps are internal functions called once: they compile inline into
// windowRows, as the one function they were.
struct WindowPass {
  WindowPass(const CubicRules& rules_in, Eigen::Index lo, Eigen::Index hi,
             const std::vector<QuadratureBreak>& breaks_in, const SignalView& s, Eigen::Index w0_in,
             Eigen::Index w1, const GearConstants& gear, const IdentificationOptions& o,
             bool held_k, Eigen::MatrixXd* inc)
      : rules(rules_in),
        breaks(breaks_in),
        seg_lo(lo),
        seg_hi(hi),
        w0(w0_in),
        L(w1 - w0_in),
        ni(L - 1),
        h(s.dt),
        h2(h * h),
        inv_me(1.0 / gear.equivalent_mass),
        ff(gear.force_factor),
        f(o.formulation),
        known(f == Formulation::Known),
        grey(f == Formulation::Greybox),
        use_force(known || grey),
        load(o.model == DampingModel::LoadLaw),
        split_k(known && held_k),
        y(s.dte),
        k(s.stiffness),
        T(s.torque),
        st(s.mesh_state),
        T_c((load && T) ? T[w0] : 0.0),
        ay(&(*inc)(0, 0)),
        my(&(*inc)(0, 1)),
        ag(&(*inc)(0, 2)),
        mg(&(*inc)(0, 3)),
        as(&(*inc)(0, 4)),
        ms(&(*inc)(0, 5)),
        dS(&(*inc)(0, 6)) {
    // The segment's edges use one-sided rules, so a segment reads no sample outside itself
    // (streamed segments give the whole-record estimates, and a NaN next door does not leak in).
    i_hi = ni;
    while (i_lo < ni && rule(w0 + i_lo).offset() != -1) ++i_lo;
    while (i_hi > i_lo && rule(w0 + i_hi - 1).offset() != -1) --i_hi;
  }
  const CubicIntervalRule& rule(Eigen::Index j) const {
    return rules.forInterval(j, seg_lo, seg_hi);
  }

  const CubicRules& rules;
  const std::vector<QuadratureBreak>& breaks;  // the segment's (see addSegment)
  const Eigen::Index seg_lo, seg_hi;           // the segment's samples
  const Eigen::Index w0, L, ni;                // window start, rows, intervals
  const double h, h2, inv_me, ff;
  const Formulation f;
  const bool known, grey, use_force, load, split_k;
  const double *const y, *const k, *const T, *const st;
  const double T_c;  // load law: T1 at the window start
  double *const ay, *const my, *const ag, *const mg, *const as, *const ms, *const dS;
  Eigen::Index i_lo = 0, i_hi = 0;  // [i_lo, i_hi): the intervals of the interior rule
};

// Pass 1, the interior intervals [i_lo, i_hi) with the interior rule (independent across
// intervals, so they vectorise).
void interiorIncrements(const WindowPass& p) {
  const double h = p.h, h2 = p.h2, inv_me = p.inv_me, ff = p.ff;
  const auto& wa = p.rules.interior.area();
  const auto& wm = p.rules.interior.moment();
  const double a0 = h * wa[0], a1 = h * wa[1], a2 = h * wa[2], a3 = h * wa[3];
  const double m0 = h2 * wm[0], m1 = h2 * wm[1], m2 = h2 * wm[2], m3 = h2 * wm[3];
  const Eigen::Index w0 = p.w0, i_lo = p.i_lo, i_hi = p.i_hi;
  double *const ay = p.ay, *const my = p.my, *const ag = p.ag, *const mg = p.mg;
  const double* yb = p.y + w0 - 1;
  if (p.split_k) {
    // K held on the interval (a switch inside is fixed up by breakIncrements): the hot path.
    const double wa4[4] = {a0, a1, a2, a3}, wm4[4] = {m0, m1, m2, m3};
    heldStiffnessIncrements(yb, p.k + w0, p.T + w0 - 1, i_lo, i_hi, wa4, wm4, inv_me, ff, ay, ag,
                            mg);
  } else if (p.grey) {
    const double wa4[4] = {a0, a1, a2, a3}, wm4[4] = {m0, m1, m2, m3};
    greyIncrements(yb, p.T + w0 - 1, p.st + w0, i_lo, i_hi, wa4, wm4, ff, ay, my, ag, mg, p.as,
                   p.ms);
    return;
  } else {
    for (Eigen::Index i = i_lo; i < i_hi; ++i) {
      ay[i] = a0 * yb[i] + a1 * yb[i + 1] + a2 * yb[i + 2] + a3 * yb[i + 3];
      my[i] = m0 * yb[i] + m1 * yb[i + 1] + m2 * yb[i + 2] + m3 * yb[i + 3];
    }
  }
  if (p.known) {
    const double* Tb = p.T + w0 - 1;
    if (!p.split_k) {
      const double* kk = p.k + w0 - 1;
      const double* yy = p.y + w0 - 1;
      for (Eigen::Index i = i_lo; i < i_hi; ++i) {
        double g[4];
        for (int c = 0; c < 4; ++c) g[c] = kk[i + c] * inv_me * yy[i + c] - ff * Tb[i + c];
        ag[i] = a0 * g[0] + a1 * g[1] + a2 * g[2] + a3 * g[3];
        mg[i] = m0 * g[0] + m1 * g[1] + m2 * g[2] + m3 * g[3];
      }
    }
  }
}

// Interval i at an edge of the record (a one-sided rule), generic.
void edgeIncrements(const WindowPass& p, Eigen::Index i) {
  const double *y = p.y, *k = p.k, *T = p.T;
  const double h = p.h, h2 = p.h2, inv_me = p.inv_me, ff = p.ff;
  const Eigen::Index j = p.w0 + i;
  const CubicIntervalRule& rule = p.rule(j);
  const Eigen::Index b = j + rule.offset();
  const auto& wa = rule.area();
  const auto& wm = rule.moment();
  double sa = 0, sm = 0, fa = 0, fm = 0, ga = 0, gm = 0;
  for (int c = 0; c < 4; ++c) {
    sa += wa[c] * y[b + c], sm += wm[c] * y[b + c];
    if (p.use_force) fa += wa[c] * ff * T[b + c], fm += wm[c] * ff * T[b + c];
    if (p.known && !p.split_k) {
      ga += wa[c] * k[b + c] * inv_me * y[b + c], gm += wm[c] * k[b + c] * inv_me * y[b + c];
    }
  }
  p.ay[i] = h * sa, p.my[i] = h2 * sm;
  if (p.known) {
    if (p.split_k) ga = k[j] * inv_me * sa, gm = k[j] * inv_me * sm;
    p.ag[i] = h * (ga - fa), p.mg[i] = h2 * (gm - fm);
  } else if (p.grey) {
    p.ag[i] = -h * fa, p.mg[i] = -h2 * fm;
    p.as[i] = p.st[j] * p.ay[i], p.ms[i] = p.st[j] * p.my[i];
  }
}

// Interval j next to a break (a switch of a held channel, a jump or kink of a smooth stiffness:
// quadrature.hpp): every stencil on one side of it, an interval holding one split there, each
// part with its own held value. Recomputed in full (all increments).
void breakIncrements(const WindowPass& p, Eigen::Index j) {
  const double *y = p.y, *k = p.k, *T = p.T, *st = p.st;
  const double h = p.h, h2 = p.h2, inv_me = p.inv_me, ff = p.ff;
  const Eigen::Index i = j - p.w0;
  QuadratureBreak near[5];
  int nn = 0;
  auto it = std::lower_bound(p.breaks.begin(), p.breaks.end(), j - 2,
                             [](const QuadratureBreak& b, Eigen::Index v) { return b.j < v; });
  for (; it != p.breaks.end() && it->j <= j + 2 && nn < 5; ++it) near[nn++] = *it;
  IntervalPart parts[2];
  const int np = p.rules.parts(j, p.seg_lo, p.seg_hi, near, nn, parts);
  double sa = 0, sm = 0, fa = 0, fm = 0, ga = 0, gm = 0, xa = 0, xm = 0;
  for (int n = 0; n < np; ++n) {
    const IntervalPart& P = parts[n];
    const auto wa = P.rule->area(P.u0, P.u1);
    const auto wm = P.rule->moment(P.u0, P.u1);
    const Eigen::Index b = j + P.rule->offset();
    double pa = 0, pm = 0;
    for (int c = 0; c < 4; ++c) {
      pa += wa[c] * y[b + c], pm += wm[c] * y[b + c];
      if (p.use_force) fa += wa[c] * ff * T[b + c], fm += wm[c] * ff * T[b + c];
      if (p.known && !p.split_k) {
        ga += wa[c] * k[b + c] * inv_me * y[b + c], gm += wm[c] * k[b + c] * inv_me * y[b + c];
      }
    }
    sa += pa, sm += pm;
    if (p.split_k) {
      const double K = (P.right ? k[j + 1] : k[j]) * inv_me;
      ga += K * pa, gm += K * pm;
    }
    if (p.grey) {
      const double sv = P.right ? st[j + 1] : st[j];
      xa += sv * pa, xm += sv * pm;
    }
  }
  p.ay[i] = h * sa, p.my[i] = h2 * sm;
  if (p.known) {
    p.ag[i] = h * (ga - fa), p.mg[i] = h2 * (gm - fm);
  } else if (p.grey) {
    p.ag[i] = -h * fa, p.mg[i] = -h2 * fm;
    p.as[i] = h * xa, p.ms[i] = h2 * xm;
  }
}

// The intervals around the segment's breaks whose neighbourhood meets this window's intervals.
void nearBreakIncrements(const WindowPass& p) {
  auto it = std::lower_bound(p.breaks.begin(), p.breaks.end(), p.w0 - 1,
                             [](const QuadratureBreak& b, Eigen::Index v) { return b.j < v; });
  for (; it != p.breaks.end() && it->j <= p.w0 + p.ni; ++it) {
    for (Eigen::Index j = it->j - 1; j <= it->j + 1; ++j) {
      if (j >= p.w0 && j < p.w0 + p.ni) breakIncrements(p, j);
    }
  }
}

// Load law: the increments of the integral of (T1 - T_c) dy (trapezoidal).
void loadIncrements(const WindowPass& p) {
  const double *y = p.y, *T = p.T, T_c = p.T_c;
  for (Eigen::Index i = 0; i < p.ni; ++i) {
    const Eigen::Index j = p.w0 + i;
    p.dS[i] = 0.5 * ((T[j] - T_c) + (T[j + 1] - T_c)) * (y[j + 1] - y[j]);
  }
}

// Greybox shape: area/moment increments of b_k(u) y for every one of the nb basis functions
// (basis: values, one column per sample of the segment), the product interpolated by the
// interval's cubic rule (columns 2k: area, 2k + 1: moment of *basis_inc).
void basisIncrements(const WindowPass& p, const Eigen::MatrixXd& basis, int nb,
                     Eigen::MatrixXd* basis_inc) {
  if (basis_inc->rows() < p.L || basis_inc->cols() < 2 * nb) {
    basis_inc->resize(std::max<Eigen::Index>(p.L, 1), 2 * nb);
  }
  for (Eigen::Index i = 0; i < p.ni; ++i) {
    const Eigen::Index j = p.w0 + i;
    const CubicIntervalRule& rule = p.rule(j);
    const Eigen::Index b = j + rule.offset();
    const auto& wa = rule.area();
    const auto& wm = rule.moment();
    for (int k = 0; k < nb; ++k) {
      double sa = 0.0, sm = 0.0;
      for (int c = 0; c < 4; ++c) {
        const double g = basis(k, b + c - p.seg_lo) * p.y[b + c];
        sa += wa[c] * g, sm += wm[c] * g;
      }
      (*basis_inc)(i, 2 * k) = p.h * sa;
      (*basis_inc)(i, 2 * k + 1) = p.h2 * sm;
    }
  }
}

// Where each kind of column stands in the rows (-1: not a column of this problem).
struct RowColumns {
  int C, L, K0, DK, F, B;  // damping, load law, stiffness K0 and dK, force, shape basis
  int b;                   // the right-hand side
};

// Pass 2 of the known and the greybox square formulations (GREY), any damping model (LOAD: the
// load law's column, its increments dS formed here, as loadIncrements would): prefix sums -> rows,
// the same integrals as generalRows with the formulation's choices compiled in. Blocked: four rows
// per step, each running sum scanned in the lanes of one vector with its carry from the previous
// block (a different summation order from generalRows' one-row chains: equal to rounding).
template <bool GREY, bool LOAD>
GD_ALWAYS_INLINE inline void forcedRows(const WindowPass& p, const RowColumns& c,
                                        Eigen::MatrixXd* rows) {
  const double *ay = p.ay, *my = p.my, *ag = p.ag, *mg = p.mg, *as = p.as, *ms = p.ms;
  const double* y = p.y + p.w0;
  const double* T = LOAD ? p.T + p.w0 : nullptr;
  double* colb = &(*rows)(0, c.b);
  double* colC = &(*rows)(0, c.C);
  double* colL = LOAD ? &(*rows)(0, c.L) : nullptr;
  double* colK0 = GREY ? &(*rows)(0, c.K0) : nullptr;
  double* colDK = GREY ? &(*rows)(0, c.DK) : nullptr;
  const V4 h = V4{0.0, 0.0, 0.0, 0.0} + p.h, half_h = 0.5 * h, T_c = h * 0.0 + p.T_c;
  const V4 T_cx = {p.T_c, p.T_c, p.T_c, p.T_c};  // (exact, a -0.0 too: loadIncrements' T_c)
  V4 P = {0.0, 0.0, 0.0, 0.0};
  DoubleIntegral Iy, Ikf, Is, Id;  // of y, K y - F (known) or -F, s y, (T1 - T_c) dy
  colb[0] = y[0];                  // row 0: every integral zero
  colC[0] = 0.0;
  if (LOAD) colL[0] = 0.0;
  if (GREY) colK0[0] = colDK[0] = 0.0;
  // Rows r .. r + n - 1 (n <= 4) from the increments of intervals r - 1 .. r + n - 2.
  auto block = [&](Eigen::Index r, int n) GD_ALWAYS_INLINE {
    const Eigen::Index i = r - 1;
    const V4 a = load4(ay + i, n);
    const V4 Pr = P + scan4(a);
    P = lastLane(Pr);
    store4(colC + r, -Pr, n);
    const V4 yr = load4(y + r, n);
    store4(colb + r, yr + Ikf.step(h, load4(ag + i, n), load4(mg + i, n)), n);
    if (GREY) {
      store4(colK0 + r, -Iy.step(h, a, load4(my + i, n)), n);
      store4(colDK + r, -Is.step(h, load4(as + i, n), load4(ms + i, n)), n);
    }
    if (LOAD) {  // loadIncrements' dS of intervals i .. i + n - 1, the same operations
      const V4 d =
          0.5 * ((load4(T + i, n) - T_cx) + (load4(T + r, n) - T_cx)) * (yr - load4(y + i, n));
      store4(colL + r, -(T_c * Pr + Id.step(h, d, half_h * d)), n);
    }
  };
  const Eigen::Index L = p.L;  // (a local: the stores could alias p's)
  Eigen::Index r = 1;
  for (; r + 4 <= L; r += 4) block(r, 4);
  if (r < L) block(r, static_cast<int>(L - r));
}

// forcedRows for the formulation's choices, AVX2 + FMA clone.
GEAR_FMA_CLONES
void forcedRowsOf(const WindowPass& p, const RowColumns& c, Eigen::MatrixXd* rows) {
  if (p.grey) {
    p.load ? forcedRows<true, true>(p, c, rows) : forcedRows<true, false>(p, c, rows);
  } else {
    p.load ? forcedRows<false, true>(p, c, rows) : forcedRows<false, false>(p, c, rows);
  }
}

// Pass 2, generic: prefix sums -> rows, every column (the nb shape basis columns from
// basis_inc); fbar: the legacy formulation's known mean forcing (NaN: a column).
void generalRows(const WindowPass& p, const RowColumns& c, const Eigen::MatrixXd& basis_inc, int nb,
                 double fbar, Eigen::MatrixXd* rows) {
  const double h = p.h;
  const bool need_iiy = !p.known;
  double* colb = &(*rows)(0, c.b);
  double P = 0.0, Gy = 0.0, Qy = 0.0, Gs = 0.0, Qs = 0.0, Gkf = 0.0, Qkf = 0.0, Sr = 0.0, Dr = 0.0;
  double Gb[IntegralMethod::kMaxColumns] = {}, Qb[IntegralMethod::kMaxColumns] = {};
  for (Eigen::Index r = 0; r < p.L; ++r) {
    if (nb > 0) {
      for (int k = 0; k < nb; ++k) {
        if (r > 0) {
          Qb[k] += h * Gb[k] + basis_inc(r - 1, 2 * k + 1);
          Gb[k] += basis_inc(r - 1, 2 * k);
        }
        (*rows)(r, c.B + k) = -Qb[k];
      }
    }
    if (r > 0) {
      const Eigen::Index i = r - 1;
      if (need_iiy) Qy += h * Gy + p.my[i], Gy += p.ay[i];
      if (p.use_force) Qkf += h * Gkf + p.mg[i], Gkf += p.ag[i];
      if (p.grey) Qs += h * Gs + p.ms[i], Gs += p.as[i];
      if (p.load) Dr += h * (Sr + 0.5 * p.dS[i]), Sr += p.dS[i];
      P += p.ay[i];
    }
    const double tau = static_cast<double>(r) * h;
    double bval = p.y[p.w0 + r];
    if (p.use_force) bval += Qkf;  // known: + IIKy - IIF; greybox: - IIF
    if (p.f == Formulation::Legacy && !std::isnan(fbar)) bval -= fbar * 0.5 * tau * tau;
    colb[r] = bval;
    if (c.C >= 0) (*rows)(r, c.C) = -P;
    if (c.L >= 0) (*rows)(r, c.L) = -(p.T_c * P + Dr);
    if (c.K0 >= 0) (*rows)(r, c.K0) = -Qy;
    if (c.DK >= 0) (*rows)(r, c.DK) = -Qs;
    if (c.F >= 0) (*rows)(r, c.F) = 0.5 * tau * tau;
  }
}

}  // namespace

// Row values of one window [w0, w1): for each row r (sample w0 + r) the q column values and b,
// stored column-major in rows_ (rows_(r, c)). Cumulative integrals restart at w0.
//
// Two passes, for speed: (1) per-interval increments of the integrals (independent across
// intervals, so they vectorise), the interior with the interior rule, then the record's edges
// with one-sided rules, then a fix-up of the rare intervals next to a switch (recomputed in full:
// its values replace the earlier steps'); (2) the prefix sums that make the cumulative single
// and double integrals, writing the rows.
void IntegralMethod::windowRows(const SignalView& s, Eigen::Index w0, Eigen::Index w1,
                                double fbar) {
  const Eigen::Index L = w1 - w0;
  const int q = static_cast<int>(columns_.size());
  if (rows_.rows() < L || rows_.cols() != q + 1) rows_.resize(std::max<Eigen::Index>(L, 1), q + 1);
  if (inc_.rows() < L || inc_.cols() < 7) inc_.resize(std::max<Eigen::Index>(L, 1), 7);
  const WindowPass p(rules_, seg_lo_, seg_hi_, breaks_, s, w0, w1, gear_, options_, held_k_, &inc_);
  interiorIncrements(p);
  for (Eigen::Index i = 0; i < p.i_lo; ++i) edgeIncrements(p, i);
  for (Eigen::Index i = p.i_hi; i < p.ni; ++i) edgeIncrements(p, i);
  nearBreakIncrements(p);
  const int nb = shape_ ? n_basis_ : 0;
  const bool forced = nb == 0 && (p.known || p.grey);  // (forcedRows forms the load law's dS)
  if (p.load && !forced) loadIncrements(p);
  if (nb > 0) basisIncrements(p, basis_, nb, &basis_inc_);
  const RowColumns c{columnIndex(Column::DampC),
                     columnIndex(Column::DampLoad),
                     columnIndex(Column::StiffK0),
                     columnIndex(Column::StiffDK),
                     columnIndex(Column::ForceConst),
                     columnIndex(Column::StiffBasis),
                     q};
  if (forced) return forcedRowsOf(p, c, &rows_);
  generalRows(p, c, basis_inc_, nb, fbar, &rows_);
}

namespace {

// Means and p1-slopes of the nc = NC columns of rows (L rows), and the Gram matrix of the
// columns projected onto the orthogonal complement of {1, p1}, p1 = r - (L-1)/2, added to
// `gram`. One pass: each column is first detrended by the line through its first and last rows
// (the projection is invariant to adding a linear function, so this is exact algebra); what
// remains is small and oscillatory, so forming the projected Gram from its moments,
//   G_ab = sum z_a z_b - (sum z_a)(sum z_b)/L - (sum p1 z_a)(sum p1 z_b)/sum p1^2,
// does not cancel the leading digits the way raw moments of the trend-dominated integrals would.
// Four rows per step, one vector per column (lane j: rows = j mod 4), the lanes summed at the end.
// NC = 0: the column count is the run-time `n_dyn` (at most CAP), for the greybox shapes' many
// columns; otherwise NC is compiled in (the common small cases).
template <int NC, int CAP = NC>
GD_ALWAYS_INLINE inline void projectedGram(const Eigen::MatrixXd& rows, Eigen::Index L, int raw_col,
                                           double* mean, double* slope, double* raw_norm,
                                           Eigen::MatrixXd* gram, int n_dyn = NC) {
  const int n = NC > 0 ? NC : n_dyn;
  const double half = 0.5 * static_cast<double>(L - 1);
  const double Ld = static_cast<double>(L);
  const double sp2 = Ld * (Ld * Ld - 1.0) / 12.0;  // sum of p1^2
  const V4 zero = {0.0, 0.0, 0.0, 0.0};
  const double* col[CAP] = {};
  double d0[CAP] = {}, d1[CAP] = {};
  V4 S[CAP], SP[CAP], M[CAP * (CAP + 1) / 2], raw4 = zero;
  for (int c = 0; c < n; ++c) {
    col[c] = &rows(0, c);
    d0[c] = col[c][0];
    d1[c] = L > 1 ? (col[c][L - 1] - col[c][0]) / static_cast<double>(L - 1) : 0.0;
    S[c] = SP[c] = zero;
  }
  for (int k = 0; k < n * (n + 1) / 2; ++k) M[k] = zero;
  // Rows r .. r + cnt - 1 (cnt <= 4; lanes past cnt masked to zero), rl = their row numbers.
  auto accumulate = [&](Eigen::Index r, int cnt, const V4& rl, const V4& mask) GD_ALWAYS_INLINE {
    V4 z[CAP];
    for (int c = 0; c < n; ++c) {
      const V4 x = load4(col[c] + r, cnt);
      z[c] = ((x - d0[c]) - d1[c] * rl) * mask;
      if (c == raw_col) raw4 += x * x;
    }
    const V4 pv = rl - half;
    for (int c = 0; c < n; ++c) {
      S[c] += z[c];
      SP[c] += pv * z[c];
    }
    int k = 0;
    for (int a = 0; a < n; ++a) {
      for (int b = a; b < n; ++b) M[k++] += z[a] * z[b];
    }
  };
  Eigen::Index r = 0;
  V4 rl = {0.0, 1.0, 2.0, 3.0};
  for (; r + 4 <= L; r += 4, rl += 4.0) accumulate(r, 4, rl, zero + 1.0);
  if (r < L) {
    const int cnt = static_cast<int>(L - r);
    const V4 mask = {1.0, cnt > 1 ? 1.0 : 0.0, cnt > 2 ? 1.0 : 0.0, 0.0};
    accumulate(r, cnt, rl, mask);
  }
  auto lanes = [](const V4& v) { return (v[0] + v[1]) + (v[2] + v[3]); };
  double Sd[CAP], SPd[CAP];
  for (int c = 0; c < n; ++c) {
    Sd[c] = lanes(S[c]);
    SPd[c] = lanes(SP[c]);
    mean[c] = Sd[c] / Ld + d0[c] + d1[c] * half;
    slope[c] = (sp2 > 0.0 ? SPd[c] / sp2 : 0.0) + d1[c];
  }
  *raw_norm += lanes(raw4);
  int k = 0;
  for (int a = 0; a < n; ++a) {
    for (int b = a; b < n; ++b) {
      const double g =
          lanes(M[k++]) - Sd[a] * Sd[b] / Ld - (sp2 > 0.0 ? SPd[a] * SPd[b] / sp2 : 0.0);
      (*gram)(a, b) += g;
      if (a != b) (*gram)(b, a) += g;
    }
  }
}

// projectedGram for nc columns (the compiled-in counts 2-6, else run-time), AVX2 + FMA clone.
GEAR_FMA_CLONES
void gramOf(int nc, const Eigen::MatrixXd& rows, Eigen::Index L, int rc, double* mean,
            double* slope, double* raw, Eigen::MatrixXd* gram) {
  switch (nc) {
    case 2:
      return projectedGram<2>(rows, L, rc, mean, slope, raw, gram);
    case 3:
      return projectedGram<3>(rows, L, rc, mean, slope, raw, gram);
    case 4:
      return projectedGram<4>(rows, L, rc, mean, slope, raw, gram);
    case 5:
      return projectedGram<5>(rows, L, rc, mean, slope, raw, gram);
    case 6:
      return projectedGram<6>(rows, L, rc, mean, slope, raw, gram);
    default:
      return projectedGram<0, IntegralMethod::kMaxColumns + 1>(rows, L, rc, mean, slope, raw, gram,
                                                               nc);
  }
}

}  // namespace

SegmentEstimate IntegralMethod::addSegment(const SignalView& s, Eigen::Index begin,
                                           Eigen::Index end, bool estimate) {
  SegmentRecord rec;
  rec.swapBuffers(&spare_);  // (a reset's buffers: no allocation for a segment after one)
  rec.window_records.clear();
  SegmentEstimate& est = rec.estimate;
  est.t_start = s.time(begin);
  est.t_end = s.time(end - 1) + s.dt;
  const long rows = static_cast<long>(end - begin);
  est.samples = rows;
  const int q = static_cast<int>(columns_.size());
  rec.gram.setZero(q + 1, q + 1);
  auto fail = [&](const std::string& why) {
    est.identifiable = false;
    est.reason = why;
    segments_.push_back(rec);
    return est;
  };
  if (window_length_ <= 0.0) window_length_ = defaultWindowLength(s, gear_);
  const Eigen::Index L0 =
      std::max<Eigen::Index>(4, static_cast<Eigen::Index>(std::llround(window_length_ / s.dt)));
  const int W = static_cast<int>(
      std::max<Eigen::Index>(1, static_cast<Eigen::Index>(std::llround(double(rows) / L0))));
  if (s.n < 4 || rows < 4L * W || rows - 2L * W - n_local_ < 2) {
    return fail("too few samples (" + std::to_string(rows) + " in the segment)");
  }
  // The quadrature stencils stay inside [begin, end).
  seg_lo_ = begin;
  seg_hi_ = end;
  FirstTouch touch;  // the channel sums (reused for the segment means) and the fused work
  if (gear_sim::Status why = checkFiniteInputs(s, begin, end, &touch); !why.ok())
    return fail(why.message());
  if (gear_sim::Status why = segmentMeans(s, begin, end, touch, &rec); !why.ok())
    return fail(why.message());
  // Windows: W near-equal spans. The damping column comes first among the locals or, for
  // shared damping, first among the shared columns; its raw norm serves the motion check.
  const double raw_c = accumulateWindows(s, begin, rows, W, &rec);
  rec.rows = rows;
  rec.windows = W;
  est.windows = W;
  const int cC = columnIndex(Column::DampC);
  if (cC >= 0 && !(rec.gram(cC, cC) > 1e-20 * raw_c)) {
    return fail("no motion: the DTE has no dynamic content to identify damping from");
  }
  if (gear_sim::Status why = solveLocals(&rec); !why.ok()) return fail(why.message());
  est.identifiable = true;
  segments_.push_back(std::move(rec));
  if (n_shared_ == 0 && estimate) {
    // Fill the estimate from a finish() of this segment alone (cheap: small matrices).
    const IdentificationResult r = finishRange(segments_.size() - 1, segments_.size());
    return r.segments.back();
  }
  return segments_.back().estimate;
}

// Finite inputs on the segment (a sum is finite only if every term is; the element-wise
// search runs only when it is not). Leaves each needed channel's sum in touch->sum (dte,
// stiffness, torque, mesh_state), and a present stiffness's sum even when it is not needed;
// with them, from the same loop (firstTouch), the start of segmentMeans' work on the DTE's third
// differences and on the held-change search of its break channel.
gear_sim::Status IntegralMethod::checkFiniteInputs(const SignalView& s, Eigen::Index begin,
                                                   Eigen::Index end, FirstTouch* touch) {
  double* channel_sum = touch->sum;
  const Formulation f = options_.formulation;
  const double* channels[] = {s.dte, needsStiffness(f) ? s.stiffness : nullptr,
                              needsTorque(f, options_.model) ? s.torque : nullptr,
                              needsMeshState(f) ? s.mesh_state : nullptr};
  const char* names[] = {"dte", "stiffness", "torque", "mesh_state"};
  // One fused pass sums every needed channel and a present stiffness (segmentMeans' k_integral
  // needs it in any formulation): their first read of the segment, together (channelSums).
  const double* present[4];
  int idx[4], np = 0;
  for (int c = 0; c < 4; ++c) {
    const double* x = c == 1 ? s.stiffness : channels[c];
    if (x != nullptr) present[np] = x, idx[np++] = c;
  }
  double sums[4] = {0, 0, 0, 0};
  const double* brk = breakChannel(s);
  int held = -1;  // brk among the channels read
  for (int p = 0; p < np; ++p) held = present[p] == brk ? p : held;
  held_blocks_.clear();
  touch->held = held >= 0 ? brk : nullptr;
  touch->end = begin;
  if (np > 0 && idx[0] == 0) {
    firstTouch(present, np, held, s.mesh_phase, begin, end, sums, touch->d3, &touch->end,
               &held_blocks_);
  } else if (np > 0) {
    channelSums(present, np, begin, end, sums);
  }
  for (int p = 0; p < np; ++p) channel_sum[idx[p]] = sums[p];
  for (int c = 0; c < 4; ++c) {
    if (channels[c] == nullptr || std::isfinite(channel_sum[c])) continue;
    for (Eigen::Index i = begin; i < end; ++i) {
      if (!std::isfinite(channels[c][i])) {
        std::ostringstream m;
        m << "NaN/Inf or implausible value in input (" << names[c] << " at t = " << s.time(i)
          << " s)";
        return gear_sim::Status::notIdentifiable(m.str(), names[c]);
      }
    }
  }
  return {};
}

const double* IntegralMethod::breakChannel(const SignalView& s) const {
  const Formulation f = options_.formulation;
  return f == Formulation::Known                  ? s.stiffness
         : (f == Formulation::Greybox && !shape_) ? s.mesh_state
                                                  : nullptr;
}

// Noise and signal levels, the segment means (time-weighted over the segment's intervals;
// switches split when located), its breaks and, for a greybox shape, its basis values.
gear_sim::Status IntegralMethod::segmentMeans(const SignalView& s, Eigen::Index begin,
                                              Eigen::Index end, const FirstTouch& touch,
                                              SegmentRecord* rec) {
  const double* channel_sum = touch.sum;
  SegmentEstimate& est = rec->estimate;
  const long rows = static_cast<long>(end - begin);
  const Formulation f = options_.formulation;
  const bool use_torque = needsTorque(f, options_.model);
  // Model-free noise and signal levels for the quality flags (quality_flags.hpp).
  segmentLevels(s.dte + begin, end - begin, channel_sum[0], touch.d3, touch.end - begin,
                &est.noise_std, &est.signal_std);
  if (use_torque) {
    rec->mean_torque = channel_sum[2] / static_cast<double>(rows);
    est.mean_torque = rec->mean_torque;
  }
  rec->duration = static_cast<double>(rows) * s.dt;
  // Breaks of the stiffness (held or smooth, decided from the segment's samples) or of the
  // greybox mesh state on the segment's intervals (forward_model.hpp), shared with the
  // refinement's forward model.
  // One scan finds whether the stiffness is held and, if so, where it switches (what
  // channelIsHeld and findBreaks find); a smooth stiffness is searched for jumps and kinks.
  const double* brk = breakChannel(s);
  held_k_ = false;
  breaks_.clear();
  changes_.clear();
  if (brk != nullptr) {
    const bool held = brk == touch.held
                          ? heldChangesAfter(brk, begin, end, f == Formulation::Known, held_blocks_,
                                             touch.end, &changes_)
                          : heldChanges(brk, begin, end, f == Formulation::Known, &changes_);
    held_k_ = f == Formulation::Known && held;
    if (held) {
      unlocated_switches_ += locateHeldSwitches(s, brk, gear_.contact_ratio, changes_, &breaks_);
    } else {
      unlocated_switches_ += findBreaks(s, brk, false, gear_.contact_ratio, begin, end, &breaks_);
    }
  }
  if (s.stiffness) {
    double sum = channel_sum[1];  // (checkFiniteInputs sums a present stiffness)
    if (held_k_) {
      for (const QuadratureBreak& b : breaks_) {
        sum += (1.0 - b.th) * (s.stiffness[b.j + 1] - s.stiffness[b.j]);
      }
    }
    rec->k_integral = sum * s.dt / gear_.equivalent_mass;
  }
  if (shape_) {
    // The shape's basis functions at every sample of the segment, and their time-means.
    if (s.mesh_phase == nullptr) {
      return gear_sim::Status::notIdentifiable(
          "missing channel mesh_phase (needed by the greybox stiffness shape " +
              toString(options_.stiffness_shape) + ")",
          "mesh_phase");
    }
    basis_.resize(n_basis_, rows);
    for (Eigen::Index i = begin; i < end; ++i) {
      if (!std::isfinite(s.mesh_phase[i])) {
        std::ostringstream m;
        m << "NaN/Inf or implausible value in input (mesh_phase at t = " << s.time(i) << " s)";
        return gear_sim::Status::notIdentifiable(m.str(), "mesh_phase");
      }
      options_.stiffness_shape.basis(s.mesh_phase[i], &basis_(0, i - begin));
    }
    rec->basis_mean.resize(static_cast<size_t>(n_basis_));
    for (int k = 0; k < n_basis_; ++k) rec->basis_mean[k] = basis_.row(k).mean();
  } else if (s.mesh_state && f == Formulation::Greybox) {
    double sum = needsMeshState(f) ? channel_sum[3] : blockSum(s.mesh_state, begin, end);
    for (const QuadratureBreak& b : breaks_) {
      sum += (1.0 - b.th) * (s.mesh_state[b.j + 1] - s.mesh_state[b.j]);
    }
    rec->mean_state = sum / static_cast<double>(rows);
    if (breaks_.empty()) {
      return gear_sim::Status::notIdentifiable(
          "mesh state constant over the segment: the stiffness levels are not "
          "identifiable (segment shorter than a mesh period?)",
          "mesh_state");
    }
  }
  return {};
}

// The rows of each of the W windows, projected and added to the segment's Gram matrix; the
// window records for the modeled response. Returns the damping column's raw squared norm.
double IntegralMethod::accumulateWindows(const SignalView& s, Eigen::Index begin, long rows, int W,
                                         SegmentRecord* rec) {
  const Formulation f = options_.formulation;
  const bool use_torque = needsTorque(f, options_.model);
  const int nc = static_cast<int>(columns_.size()) + 1;
  const int rc = std::max(columnIndex(Column::DampC), 0);
  double raw_c = 0.0;
  rec->window_records.reserve(W);
  for (int w = 0; w < W; ++w) {
    const Eigen::Index w0 = begin + (rows * w) / W, w1 = begin + (rows * (w + 1)) / W;
    const Eigen::Index L = w1 - w0;
    windowRows(s, w0, w1, legacy_fbar_);
    WindowRecord& wr = rec->window_records.emplace_back();  // (in place: ~600 bytes)
    wr.t_start = s.time(w0);
    wr.t_end = s.time(w1 - 1);
    wr.rows = L;
    wr.dt = s.dt;
    wr.torque_T = (use_torque && s.torque) ? s.torque[w0] : kNaN;
    double raw = 0.0;
    double* mean = wr.mean.data();
    double* slope = wr.slope.data();
    gramOf(nc, rows_, L, rc, mean, slope, &raw, &rec->gram);
    raw_c += raw;
  }
  return raw_c;
}

// Segment-local solve (final for models without shared unknowns): the condition number, and
// the refusal of a rank-deficient or ill-conditioned segment.
gear_sim::Status IntegralMethod::solveLocals(SegmentRecord* rec) const {
  if (n_local_ == 0) return {};
  const int q = static_cast<int>(columns_.size());
  double cond = 0.0;
  const bool ok = solveEquilibrated(rec->gram.topLeftCorner(n_local_, n_local_),
                                    rec->gram.block(0, q, n_local_, 1), options_.max_condition,
                                    &rec->local_solution, &rec->local_inverse, &cond);
  rec->estimate.condition = cond;
  if (ok) return {};
  rec->local_inverse.resize(0, 0);
  rec->local_solution.resize(0);
  std::ostringstream m;
  m << "rank deficient or ill-conditioned (condition " << cond << " > " << options_.max_condition
    << ")";
  return gear_sim::Status::notIdentifiable(m.str(), "max_condition");
}

IdentificationResult IntegralMethod::finish() const { return finishRange(0, segments_.size()); }

// The shared unknowns of segments [s_begin, s_end): each segment's locals eliminated (Schur
// complement), the reduced system accumulated and solved; per segment the inverse of its local
// block (for the back-substitution).
struct IntegralMethod::SharedSolution {
  struct Local {
    // The inverse of the local block: the segment record's (addSegment's solve; not copied)
    // when `record` is set, else `own`.
    const Eigen::MatrixXd* record = nullptr;
    Eigen::MatrixXd own;
    bool ok = false;
    const Eigen::MatrixXd& Gll_inv() const { return record != nullptr ? *record : own; }
  };
  std::vector<Local> locals;  // per segment of the range
  Eigen::VectorXd g;          // shared unknowns
  Eigen::MatrixXd Ainv;       // inverse of the reduced normal matrix
  bool ok = true;
  double cond = 1.0;
  std::string reason;    // why not ok
  long dof = 0;          // residual degrees of freedom over the identifiable segments
  double sigma2 = kNaN;  // residual variance of the shared problem (ns > 0 and ok)
};

// One segment's unknowns (locals, then shared) and their covariance; empty if not identified.
struct IntegralMethod::SegmentParams {
  Eigen::VectorXd theta;  // q
  Eigen::MatrixXd cov;    // q x q
};

IntegralMethod::SharedSolution IntegralMethod::solveShared(size_t s_begin, size_t s_end) const {
  const int q = static_cast<int>(columns_.size());
  const int nl = n_local_, ns = n_shared_;
  SharedSolution sh;
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(ns, ns);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(ns);
  double rss_total = 0.0;
  sh.locals.resize(s_end - s_begin);
  for (size_t i = s_begin; i < s_end; ++i) {
    const SegmentRecord& rec = segments_[i];
    if (!rec.estimate.identifiable) continue;
    const Eigen::MatrixXd& G = rec.gram;
    SharedSolution::Local& L = sh.locals[i - s_begin];
    Eigen::VectorXd own_xl;
    const Eigen::VectorXd* xl = &own_xl;
    double cond = 0.0;
    if (nl > 0 && rec.local_inverse.rows() == nl) {
      // addSegment's solve (the same call, which passed the stricter max_condition).
      L.record = &rec.local_inverse;
      xl = &rec.local_solution;
    } else if (!solveEquilibrated(G.topLeftCorner(nl, nl), G.block(0, q, nl, 1), 1e300, &own_xl,
                                  &L.own, &cond)) {
      continue;
    }
    L.ok = true;
    if (ns == 0) continue;  // (the shared problem's sums below are of zero size)
    const Eigen::MatrixXd Gsl = G.block(nl, 0, ns, nl);
    A += G.block(nl, nl, ns, ns) - Gsl * L.Gll_inv() * Gsl.transpose();
    rhs += G.block(nl, q, ns, 1) - Gsl * *xl;
    rss_total += std::max(G(q, q) - G.row(q).head(nl).dot(*xl), kRssFloor * G(q, q));
    sh.dof += rec.rows - 2L * rec.windows - nl;
  }
  sh.g = Eigen::VectorXd::Zero(ns);
  sh.Ainv = Eigen::MatrixXd::Zero(ns, ns);
  if (ns > 0) {
    sh.dof -= ns;
    if (sh.dof < 1) {
      sh.ok = false;
      sh.reason = "too few samples over the identifiable segments";
    } else if (!solveEquilibrated(A, rhs, options_.max_condition, &sh.g, &sh.Ainv, &sh.cond)) {
      sh.ok = false;
      std::ostringstream m;
      m << "rank deficient or ill-conditioned (condition " << sh.cond << ")";
      if (options_.model == DampingModel::LoadLaw) {
        // The usual cause: a constant load leaves c1 undetermined (held-out sweeps: 5 of 40
        // load_law records, which said only the condition number).
        double lo = kNaN, hi = kNaN;
        for (size_t i = s_begin; i < s_end; ++i) {
          const SegmentEstimate& e = segments_[i].estimate;
          if (!e.identifiable || !std::isfinite(e.mean_torque)) continue;
          lo = std::isnan(lo) ? e.mean_torque : std::min(lo, e.mean_torque);
          hi = std::isnan(hi) ? e.mean_torque : std::max(hi, e.mean_torque);
        }
        if (std::isfinite(lo) && !(hi - lo > 1e-6 * std::max(std::abs(lo), std::abs(hi))))
          m << ": the load law needs a load that varies over the analysed range (the segments' "
               "mean torques are all "
            << lo << " N*m); with a constant load use the constant model";
      }
      sh.reason = m.str();
    } else {
      rss_total -= rhs.dot(sh.g);
    }
  }
  sh.sigma2 = (ns > 0 && sh.ok) ? std::max(rss_total, 0.0) / static_cast<double>(sh.dof) : kNaN;
  return sh;
}

// Per-segment parameters and covariances by back-substitution of the shared unknowns, and
// omega0 = sqrt(mean K): from the data (known) or the identified stiffness.
std::vector<IntegralMethod::SegmentParams> IntegralMethod::segmentParams(size_t s_begin,
                                                                         size_t s_end,
                                                                         const SharedSolution& sh,
                                                                         double* omega0) const {
  const int q = static_cast<int>(columns_.size());
  const int nl = n_local_, ns = n_shared_;
  double k_int = 0.0, dur = 0.0;
  std::vector<SegmentParams> params(s_end - s_begin);
  for (size_t i = s_begin; i < s_end; ++i) {
    const SegmentRecord& rec = segments_[i];
    const SharedSolution::Local& L = sh.locals[i - s_begin];
    if (!rec.estimate.identifiable || !L.ok || (ns > 0 && !sh.ok)) continue;
    const Eigen::MatrixXd& G = rec.gram;
    SegmentParams& p = params[i - s_begin];
    p.theta.resize(q);
    if (ns == 0) {
      // Local unknowns only: the general expressions below with their zero-size terms dropped
      // (the same values, without the temporaries).
      p.theta.noalias() = L.Gll_inv() * G.block(0, q, nl, 1);
      // The residual sum from the Gram matrix cancels to rounding when the fit is near exact:
      // floor it at the rounding level instead of reporting a zero standard error.
      const double rss = std::max(G(q, q) - G.row(q).head(nl).dot(p.theta), kRssFloor * G(q, q));
      p.cov = (rss / static_cast<double>(rec.rows - 2L * rec.windows - nl)) * L.Gll_inv();
    } else {
      const Eigen::MatrixXd Gls = G.block(0, nl, nl, ns);
      const Eigen::VectorXd xl = L.Gll_inv() * (G.block(0, q, nl, 1) - Gls * sh.g);
      p.theta.head(nl) = xl;
      p.theta.tail(ns) = sh.g;
      const double sigma2 = sh.sigma2;
      const Eigen::MatrixXd B = L.Gll_inv() * Gls;  // locals' dependence on the shared unknowns
      p.cov = Eigen::MatrixXd::Zero(q, q);
      p.cov.topLeftCorner(nl, nl) = sigma2 * (L.Gll_inv() + B * sh.Ainv * B.transpose());
      p.cov.block(0, nl, nl, ns) = -sigma2 * B * sh.Ainv;
      p.cov.block(nl, 0, ns, nl) = p.cov.block(0, nl, nl, ns).transpose();
      p.cov.bottomRightCorner(ns, ns) = sigma2 * sh.Ainv;
    }
    // Mean normalised stiffness over the segment.
    double kmean = kNaN;
    const int cK0 = columnIndex(Column::StiffK0), cDK = columnIndex(Column::StiffDK);
    if (options_.formulation == Formulation::Known && rec.duration > 0.0) {
      kmean = rec.k_integral / rec.duration;
    } else if (cK0 >= 0) {
      kmean = p.theta[cK0] + (cDK >= 0 ? p.theta[cDK] * rec.mean_state : 0.0);
    } else if (const int cB = columnIndex(Column::StiffBasis); cB >= 0) {
      kmean = 0.0;
      for (int k = 0; k < n_basis_; ++k) kmean += p.theta[cB + k] * rec.basis_mean[k];
    }
    if (std::isfinite(kmean)) k_int += kmean * rec.duration, dur += rec.duration;
  }
  *omega0 = dur > 0.0 && k_int > 0.0 ? std::sqrt(k_int / dur)
                                     : std::sqrt(gear_.mean_stiffness / gear_.equivalent_mass);
  return params;
}

namespace {
// C, its standard deviation, c and xi of an estimate.
void fillC(SegmentEstimate* e, double C, double var, double me, double omega0) {
  e->C = C;
  e->C_std = std::sqrt(std::max(var, 0.0));
  e->c = coefficientFromC(C, me);
  e->xi = ratioFromC(C, omega0);
}
}  // namespace

// The stiffness of an identified segment: k_min/k_max of the two-level model, or the
// identified curve of a greybox shape and its extremes over a mesh cycle (for the tables).
void IntegralMethod::stiffnessEstimate(const SegmentParams& p, SegmentEstimate* e) const {
  const double me = gear_.equivalent_mass;
  const int cK0 = columnIndex(Column::StiffK0), cDK = columnIndex(Column::StiffDK);
  if (cK0 >= 0) {
    const double k0 = p.theta[cK0];
    if (cDK >= 0) {
      const double dk = p.theta[cDK];
      e->k_min = me * k0;
      e->k_max = me * (k0 + dk);
      e->k_min_std = me * std::sqrt(std::max(p.cov(cK0, cK0), 0.0));
      e->k_max_std =
          me * std::sqrt(std::max(p.cov(cK0, cK0) + p.cov(cDK, cDK) + 2.0 * p.cov(cK0, cDK), 0.0));
    } else {
      e->k_min = e->k_max = me * k0;
      e->k_min_std = e->k_max_std = me * std::sqrt(std::max(p.cov(cK0, cK0), 0.0));
    }
  }
  if (const int cB = columnIndex(Column::StiffBasis); cB >= 0) {
    e->stiffness_curve.resize(n_basis_);
    e->stiffness_curve_std.resize(n_basis_);
    for (int k = 0; k < n_basis_; ++k) {
      e->stiffness_curve[k] = me * p.theta[cB + k];
      e->stiffness_curve_std[k] = me * std::sqrt(std::max(p.cov(cB + k, cB + k), 0.0));
    }
    constexpr int kGrid = 720;
    std::vector<double> b(n_basis_);
    e->k_min = std::numeric_limits<double>::infinity();
    e->k_max = -e->k_min;
    for (int g = 0; g < kGrid; ++g) {
      options_.stiffness_shape.basis(static_cast<double>(g) / kGrid, b.data());
      double k = 0.0;
      for (int j = 0; j < n_basis_; ++j) k += e->stiffness_curve[j] * b[j];
      e->k_min = std::min(e->k_min, k), e->k_max = std::max(e->k_max, k);
    }
  }
}

// One segment's estimate from its parameters; its windows' nuisance estimates (for the modeled
// response) appended to `windows`.
SegmentEstimate IntegralMethod::segmentEstimate(const SegmentRecord& rec, const SegmentParams& p,
                                                const SharedSolution& sh, double omega0,
                                                std::vector<WindowEstimate>* windows) const {
  const int q = static_cast<int>(columns_.size());
  const double me = gear_.equivalent_mass;
  const int cC = columnIndex(Column::DampC), cL = columnIndex(Column::DampLoad);
  SegmentEstimate e = rec.estimate;
  if (e.identifiable && p.theta.size() == 0) {
    e.identifiable = false;
    e.reason = (n_shared_ > 0 && !sh.ok) ? sh.reason : "rank deficient";
  }
  if (!e.identifiable) {
    e.C = e.C_std = e.c = e.xi = kNaN;
    e.k_min = e.k_max = e.k_min_std = e.k_max_std = kNaN;
    return e;
  }
  if (cL >= 0) {  // load law: C at the segment's mean torque
    const double T = rec.mean_torque;
    const double var = p.cov(cC, cC) + T * T * p.cov(cL, cL) + 2.0 * T * p.cov(cC, cL);
    fillC(&e, p.theta[cC] + p.theta[cL] * T, var, me, omega0);
  } else {
    fillC(&e, p.theta[cC], p.cov(cC, cC), me, omega0);
  }
  stiffnessEstimate(p, &e);
  const int cF = columnIndex(Column::ForceConst);
  if (cF >= 0) {
    e.forcing = p.theta[cF];
  } else if (options_.formulation == Formulation::Legacy) {
    e.forcing = legacy_fbar_;
  }
  // RMS residual of the integral equations at the estimate (shared unknowns included).
  const Eigen::MatrixXd& G = rec.gram;
  const double rss =
      G(q, q) - 2.0 * p.theta.dot(G.col(q).head(q)) + p.theta.dot(G.topLeftCorner(q, q) * p.theta);
  e.residual_rms =
      std::sqrt(std::max(rss, kRssFloor * G(q, q)) / static_cast<double>(std::max(rec.rows, 1L)));
  // Windows: nuisance estimates for the modeled response.
  for (const WindowRecord& w : rec.window_records) {
    double m = w.mean[q], sl = w.slope[q];
    for (int c = 0; c < q; ++c) m -= p.theta[c] * w.mean[c], sl -= p.theta[c] * w.slope[c];
    const double half = 0.5 * static_cast<double>(w.rows - 1);
    WindowEstimate we;
    we.t_start = w.t_start;
    we.t_end = w.t_end;
    we.alpha = sl / w.dt;
    we.y_T = m - sl * half;
    double CT = p.theta[cC];
    if (cL >= 0) CT += p.theta[cL] * w.torque_T;
    we.velocity = we.alpha - CT * we.y_T;
    windows->push_back(we);
  }
  return e;
}

// The constant model's and the load law's estimates from the shared unknowns.
void IntegralMethod::sharedSummaries(const SharedSolution& sh, double omega0,
                                     IdentificationResult* res) const {
  const int nl = n_local_;
  const double me = gear_.equivalent_mass;
  const int cC = columnIndex(Column::DampC), cL = columnIndex(Column::DampLoad);
  const int cK0 = columnIndex(Column::StiffK0);
  if (options_.model == DampingModel::Constant) {
    SegmentEstimate c;
    if (!res->segments.empty()) {
      c.t_start = res->segments.front().t_start;
      c.t_end = res->segments.back().t_end;
    }
    c.identifiable = sh.ok && sh.dof > 0;
    c.reason = sh.reason;
    c.condition = sh.cond;
    for (const auto& r : segments_) c.samples += r.rows, c.windows += r.windows;
    if (c.identifiable && cC >= nl) {
      fillC(&c, sh.g[cC - nl], sh.sigma2 * sh.Ainv(cC - nl, cC - nl), me, omega0);
      if (cK0 >= nl) {
        c.k_min = c.k_max = me * sh.g[cK0 - nl];
        c.k_min_std = c.k_max_std =
            me * std::sqrt(std::max(sh.sigma2 * sh.Ainv(cK0 - nl, cK0 - nl), 0.0));
      }
    } else {
      c.identifiable = false;
      if (c.reason.empty()) c.reason = "no identifiable segment";
    }
    res->constant = c;
  }
  if (options_.model == DampingModel::LoadLaw) {
    LoadLawEstimate l;
    l.identifiable = sh.ok && sh.dof > 0;
    l.reason = sh.reason;
    if (l.identifiable) {
      const int a = cC - nl, b = cL - nl;
      l.c0 = coefficientFromC(sh.g[a], me);
      l.c1 = coefficientFromC(sh.g[b], me);
      l.c0_std = coefficientFromC(std::sqrt(std::max(sh.sigma2 * sh.Ainv(a, a), 0.0)), me);
      l.c1_std = coefficientFromC(std::sqrt(std::max(sh.sigma2 * sh.Ainv(b, b), 0.0)), me);
    } else if (l.reason.empty()) {
      l.reason = "no identifiable segment";
    }
    res->load_law = l;
  }
}

// The estimates of segments [s_begin, s_end): shared unknowns, per-segment parameters, each
// segment's estimate, then the shared models' summaries.
IdentificationResult IntegralMethod::finishRange(size_t s_begin, size_t s_end) const {
  IdentificationResult res;
  res.formulation = options_.formulation;
  res.model = options_.model;
  res.stiffness_shape = options_.stiffness_shape;
  res.equivalent_mass = gear_.equivalent_mass;
  res.window_length = window_length_;
  const SharedSolution sh = solveShared(s_begin, s_end);
  double omega0 = kNaN;
  const std::vector<SegmentParams> params = segmentParams(s_begin, s_end, sh, &omega0);
  res.omega0 = omega0;
  size_t n_windows = 0;
  for (size_t i = s_begin; i < s_end; ++i) n_windows += segments_[i].window_records.size();
  res.windows.reserve(n_windows);
  res.segments.reserve(s_end - s_begin);
  for (size_t i = s_begin; i < s_end; ++i)
    res.segments.push_back(
        segmentEstimate(segments_[i], params[i - s_begin], sh, omega0, &res.windows));
  sharedSummaries(sh, omega0, &res);
  if (unlocated_switches_ > 0)
    res.warnings.push_back(switchesUnlocatedWarning(unlocated_switches_));
  return res;
}

// ----------------------------------------------------------------------------------------------

}  // namespace gear_damping_id
