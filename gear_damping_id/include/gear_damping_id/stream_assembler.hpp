// Assembly of a live stream of sample chunks into damping segments (docs/method.md §6 "Topics",
// issue 6). No ROS: the nodes convert gear_damping/SignalChunk messages into ChunkData and feed
// them here; everything about sequencing lives in this class so it is unit-tested without roscore.
//
// Index and time convention: sample g of the stream (g = first_index + i of a chunk) is at
// t = g / sample_rate [s] (t = 0 at the start of the record), as in SignalChunk.
//
// Segments: boundaries at t_first + i*segment_length, i = 0, 1, ..., where t_first is the time
// of the first sample at or after options.t_start (sample 0 when t_start <= 0): segment i holds
// the samples g with ceil((t_first + i*dT)*fs - 1e-3) <= g < ceil((t_first + (i+1)*dT)*fs - 1e-3),
// exactly the ranges of gear_damping_id::segmentRanges for a record starting at sample 0. With a
// finite t_end, a final partial segment shorter than half dT joins the previous one (as offline).
// segment_length 0 or inf: one segment that closes only at a gap or at the end of the stream.
//
// Runs: a run is a contiguous stretch of accepted samples. A segment is emitted (nextSegment)
// once the run holds its samples plus `context` samples after it (IntegralMethod::addSegment may
// read up to two samples beyond a segment; giving it the same neighbours as the offline record
// keeps the live result equal to the offline one), or when the run closes early. A run closes at
// - a gap (missing indices, after waiting for up to `reorder_chunks` later chunks for the
//   missing one): the samples on either side are never integrated together; the part of the
//   segment before the gap and the part after it are emitted as separate (partial) segments;
// - a change of the set of channels present;
// - a restart (a chunk with first_index 0 after later samples: the publisher started over),
//   which also starts a new epoch: the consumer resets its estimates when the epoch changes;
// - endOfStream() (end of a bag, an idle publisher, or a trigger).
// Rejected (never enter a run, counted): chunks with a non-finite value in any channel present,
// implausible values (mesh_state other than 0 or 1; |dte| above options.max_abs_dte; a dte,
// stiffness or torque magnitude above options.magnitude_factor times the channel's running scale,
// the median of the largest |value| of the last 16 accepted chunks), a sample rate different
// from the run's (relative tolerance 1e-9), malformed chunks (no samples, sample rate not finite
// and > 0, an index beyond 2^52, fewer than 4 samples per segment at the chunk's rate). Ignored
// (counted): exact duplicates, chunks that arrive after their indices were declared a gap
// ("late"); a chunk overlapping accepted samples contributes only its new samples.
//
// Implausible index jumps (a DAQ counter glitch, a publisher restarted at a non-zero index): a
// chunk starting more than J = max(options.max_jump * sample_rate, (reorder_chunks + 1) * its
// size) samples after the expected index, or ending more than J before it (index 0 is a restart,
// above), is held aside as a suspect, not in the reorder buffer. The next chunk decides:
// - it continues the suspect (starts at the suspect's end): the stream really jumped. The old
//   record is finished and a new record (epoch) starts at the suspect, as for a restart;
// - anything else: the suspect was a glitch and is dropped (rejected, its samples counted);
// - endOfStream() drops a pending suspect (counted the same way).
// So one bad chunk never moves the expected index, and a stream that really jumped resumes after
// one chunk. Both outcomes are counted (jumps, jump_records, rejected_jump).
//
// Sample accounting (StreamCounters): every sample of every chunk given to push() ends up in
// exactly one of samples_accepted, samples_duplicate (already accepted: duplicate chunks and the
// overlapping part of trimmed chunks), samples_late, samples_rejected; a suspect counts once
// decided. Samples that never arrived show as missing indices: samples_missing (gaps), of which
// samples_missing_rejected were indices of rejected chunks. A subscriber-queue overflow or a
// transport loss therefore appears as samples_missing - samples_missing_rejected.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <deque>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "gear_damping_id/signal_view.hpp"
#include "gear_sim/option_status.hpp"
#include "gear_sim/status.hpp"

namespace gear_damping_id {

/// One chunk of consecutive samples (pointers valid during push only). Optional channels are
/// null when absent; every present channel holds n values.
struct ChunkData {
  std::uint64_t first_index = 0;       ///< global index of the first sample
  double sample_rate = 0.0;            ///< [Hz]
  size_t n = 0;                        ///< samples
  const double* dte = nullptr;         ///< [m] required
  const double* stiffness = nullptr;   ///< [N/m]
  const double* torque = nullptr;      ///< [N*m]
  const double* mesh_state = nullptr;  ///< [0/1]
  const double* mesh_phase = nullptr;  ///< [mesh cycles]
};

struct StreamOptions {
  /// Damping segment length dT [s]; 0 or inf: one segment per run (closed at a gap or the end).
  double segment_length = 1e-3;
  /// Analysed time range [s] (samples outside are ignored, apart from the stencil context).
  double t_start = -std::numeric_limits<double>::infinity();
  double t_end = std::numeric_limits<double>::infinity();
  /// Chunks held while waiting for a missing earlier chunk (out-of-order delivery) before the
  /// missing samples are declared a gap. 0: a missing index is a gap at once.
  int reorder_chunks = 8;
  /// Samples kept on either side of a segment for the quadrature stencils (2 = what the
  /// integral method reads).
  int context = 2;
  /// [s] index jumps larger than this (and than the reorder window) are implausible: see the
  /// header comment. > 0; .inf disables the rule.
  double max_jump = 0.5;
  /// A chunk whose largest |dte|, |stiffness| or |torque| exceeds this multiple of the channel's
  /// running scale is rejected as physically absurd. 0 disables the relative check; else >= 10.
  double magnitude_factor = 1e6;
  /// [m] |dte| above this is rejected whatever the running scale (a DTE is micrometres). > 0.
  double max_abs_dte = 1.0;
  /// The first rule broken: field, value and rule (gear_sim/option_status.hpp).
  gear_sim::OptionStatus check() const;  ///< ok, or the first rule broken (option_status.hpp)
};

/// What happened to a chunk given to push().
enum class ChunkStatus {
  Accepted,           ///< appended to the current run (possibly after trimming an overlap)
  Held,               ///< ahead of the expected index: held for reordering
  Duplicate,          ///< every sample already accepted: ignored
  Late,               ///< its samples were already declared missing (a gap): ignored
  RejectedNonFinite,  ///< NaN/Inf in a channel: rejected
  RejectedRate,       ///< sample rate differs from the stream's: rejected
  RejectedMalformed,  ///< no samples, no dte, bad sample rate or index: rejected
  RejectedValue,      ///< mesh_state not 0/1, or an absurd magnitude: rejected
  Suspect             ///< implausible index jump: held aside until the next chunk decides
};
const char* toString(ChunkStatus s);

/// Event counters since construction or reset().
struct StreamCounters {
  unsigned long chunks_received = 0;
  unsigned long chunks_accepted = 0;  ///< appended (incl. trimmed overlaps and released holds)
  unsigned long samples_accepted = 0;
  unsigned long gaps = 0;             ///< runs closed by missing indices
  unsigned long samples_missing = 0;  ///< samples in those gaps
  unsigned long duplicates = 0;
  unsigned long overlaps = 0;      ///< chunks partly overlapping accepted samples (trimmed)
  unsigned long late = 0;          ///< chunks arriving after their gap was declared
  unsigned long out_of_order = 0;  ///< chunks held and released in order
  unsigned long rejected_nonfinite = 0;
  unsigned long rejected_rate = 0;
  unsigned long rejected_malformed = 0;
  unsigned long rejected_value = 0;  ///< mesh_state not 0/1 or absurd magnitude
  unsigned long rejected_jump = 0;   ///< suspects (implausible jumps) dropped as glitches
  unsigned long jumps = 0;           ///< implausible index jumps seen (suspects)
  unsigned long jump_records = 0;    ///< suspects confirmed: new record (epoch) at the jump
  unsigned long restarts = 0;
  unsigned long channel_changes = 0;
  // Per-sample accounting (see the header comment).
  unsigned long samples_received = 0;          ///< samples in all chunks given to push()
  unsigned long samples_duplicate = 0;         ///< already accepted (duplicates, trimmed overlaps)
  unsigned long samples_late = 0;              ///< in late chunks
  unsigned long samples_rejected = 0;          ///< in rejected chunks (incl. dropped suspects)
  unsigned long samples_missing_rejected = 0;  ///< of samples_missing: indices of rejected chunks
  /// Samples lost to the estimator: indices never accepted (gaps) + dropped suspects' samples.
  unsigned long samplesLost() const { return samples_missing + samples_suspect_dropped; }
  /// Gap samples that no chunk brought, rejected or not (queue overflow, transport loss).
  unsigned long samplesNeverArrived() const {
    const unsigned long known = samples_missing_rejected + samples_late;
    return samples_missing > known ? samples_missing - known : 0;
  }
  unsigned long samples_suspect_dropped = 0;  ///< of samples_rejected: in dropped suspects
  unsigned long segments_emitted = 0;
  unsigned long partial_segments = 0;  ///< emitted shorter than dT (closed by a gap/restart/end)
};

/// The health of a stream for periodic reports (the nodes' diagnostics), from the counters:
/// - ERROR "sustained loss" when each of the last kSustained reports saw a loss;
/// - else WARN for kHold seconds after any loss (a sample lost, rejected or late);
/// - WARN from the first implausible index jump on (persistent until reset());
/// - WARN for one report after a duplicate, a restart or a channel change;
/// - OK otherwise. The message names every condition that holds.
class LossMonitor {
 public:
  enum class Level { Ok = 0, Warn = 1, Error = 2 };
  struct Report {
    Level level = Level::Ok;
    std::string message;  ///< "" when OK
  };
  static constexpr double kHold = 10.0;  ///< [s] a loss keeps the status WARN this long
  static constexpr int kSustained = 3;   ///< reports in a row with a loss: ERROR

  /// Called once per report with the counters and the time of the report [s] (any monotonic
  /// clock); `last_jump` describes the last implausible jump (may be empty).
  Report update(const StreamCounters& k, double now, const std::string& last_jump = "");
  void reset() { *this = LossMonitor(); }

 private:
  unsigned long last_lost_ = 0, last_events_ = 0;
  int streak_ = 0;
  bool have_loss_ = false;
  double last_loss_ = 0.0;
};

/// A segment ready for identification, with its own copy of the samples: samples [begin, end)
/// of view() are the segment, the rest (up to `context` on each side) stencil context.
struct StreamSegment {
  std::uint64_t first_index = 0;  ///< global index of view() sample 0
  double sample_rate = 0.0;       ///< [Hz]
  Eigen::Index begin = 0, end = 0;
  long segment_number = 0;  ///< i of the boundary grid (several partial pieces may share it)
  bool partial = false;     ///< shorter than its grid segment (a gap, restart or end cut it)
  unsigned long epoch = 0;  ///< restarts before this segment
  std::vector<double> dte, stiffness, torque, mesh_state, mesh_phase;  ///< empty = absent
  /// View with t0 = first_index / sample_rate, dt = 1 / sample_rate (global stream time).
  SignalView view() const;
};

class StreamAssembler {
 public:
  /// `options` must be valid.
  explicit StreamAssembler(const StreamOptions& options);

  /// Takes one chunk (see the header comment for the rules). `detail` (may be null) receives a
  /// human-readable reason for rejections, gaps and restarts ("" otherwise). Never throws on
  /// any content.
  ChunkStatus push(const ChunkData& chunk, std::string* detail = nullptr);

  /// End of the stream (or of a burst): held chunks are released (missing indices before them
  /// become gaps) and the current run closes, emitting its last, possibly partial, segment. A
  /// later chunk continuing at the next index starts a new run (not counted as a gap).
  void endOfStream();

  /// Pops the oldest ready segment; false if none.
  bool nextSegment(StreamSegment* out);
  size_t readySegments() const { return ready_.size(); }

  /// Forgets everything (runs, held chunks, ready segments, counters); keeps the options.
  void reset();

  const StreamCounters& counters() const { return counters_; }
  const StreamOptions& options() const { return options_; }
  unsigned long epoch() const { return epoch_; }
  /// Samples accepted in the current run and held chunks (for diagnostics).
  size_t bufferedSamples() const { return static_cast<size_t>(run_.dte.size()); }
  size_t heldChunks() const { return held_.size(); }
  /// An implausible jump waits for the next chunk (see the header comment).
  bool hasSuspect() const { return have_suspect_; }
  /// Global index expected next (valid once a chunk was accepted).
  std::uint64_t nextIndex() const { return next_index_; }
  double sampleRate() const { return rate_; }

 private:
  struct Buffer {  // the current run from global index `first` on
    std::uint64_t first = 0;
    std::vector<double> dte, stiffness, torque, mesh_state, mesh_phase;
  };
  struct Held {  // a chunk's own copy (reorder buffer, suspect)
    double sample_rate = 0.0;
    unsigned mask = 0;
    std::vector<double> dte, stiffness, torque, mesh_state, mesh_phase;
    static Held copyOf(const ChunkData& c);
    ChunkData chunk(std::uint64_t first_index) const;  // pointing into this copy
  };

  static unsigned channelMask(const ChunkData& c);
  ChunkStatus reject(ChunkStatus status, const ChunkData& c, unsigned long* counter);
  // push's named steps (stream_assembler.cpp): the input checks (ok, or InvalidInput naming the
  // channel), then the classification of a valid chunk (its ChunkStatus and detail).
  gear_sim::Status checkWellFormed(const ChunkData& c);
  gear_sim::Status checkFinite(const ChunkData& c) const;
  gear_sim::Status checkPlausible(const ChunkData& c) const;
  void startOver(std::string* why);
  ChunkStatus holdSuspect(const ChunkData& c, std::string* why);
  ChunkStatus place(const ChunkData& c, std::string* why);
  void updateScales(const ChunkData& c);
  bool isJump(const ChunkData& c) const;
  void decideSuspect(const ChunkData& next);
  void dropSuspect();
  void append(const ChunkData& c, size_t skip);
  void releaseHeld(bool force);
  void closeRun();
  void emitReady(bool closing);
  std::uint64_t firstAnalysed() const;     // first global index >= t_start
  std::uint64_t endAnalysed() const;       // one past the last index <= t_end (max if inf)
  std::uint64_t boundary(long i) const;    // start of grid segment i
  long segmentOf(std::uint64_t g) const;   // grid segment holding g
  std::uint64_t segmentEnd(long i) const;  // end of grid segment i (tail merge applied)
  bool wholeRun() const;
  bool inRecentGap(std::uint64_t a, std::uint64_t b) const;

  StreamOptions options_;
  StreamCounters counters_;
  double rate_ = 0.0;             // 0: not yet known
  unsigned mask_ = 0;             // channels present in the current run
  bool have_run_ = false;         // a run is open
  bool seen_any_ = false;         // a chunk was accepted since construction/reset/restart
  std::uint64_t next_index_ = 0;  // expected next global index
  std::uint64_t seg_begin_ = 0;   // first index not yet emitted in the current run
  unsigned long epoch_ = 0;
  Buffer run_;
  std::map<std::uint64_t, Held> held_;
  std::deque<std::pair<std::uint64_t, std::uint64_t>> recent_gaps_;
  std::deque<StreamSegment> ready_;
  std::deque<std::pair<std::uint64_t, std::uint64_t>> recent_rejected_;  // index ranges
  // Running magnitude scales of dte, stiffness, torque: max |value| of the last accepted chunks.
  std::array<std::deque<double>, 3> recent_max_;
  bool have_suspect_ = false;
  std::uint64_t suspect_first_ = 0;
  Held suspect_;
};

}  // namespace gear_damping_id
