// Chunk sequencing and segment assembly for the live nodes (see stream_assembler.hpp).
#include "gear_damping_id/stream_assembler.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace gear_damping_id {

namespace {

constexpr double kIndexEps = 1e-3;       // as segmentRanges: boundaries within 1e-3 of a sample
constexpr double kRateTolerance = 1e-9;  // relative sample-rate change that rejects a chunk
constexpr size_t kRecentGaps = 64;       // gaps remembered to tell late chunks from duplicates
constexpr std::uint64_t kNoEnd = std::numeric_limits<std::uint64_t>::max();
// Largest accepted global index: 2^52, so index/time arithmetic in doubles stays exact (142
// years at 1 MHz). Segments must hold at least kMinSegmentSamples samples at the stream's rate.
constexpr std::uint64_t kMaxIndex = std::uint64_t{1} << 52;
constexpr double kMinSegmentSamples = 4.0;
// No acquisition samples faster than 1 THz; the cap also keeps every time-to-index product of
// an analysed range (t_start, t_end up to years) far inside the 64-bit index range.
constexpr double kMaxSampleRate = 1e12;  // [Hz]
constexpr size_t kScaleChunks = 16;      // accepted chunks whose largest |value| form the scale

enum Channel : unsigned { kStiffness = 1, kTorque = 2, kState = 4, kPhase = 8 };

// The five channels of a sample copy as pointers (null when absent), into any view type.
template <class View, class Copy>
void pointChannels(const Copy& c, View* v) {
  auto ptr = [](const std::vector<double>& x) { return x.empty() ? nullptr : x.data(); };
  v->dte = ptr(c.dte);
  v->stiffness = ptr(c.stiffness);
  v->torque = ptr(c.torque);
  v->mesh_state = ptr(c.mesh_state);
  v->mesh_phase = ptr(c.mesh_phase);
}

}  // namespace

const char* toString(ChunkStatus s) {
  switch (s) {
    case ChunkStatus::Accepted:
      return "accepted";
    case ChunkStatus::Held:
      return "held for reordering";
    case ChunkStatus::Duplicate:
      return "duplicate";
    case ChunkStatus::Late:
      return "late (after its gap)";
    case ChunkStatus::RejectedNonFinite:
      return "rejected: NaN/Inf";
    case ChunkStatus::RejectedRate:
      return "rejected: sample rate changed";
    case ChunkStatus::RejectedMalformed:
      return "rejected: malformed";
    case ChunkStatus::RejectedValue:
      return "rejected: implausible value";
    case ChunkStatus::Suspect:
      return "implausible index jump (held until the next chunk)";
  }
  return "?";
}

gear_sim::OptionStatus StreamOptions::check() const {
  auto bad = [](const std::string& field, const auto& value, const std::string& rule) {
    return gear_sim::violated("StreamOptions", field, value, rule);
  };
  if (!(segment_length >= 0.0))
    return bad("segment_length", segment_length, "must be >= 0 [s] (0 or .inf = whole run)");
  if (std::isnan(t_start)) return bad("t_start", t_start, "must be a number [s]");
  if (!(t_end > t_start))
    return bad("t_start", t_start, "must be < t_end = " + gear_sim::formatNumber(t_end) + " [s]");
  if (reorder_chunks < 0 || reorder_chunks > 100000)
    return bad("reorder_chunks", reorder_chunks, "must be in [0, 100000]");
  if (context < 0 || context > 1000)
    return bad("context", context, "must be in [0, 1000] [samples]");
  if (!(max_jump > 0.0)) return bad("max_jump", max_jump, "must be > 0 [s] (.inf: no jump rule)");
  if (!(magnitude_factor == 0.0 || (magnitude_factor >= 10.0 && std::isfinite(magnitude_factor))))
    return bad("magnitude_factor", magnitude_factor, "must be 0 (off) or finite >= 10");
  if (!(max_abs_dte > 0.0)) return bad("max_abs_dte", max_abs_dte, "must be > 0 [m]");
  return {};
}

SignalView StreamSegment::view() const {
  SignalView v;
  v.t0 = static_cast<double>(first_index) / sample_rate;
  v.dt = 1.0 / sample_rate;
  v.n = static_cast<Eigen::Index>(dte.size());
  pointChannels(*this, &v);
  return v;
}

StreamAssembler::StreamAssembler(const StreamOptions& options) : options_(options) {}

StreamAssembler::Held StreamAssembler::Held::copyOf(const ChunkData& c) {
  Held h;
  h.sample_rate = c.sample_rate;
  h.mask = channelMask(c);
  auto copy = [&](const double* p, std::vector<double>* v) {
    if (p) v->assign(p, p + c.n);
  };
  copy(c.dte, &h.dte);
  copy(c.stiffness, &h.stiffness);
  copy(c.torque, &h.torque);
  copy(c.mesh_state, &h.mesh_state);
  copy(c.mesh_phase, &h.mesh_phase);
  return h;
}

ChunkData StreamAssembler::Held::chunk(std::uint64_t first_index) const {
  ChunkData c;
  c.first_index = first_index;
  c.sample_rate = sample_rate;
  c.n = dte.size();
  pointChannels(*this, &c);
  return c;
}

void StreamAssembler::reset() {
  counters_ = StreamCounters();
  rate_ = 0.0;
  mask_ = 0;
  have_run_ = seen_any_ = false;
  next_index_ = seg_begin_ = 0;
  epoch_ = 0;
  run_ = Buffer();
  held_.clear();
  recent_gaps_.clear();
  ready_.clear();
  recent_rejected_.clear();
  for (auto& r : recent_max_) r.clear();
  have_suspect_ = false;
  suspect_ = Held();
}

unsigned StreamAssembler::channelMask(const ChunkData& c) {
  return (c.stiffness ? kStiffness : 0u) | (c.torque ? kTorque : 0u) |
         (c.mesh_state ? kState : 0u) | (c.mesh_phase ? kPhase : 0u);
}

bool StreamAssembler::wholeRun() const {
  return !(options_.segment_length > 0.0) || !std::isfinite(options_.segment_length);
}

std::uint64_t StreamAssembler::firstAnalysed() const {
  if (!(options_.t_start > 0.0)) return 0;
  const double first = std::ceil(options_.t_start * rate_ - kIndexEps);
  return first >= 1.8e19 ? kNoEnd : static_cast<std::uint64_t>(first);
}

std::uint64_t StreamAssembler::endAnalysed() const {
  if (!std::isfinite(options_.t_end)) return kNoEnd;
  if (options_.t_end < 0.0) return 0;
  const double last = std::floor(options_.t_end * rate_ + kIndexEps);
  if (last >= 1.8e19) return kNoEnd;
  return static_cast<std::uint64_t>(last) + 1;
}

std::uint64_t StreamAssembler::boundary(long i) const {
  const double t_first = static_cast<double>(firstAnalysed()) / rate_;
  const double t = t_first + static_cast<double>(i) * options_.segment_length;
  const double g = std::ceil(t * rate_ - kIndexEps);
  return g <= 0.0 ? 0 : g >= 1.8e19 ? kNoEnd : static_cast<std::uint64_t>(g);
}

long StreamAssembler::segmentOf(std::uint64_t g) const {
  if (wholeRun()) return 0;
  const double t_first = static_cast<double>(firstAnalysed()) / rate_;
  const double x = (static_cast<double>(g) / rate_ - t_first) / options_.segment_length;
  long i = x > 0.0 ? static_cast<long>(std::floor(x)) : 0;
  while (boundary(i + 1) <= g) ++i;
  while (i > 0 && boundary(i) > g) --i;
  return i;
}

std::uint64_t StreamAssembler::segmentEnd(long i) const {
  const std::uint64_t end = endAnalysed();
  if (wholeRun()) return end;
  const std::uint64_t e = boundary(i + 1);
  if (e >= end) return end;
  // A final partial segment shorter than half dT joins this one (segmentRanges does the same).
  if (end != kNoEnd && boundary(i + 2) >= end &&
      static_cast<double>(end - e) < 0.5 * options_.segment_length * rate_) {
    return end;
  }
  return e;
}

bool StreamAssembler::inRecentGap(std::uint64_t a, std::uint64_t b) const {
  for (const auto& g : recent_gaps_) {
    if (a < g.second && b > g.first) return true;
  }
  return false;
}

ChunkStatus StreamAssembler::reject(ChunkStatus status, const ChunkData& c,
                                    unsigned long* counter) {
  ++*counter;
  counters_.samples_rejected += c.n;
  // Remembered so that a gap over these indices is attributed to the rejection.
  recent_rejected_.emplace_back(c.first_index, c.first_index + c.n);
  if (recent_rejected_.size() > kRecentGaps) recent_rejected_.pop_front();
  return status;
}

gear_sim::Status StreamAssembler::checkPlausible(const ChunkData& c) const {
  std::ostringstream m;
  if (c.mesh_state) {
    for (size_t i = 0; i < c.n; ++i) {
      if (c.mesh_state[i] != 0.0 && c.mesh_state[i] != 1.0) {
        m << "chunk at index " << c.first_index << ": mesh_state[" << i << "] = " << c.mesh_state[i]
          << " (must be 0 or 1)";
        return gear_sim::Status::invalidInput(m.str(), "mesh_state");
      }
    }
  }
  const std::array<std::pair<const double*, const char*>, 3> channels = {
      {{c.dte, "dte"}, {c.stiffness, "stiffness"}, {c.torque, "torque"}}};
  for (size_t k = 0; k < channels.size(); ++k) {
    const double* p = channels[k].first;
    if (p == nullptr) continue;
    double peak = 0.0;
    for (size_t i = 0; i < c.n; ++i) peak = std::max(peak, std::abs(p[i]));
    if (k == 0 && peak > options_.max_abs_dte) {
      m << "chunk at index " << c.first_index << ": |dte| up to " << peak
        << " m (above max_abs_dte " << options_.max_abs_dte << " m)";
      return gear_sim::Status::invalidInput(m.str(), "dte");
    }
    if (options_.magnitude_factor > 0.0 && !recent_max_[k].empty()) {
      std::vector<double> r(recent_max_[k].begin(), recent_max_[k].end());
      std::nth_element(r.begin(), r.begin() + static_cast<std::ptrdiff_t>(r.size() / 2), r.end());
      const double scale = r[r.size() / 2];
      if (scale > 0.0 && peak > options_.magnitude_factor * scale) {
        m << "chunk at index " << c.first_index << ": |" << channels[k].second << "| up to " << peak
          << ", " << peak / scale << " times the stream's running scale " << scale
          << " (magnitude_factor " << options_.magnitude_factor << ")";
        return gear_sim::Status::invalidInput(m.str(), channels[k].second);
      }
    }
  }
  return {};
}

void StreamAssembler::updateScales(const ChunkData& c) {
  const double* channels[] = {c.dte, c.stiffness, c.torque};
  for (size_t k = 0; k < 3; ++k) {
    if (channels[k] == nullptr) continue;
    double peak = 0.0;
    for (size_t i = 0; i < c.n; ++i) peak = std::max(peak, std::abs(channels[k][i]));
    recent_max_[k].push_back(peak);
    if (recent_max_[k].size() > kScaleChunks) recent_max_[k].pop_front();
  }
}

bool StreamAssembler::isJump(const ChunkData& c) const {
  if (!seen_any_ || !std::isfinite(options_.max_jump)) return false;
  const double by_time = options_.max_jump * rate_;
  const double by_reorder =
      static_cast<double>(options_.reorder_chunks + 1) * static_cast<double>(c.n);
  const double j = std::max(by_time, by_reorder);
  const double first = static_cast<double>(c.first_index);
  const double next = static_cast<double>(next_index_);
  return first - next > j || next - (first + static_cast<double>(c.n)) > j;
}

void StreamAssembler::dropSuspect() {
  if (!have_suspect_) return;
  have_suspect_ = false;
  ChunkData c;
  c.first_index = suspect_first_;
  c.n = suspect_.dte.size();
  reject(ChunkStatus::RejectedValue, c, &counters_.rejected_jump);
  counters_.samples_suspect_dropped += c.n;
  suspect_ = Held();
}

void StreamAssembler::decideSuspect(const ChunkData& c) {
  if (!have_suspect_) return;
  const std::uint64_t end = suspect_first_ + suspect_.dte.size();
  if (c.first_index != end || channelMask(c) != suspect_.mask ||
      std::abs(c.sample_rate - suspect_.sample_rate) > kRateTolerance * suspect_.sample_rate) {
    dropSuspect();
    return;
  }
  // Confirmed: the stream jumped. Finish the old record; a new one starts at the suspect.
  have_suspect_ = false;
  releaseHeld(true);
  closeRun();
  ++counters_.jump_records;
  ++epoch_;
  recent_gaps_.clear();
  next_index_ = suspect_first_;
  const Held h = std::move(suspect_);
  suspect_ = Held();
  const ChunkData s = h.chunk(suspect_first_);
  updateScales(s);
  append(s, 0);
}

// push's first check: a chunk the assembler cannot place at all (no samples, no dte, a rate that
// is not a positive finite number or above 1e12 Hz, an index beyond 2^52, fewer than 4 samples per
// segment): InvalidInput saying why, and counted.
gear_sim::Status StreamAssembler::checkWellFormed(const ChunkData& c) {
  const bool short_segments =
      !wholeRun() && !(options_.segment_length * c.sample_rate >= kMinSegmentSamples);
  const bool rate_too_high = c.sample_rate > kMaxSampleRate;
  if (!(c.n == 0 || c.dte == nullptr || !std::isfinite(c.sample_rate) || !(c.sample_rate > 0.0) ||
        rate_too_high || c.n > kMaxIndex || c.first_index > kMaxIndex - c.n || short_segments))
    return {};
  ++counters_.rejected_malformed;
  if (c.dte != nullptr && c.n <= kMaxIndex) {
    counters_.samples_received += c.n;
    counters_.samples_rejected += c.n;
  }
  std::ostringstream m;
  m << "chunk at index " << c.first_index << ": " << c.n << " samples, sample_rate "
    << c.sample_rate << " Hz" << (c.dte == nullptr ? ", no dte" : "")
    << (c.n > kMaxIndex || c.first_index > kMaxIndex - c.n ? ", index beyond 2^52" : "")
    << (short_segments ? ", fewer than 4 samples per segment" : "")
    << (rate_too_high ? ", sample rate above 1e12 Hz" : "");
  return gear_sim::Status::invalidInput(m.str());
}

// The first non-finite sample of any channel the chunk has: InvalidInput naming it (field: the
// channel).
gear_sim::Status StreamAssembler::checkFinite(const ChunkData& c) const {
  const std::pair<const double*, const char*> channels[] = {{c.dte, "dte"},
                                                            {c.stiffness, "stiffness"},
                                                            {c.torque, "torque"},
                                                            {c.mesh_state, "mesh_state"},
                                                            {c.mesh_phase, "mesh_phase"}};
  for (const auto& ch : channels) {
    if (ch.first == nullptr) continue;
    for (size_t i = 0; i < c.n; ++i) {
      if (!std::isfinite(ch.first[i])) {
        std::ostringstream m;
        m << "chunk at index " << c.first_index << ": " << ch.second << "[" << i
          << "] = " << ch.first[i];
        return gear_sim::Status::invalidInput(m.str(), ch.second);
      }
    }
  }
  return {};
}

// The publisher started over (index 0 after later ones): finish the old record, start a new
// epoch.
void StreamAssembler::startOver(std::string* why) {
  releaseHeld(true);
  closeRun();
  ++counters_.restarts;
  ++epoch_;
  std::ostringstream m;
  m << "restart: index 0 after index " << next_index_ - 1;
  *why = m.str();
  seen_any_ = false;
  rate_ = 0.0;
  recent_gaps_.clear();
}

// An implausible jump of the index: the chunk is held as a suspect until the next chunk shows a
// new record (it continues this one) or a glitch.
ChunkStatus StreamAssembler::holdSuspect(const ChunkData& c, std::string* why) {
  ++counters_.jumps;
  std::ostringstream m;
  m << "implausible index jump: chunk at index " << c.first_index << ", expected " << next_index_
    << " (" << (static_cast<double>(c.first_index) - static_cast<double>(next_index_)) / rate_
    << " s): held until the next chunk shows a new record (it continues this one) or a glitch";
  *why = m.str();
  have_suspect_ = true;
  suspect_first_ = c.first_index;
  suspect_ = Held::copyOf(c);
  return ChunkStatus::Suspect;
}

// A valid chunk of the current record, by where it falls: behind the expected index (late into
// a recent gap, or a duplicate), at or across it (appended, then the held chunks it frees), or
// ahead of it (held, waiting for the missing samples).
ChunkStatus StreamAssembler::place(const ChunkData& c, std::string* why) {
  const std::uint64_t end = c.first_index + c.n;
  if (end <= next_index_) {
    if (inRecentGap(c.first_index, end)) {
      ++counters_.late;
      counters_.samples_late += c.n;
      return ChunkStatus::Late;
    }
    ++counters_.duplicates;
    counters_.samples_duplicate += c.n;
    return ChunkStatus::Duplicate;
  }
  if (c.first_index <= next_index_) {
    if (c.first_index < next_index_) ++counters_.overlaps;
    if (!held_.empty()) ++counters_.out_of_order;  // it filled the hole before the held chunks
    append(c, static_cast<size_t>(next_index_ - c.first_index));
    releaseHeld(false);
    return ChunkStatus::Accepted;
  }
  if (held_.count(c.first_index) != 0) {
    ++counters_.duplicates;
    counters_.samples_duplicate += c.n;
    return ChunkStatus::Duplicate;
  }
  held_[c.first_index] = Held::copyOf(c);
  const unsigned long gaps_before = counters_.gaps;
  releaseHeld(false);
  if (counters_.gaps != gaps_before) {
    std::ostringstream m;
    m << "gap: " << recent_gaps_.back().second - recent_gaps_.back().first
      << " samples missing from index " << recent_gaps_.back().first;
    *why = m.str();
  }
  return ChunkStatus::Held;
}

ChunkStatus StreamAssembler::push(const ChunkData& c, std::string* detail) {
  std::string scratch;
  std::string& why = detail ? *detail : scratch;
  why.clear();
  ++counters_.chunks_received;
  // The input checks: a failed one classifies the chunk, its message is the detail.
  if (const gear_sim::Status s = checkWellFormed(c); !s.ok()) {
    why = s.message();
    return ChunkStatus::RejectedMalformed;
  }
  counters_.samples_received += c.n;
  if (const gear_sim::Status s = checkFinite(c); !s.ok()) {
    why = s.message();
    return reject(ChunkStatus::RejectedNonFinite, c, &counters_.rejected_nonfinite);
  }
  if (const gear_sim::Status s = checkPlausible(c); !s.ok()) {
    why = s.message();
    return reject(ChunkStatus::RejectedValue, c, &counters_.rejected_value);
  }
  decideSuspect(c);  // a pending suspect is confirmed by this chunk or dropped
  if (seen_any_ && c.first_index == 0 && next_index_ > 0) startOver(&why);
  if (seen_any_ && std::abs(c.sample_rate - rate_) > kRateTolerance * rate_) {
    std::ostringstream m;
    m << "chunk at index " << c.first_index << ": sample_rate " << c.sample_rate
      << " Hz, stream at " << rate_ << " Hz";
    why = m.str();
    return reject(ChunkStatus::RejectedRate, c, &counters_.rejected_rate);
  }
  if (isJump(c)) return holdSuspect(c, &why);
  if (!seen_any_) {
    seen_any_ = true;
    rate_ = c.sample_rate;
    next_index_ = c.first_index;
  }
  updateScales(c);
  return place(c, &why);
}

void StreamAssembler::releaseHeld(bool force) {
  while (!held_.empty()) {
    auto it = held_.begin();
    const std::uint64_t first = it->first;
    const size_t n = it->second.dte.size();
    if (first + n <= next_index_) {  // became a duplicate meanwhile
      held_.erase(it);
      ++counters_.duplicates;
      counters_.samples_duplicate += n;
      continue;
    }
    if (first > next_index_) {
      if (!force && held_.size() <= static_cast<size_t>(options_.reorder_chunks)) break;
      // The missing samples are not coming: a gap. Never integrate across it.
      ++counters_.gaps;
      counters_.samples_missing += first - next_index_;
      std::uint64_t rejected = 0;  // the rejected indices in the gap
      for (const auto& r : recent_rejected_) {
        const std::uint64_t lo = std::max(r.first, next_index_), hi = std::min(r.second, first);
        if (hi > lo) rejected += hi - lo;
      }
      counters_.samples_missing_rejected += std::min(rejected, first - next_index_);
      recent_gaps_.emplace_back(next_index_, first);
      if (recent_gaps_.size() > kRecentGaps) recent_gaps_.pop_front();
      closeRun();
      next_index_ = first;
    }
    const Held h = std::move(it->second);
    held_.erase(it);
    append(h.chunk(first), static_cast<size_t>(next_index_ - first));
  }
}

void StreamAssembler::append(const ChunkData& c, size_t skip) {
  const unsigned m = channelMask(c);
  if (have_run_ && m != mask_) {
    ++counters_.channel_changes;
    closeRun();
  }
  if (!have_run_) {
    run_ = Buffer();
    run_.first = next_index_;
    seg_begin_ = next_index_;
    mask_ = m;
    have_run_ = true;
  }
  auto add = [&](const double* p, std::vector<double>* v) {
    if (p) v->insert(v->end(), p + skip, p + c.n);
  };
  add(c.dte, &run_.dte);
  add(c.stiffness, &run_.stiffness);
  add(c.torque, &run_.torque);
  add(c.mesh_state, &run_.mesh_state);
  add(c.mesh_phase, &run_.mesh_phase);
  next_index_ += c.n - skip;
  ++counters_.chunks_accepted;
  counters_.samples_accepted += c.n - skip;
  counters_.samples_duplicate += skip;
  emitReady(false);
}

void StreamAssembler::closeRun() {
  if (!have_run_) return;
  emitReady(true);
  have_run_ = false;
  run_ = Buffer();
}

void StreamAssembler::endOfStream() {
  dropSuspect();
  releaseHeld(true);
  closeRun();
}

void StreamAssembler::emitReady(bool closing) {
  const std::uint64_t ctx = static_cast<std::uint64_t>(options_.context);
  const std::uint64_t run_end = run_.first + run_.dte.size();
  const std::uint64_t first_analysed = firstAnalysed();
  const std::uint64_t end_analysed = endAnalysed();
  for (;;) {
    const std::uint64_t lo = std::max(seg_begin_, first_analysed);
    if (lo >= end_analysed || lo >= run_end) break;
    const long i = segmentOf(lo);
    const std::uint64_t se = segmentEnd(i);
    const bool complete = se != kNoEnd && run_end >= se && run_end - se >= ctx;
    if (!complete && !closing) break;
    const std::uint64_t piece_end = std::min(se, run_end);
    const std::uint64_t copy_lo = std::max(run_.first, lo >= ctx ? lo - ctx : 0);
    const std::uint64_t copy_hi = std::min(piece_end + ctx, run_end);
    StreamSegment s;
    s.first_index = copy_lo;
    s.sample_rate = rate_;
    s.begin = static_cast<Eigen::Index>(lo - copy_lo);
    s.end = static_cast<Eigen::Index>(piece_end - copy_lo);
    s.segment_number = i;
    s.partial = lo != (wholeRun() ? first_analysed : boundary(i)) || piece_end != se;
    s.epoch = epoch_;
    const size_t a = static_cast<size_t>(copy_lo - run_.first);
    const size_t b = static_cast<size_t>(copy_hi - run_.first);
    auto slice = [&](const std::vector<double>& v, std::vector<double>* out) {
      if (!v.empty())
        out->assign(v.begin() + static_cast<std::ptrdiff_t>(a),
                    v.begin() + static_cast<std::ptrdiff_t>(b));
    };
    slice(run_.dte, &s.dte);
    slice(run_.stiffness, &s.stiffness);
    slice(run_.torque, &s.torque);
    slice(run_.mesh_state, &s.mesh_state);
    slice(run_.mesh_phase, &s.mesh_phase);
    ++counters_.segments_emitted;
    if (s.partial) ++counters_.partial_segments;
    ready_.push_back(std::move(s));
    seg_begin_ = piece_end;
    if (piece_end < se) break;
  }
  // Drop what no future segment needs (keep the stencil context before the next segment;
  // nothing once the analysed range is over).
  const std::uint64_t next = std::max(seg_begin_, first_analysed);
  const std::uint64_t keep =
      next >= end_analysed ? run_end : std::max(run_.first, next >= ctx ? next - ctx : 0);
  const size_t drop =
      static_cast<size_t>(std::min<std::uint64_t>(keep - run_.first, run_.dte.size()));
  if (drop > 0) {
    auto erase = [&](std::vector<double>* v) {
      if (!v->empty()) v->erase(v->begin(), v->begin() + static_cast<std::ptrdiff_t>(drop));
    };
    erase(&run_.dte);
    erase(&run_.stiffness);
    erase(&run_.torque);
    erase(&run_.mesh_state);
    erase(&run_.mesh_phase);
    run_.first += drop;
  }
}

LossMonitor::Report LossMonitor::update(const StreamCounters& k, double now,
                                        const std::string& last_jump) {
  Report r;
  auto raise = [&](Level level, const std::string& text) {
    r.level = std::max(r.level, level);
    r.message += (r.message.empty() ? "" : "; ") + text;
  };
  // Changes whenever a sample is lost, rejected or late (a change detector, not a count).
  const unsigned long lost = k.samplesLost() + k.samples_late + k.samples_rejected;
  const bool loss = lost != last_lost_;
  last_lost_ = lost;
  if (loss) have_loss_ = true, last_loss_ = now;
  streak_ = loss ? streak_ + 1 : 0;
  if (streak_ >= kSustained) {
    raise(Level::Error, "sustained loss: samples lost in each of the last " +
                            std::to_string(kSustained) + " reports");
  } else if (have_loss_ && now - last_loss_ < kHold) {
    raise(Level::Warn, "samples lost (gap, rejected or late) in the last " +
                           std::to_string(static_cast<int>(kHold)) + " s");
  }
  if (k.jumps > 0) {
    raise(Level::Warn, "implausible index jumps since start/reset: " + std::to_string(k.jumps) +
                           (last_jump.empty() ? "" : " (last: " + last_jump + ")"));
  }
  const unsigned long events = k.duplicates + k.restarts + k.channel_changes;
  if (events != last_events_) {
    raise(Level::Warn, "stream events (duplicates/restarts/channel changes) since last report");
  }
  last_events_ = events;
  return r;
}

bool StreamAssembler::nextSegment(StreamSegment* out) {
  if (ready_.empty()) return false;
  *out = std::move(ready_.front());
  ready_.pop_front();
  return true;
}

}  // namespace gear_damping_id
