#include "gear_sim_ros/bag_io.hpp"

#include <fcntl.h>
#include <gear_damping/GearParams.h>
#include <gear_damping/SignalChunk.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <future>
#include <limits>
#include <memory>
#include <mutex>
#include <thread>
#include <tuple>
#include <utility>

#ifdef __SSE2__
#include <emmintrin.h>
#endif
#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

#include "gear_sim/async.hpp"
#include "gear_sim/message_text.hpp"
#include "gear_sim/signal_csv.hpp"
#include "gear_sim/simd_clones.hpp"
#include "gear_sim/window_prefix.hpp"
#include "gear_sim_ros/bag_format.hpp"
#include "gear_sim_ros/conversions.hpp"

namespace gear_sim_ros {
using gear_sim::formatNumber;
using gear_sim::Status;
namespace {

constexpr const char* kChunkType = "gear_damping/SignalChunk";
constexpr const char* kParamsType = "gear_damping/GearParams";
constexpr int kMaxGapWarnings = 5;

std::string openError(const std::string& path, const std::exception& e) {
  return path + ": cannot read as a bag (" + gear_sim::quoteForMessage(e.what()) +
         "); if it is truncated, `rosbag reindex` may recover it";
}

// A SignalChunk read in place from its serialized bytes (laid out by chunkLayout): the scan
// needs its values once, not a deserialised copy.
struct RawArray {
  const std::uint8_t* p = nullptr;
  size_t n = 0;
  size_t size() const { return n; }
  bool empty() const { return n == 0; }
  double operator[](size_t i) const {  // a float64 element (little-endian, as the host)
    double v;
    std::memcpy(&v, p + 8 * i, 8);
    return v;
  }
};
struct RawChunk {
  double sample_rate = 0.0;
  std::uint64_t first_index = 0;
  RawArray dte, dte_velocity, stiffness, torque, mesh_state, mesh_phase, damping;
  // The scan found every value of the ranged channels (kPlausibleRanges) in its range: they are
  // read as they are (plausibleCopy would keep every one). Set only by ChunkScan::addInPlace.
  bool plausible = false;
};

// Where the fields of a SignalChunk's `n` serialized bytes lie, into *c; the layout problem
// (checkMessageLayout's), empty when every length fits.
std::string chunkLayout(const std::uint8_t* bytes, std::uint32_t n, RawChunk* c);
// The serialized bytes of `m` into *buf (grown as needed, never shrunk); returns their count.
std::uint32_t copyMessage(const rosbag::MessageInstance& m, std::vector<std::uint8_t>* buf);
// A deserialised chunk serialized again into *buf (grown as needed) and laid out into *c: the
// fallback of the in-place reading, so both paths hand on the same RawChunk.
void layoutDeserialised(const gear_damping::SignalChunk& p, std::vector<std::uint8_t>* buf,
                        RawChunk* c);

// The channels a chunk carries, as a bit set (dte_velocity, stiffness, torque, mesh_state,
// mesh_phase, damping).
unsigned channelSet(bool velocity, bool stiffness, bool torque, bool mesh_state, bool mesh_phase,
                    bool damping) {
  return (velocity ? 1u : 0u) | (stiffness ? 2u : 0u) | (torque ? 4u : 0u) |
         (mesh_state ? 8u : 0u) | (mesh_phase ? 16u : 0u) | (damping ? 32u : 0u);
}
unsigned channelSet(const RawChunk& c) {
  return channelSet(!c.dte_velocity.empty(), !c.stiffness.empty(), !c.torque.empty(),
                    !c.mesh_state.empty(), !c.mesh_phase.empty(), !c.damping.empty());
}
unsigned channelSet(const BagSignalInfo& info) {
  return channelSet(info.dte_velocity, info.stiffness, info.torque, info.mesh_state,
                    info.mesh_phase, info.damping);
}

std::string channelLengthError(const RawChunk& c) {
  const size_t m = c.dte.size();
  auto bad = [m](size_t s) { return s != 0 && s != m; };
  if (bad(c.dte_velocity.size())) return "dte_velocity";
  if (bad(c.stiffness.size())) return "stiffness";
  if (bad(c.torque.size())) return "torque";
  if (bad(c.mesh_state.size())) return "mesh_state";
  if (bad(c.mesh_phase.size())) return "mesh_phase";
  if (bad(c.damping.size())) return "damping";
  return {};
}

// Counts the outlier chunks and turns the plausibility counts into warnings.
void addPlausibilityWarnings(std::vector<double> chunk_max, BagSignalInfo* info) {
  if (!chunk_max.empty()) {
    std::vector<double> sorted = chunk_max;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(sorted.size() / 2),
                     sorted.end());
    const double median = sorted[sorted.size() / 2];
    if (median > 0.0)
      for (double m : chunk_max)
        if (m > kOutlierChunkFactor * median) ++info->outlier_chunks;
  }
  gear_sim::ImplausibleCounts counts;
  counts.non_finite = info->non_finite_values;
  counts.out_of_range = info->out_of_range_values;
  counts.bad_mesh_states = info->bad_mesh_states;
  for (std::string& w : gear_sim::implausibleWarnings(counts, "in the chunks"))
    info->warnings.push_back(std::move(w));
  if (info->outlier_chunks > 0)
    info->warnings.push_back(std::to_string(info->outlier_chunks) +
                             " chunks whose largest |dte| exceeds " +
                             gear_sim::formatNumber(kOutlierChunkFactor) +
                             "x the record's median chunk maximum: corrupt payloads?");
}

// The channels of a chunk that plausibility is checked on, in kPlausibleRanges' order.
std::array<const RawArray*, 6> rangedChannels(const RawChunk& c) {
  return {&c.dte, &c.dte_velocity, &c.stiffness, &c.torque, &c.mesh_phase, &c.damping};
}

bool inRange(const PlausibleRange& r, double x) { return x >= r.low && x <= r.high; }

// Whether x is finite, written so that loops over arrays vectorise: x - x is 0 for finite x and
// NaN for NaN and +-Inf.
inline bool finite(double x) { return x - x == 0.0; }

// The values of `a` that are not finite (*non_finite) and those outside `range` (*outside, the
// non-finite ones included: they fail every range check). Two lanes at a time with SSE2 (the
// compiler keeps a double or integer count in order, one value at a time).
#if defined(__GNUC__) && defined(__x86_64__)
#define GEAR_AVX2_PATHS 1
// Whether the machine has AVX2 (the scan's counts and maximum then run four lanes at a time:
// the same counts and the same maximum, which depend on no order).
bool haveAvx2() {
  static const bool yes = __builtin_cpu_supports("avx2");
  return yes;
}

// countOutside's counts, eight values (two vectors of four) at a time: a lane's in-range mask
// (-1) subtracted from its count. A non-finite value is outside every range, so the non-finite
// ones are counted only when some value is outside (a second pass; none in a plausible chunk).
__attribute__((target("avx2"))) void countOutsideAvx2(const RawArray& a,
                                                      const PlausibleRange& range,
                                                      std::int64_t* non_finite,
                                                      std::int64_t* outside) {
  const __m256d low = _mm256_set1_pd(range.low), high = _mm256_set1_pd(range.high);
  const double* x = reinterpret_cast<const double*>(a.p);
  __m256i in0 = _mm256_setzero_si256(), in1 = _mm256_setzero_si256();
  size_t i = 0;
  for (; i + 8 <= a.size(); i += 8) {
    const __m256d x0 = _mm256_loadu_pd(x + i), x1 = _mm256_loadu_pd(x + i + 4);
    const __m256d m0 =
        _mm256_and_pd(_mm256_cmp_pd(x0, low, _CMP_GE_OQ), _mm256_cmp_pd(x0, high, _CMP_LE_OQ));
    const __m256d m1 =
        _mm256_and_pd(_mm256_cmp_pd(x1, low, _CMP_GE_OQ), _mm256_cmp_pd(x1, high, _CMP_LE_OQ));
    in0 = _mm256_sub_epi64(in0, _mm256_castpd_si256(m0));
    in1 = _mm256_sub_epi64(in1, _mm256_castpd_si256(m1));
  }
  std::int64_t lanes[4];
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(lanes), _mm256_add_epi64(in0, in1));
  std::int64_t nf = 0,
               out = static_cast<std::int64_t>(i) - (lanes[0] + lanes[1] + lanes[2] + lanes[3]);
  for (; i < a.size(); ++i) {
    const double v = a[i];
    out += ((v >= range.low) & (v <= range.high)) ? 0 : 1;  // (no branch: inRange's && has one)
  }
  if (out > 0) {
    for (size_t j = 0; j < a.size(); ++j) nf += finite(a[j]) ? 0 : 1;
  }
  *non_finite = nf;
  *outside = out;
}

// The largest finite |x| of `a` (0 when none), four lanes at a time.
__attribute__((target("avx2"))) double maxFiniteAbsAvx2(const RawArray& a) {
  const __m256d sign = _mm256_set1_pd(-0.0), zero = _mm256_setzero_pd();
  __m256d m = zero;
  size_t i = 0;
  for (; i + 4 <= a.size(); i += 4) {
    const __m256d v =
        _mm256_andnot_pd(sign, _mm256_loadu_pd(reinterpret_cast<const double*>(a.p + 8 * i)));
    const __m256d fin = _mm256_cmp_pd(_mm256_sub_pd(v, v), zero, _CMP_EQ_OQ);
    m = _mm256_max_pd(m, _mm256_and_pd(v, fin));  // a non-finite value counts as 0
  }
  double lanes[4];
  _mm256_storeu_pd(lanes, m);
  double best = std::max(std::max(lanes[0], lanes[1]), std::max(lanes[2], lanes[3]));
  for (; i < a.size(); ++i) {
    const double v = std::abs(a[i]);
    best = finite(v) && v > best ? v : best;
  }
  return best;
}
#endif

void countOutside(const RawArray& a, const PlausibleRange& range, std::int64_t* non_finite,
                  std::int64_t* outside) {
#ifdef GEAR_AVX2_PATHS
  if (haveAvx2()) return countOutsideAvx2(a, range, non_finite, outside);
#endif
  size_t i = 0;
  std::int64_t nf = 0, out = 0;
#ifdef __SSE2__
  const __m128d low = _mm_set1_pd(range.low), high = _mm_set1_pd(range.high);
  const __m128d zero = _mm_setzero_pd(), ones = _mm_castsi128_pd(_mm_set1_epi64x(-1));
  __m128i nf2 = _mm_setzero_si128(), out2 = _mm_setzero_si128();
  for (; i + 2 <= a.size(); i += 2) {
    const __m128d x = _mm_loadu_pd(reinterpret_cast<const double*>(a.p + 8 * i));
    const __m128d fin = _mm_cmpeq_pd(_mm_sub_pd(x, x), zero);  // all ones where finite
    const __m128d in = _mm_and_pd(_mm_cmpge_pd(x, low), _mm_cmple_pd(x, high));
    // A lane's mask is -1 where the value counts: subtracting it adds 1.
    nf2 = _mm_sub_epi64(nf2, _mm_castpd_si128(_mm_andnot_pd(fin, ones)));
    out2 = _mm_sub_epi64(out2, _mm_castpd_si128(_mm_andnot_pd(in, ones)));
  }
  std::int64_t lanes[2];
  _mm_storeu_si128(reinterpret_cast<__m128i*>(lanes), nf2);
  nf = lanes[0] + lanes[1];
  _mm_storeu_si128(reinterpret_cast<__m128i*>(lanes), out2);
  out = lanes[0] + lanes[1];
#endif
  for (; i < a.size(); ++i) {
    const double x = a[i];
    nf += finite(x) ? 0 : 1;
    out += inRange(range, x) ? 0 : 1;
  }
  *non_finite = nf;
  *outside = out;
}

// Counts the implausible values of a chunk into `info`; returns the chunk's max |dte|
// (finite values only, 0 when none). Branch-free counts (an out-of-range count includes the
// non-finite values, which fail every range check, and is corrected by their count), so the
// loops over the channels vectorise.
double countImplausible(const RawChunk& c, BagSignalInfo* info) {
  const auto channels = rangedChannels(c);
  for (size_t k = 0; k < channels.size(); ++k) {
    const RawArray& a = *channels[k];
    std::int64_t non_finite = 0, outside = 0;
    countOutside(a, kPlausibleRanges[k], &non_finite, &outside);
    info->non_finite_values += non_finite;
    info->out_of_range_values += outside - non_finite;
  }
  std::int64_t bad_states = 0;  // a byte: finite, plausible when 0 or 1
  for (size_t i = 0; i < c.mesh_state.size(); ++i) bad_states += c.mesh_state.p[i] > 1 ? 1 : 0;
  info->bad_mesh_states += bad_states;
#ifdef GEAR_AVX2_PATHS
  if (haveAvx2()) return maxFiniteAbsAvx2(c.dte);
#endif
  double m = 0.0;
  for (size_t i = 0; i < c.dte.size(); ++i) {
    const double a = std::abs(c.dte[i]);
    m = finite(a) && a > m ? a : m;
  }
  return m;
}

// ---- Direct reading (BagSignalInfo::direct) ----
// rosbag reads a bag's chunk messages by reading each chunk's data into a buffer and copying a
// message's bytes out of it; for the common bag (one connection on the topic, uncompressed
// chunks, every message indexed) the same bytes are read here with one pread per chunk and used
// where they lie, in the order rosbag::View gives (its index entries).

// ros::Header::parse refuses a field longer than this (rosbag then throws): a record header no
// longer than it has no such field, so rosbag reads it as the direct reading does.
constexpr std::uint64_t kRosHeaderFieldLimit = 1000000;

// The bag file, read by pread.
class DirectFile {
 public:
  explicit DirectFile(const std::string& path) : fd_(::open(path.c_str(), O_RDONLY | O_CLOEXEC)) {}
  ~DirectFile() {
    if (fd_ >= 0) ::close(fd_);
  }
  DirectFile(const DirectFile&) = delete;
  DirectFile& operator=(const DirectFile&) = delete;
  // Whether the open file is the one stamped (BagStructure::stamp; an unknown stamp: never).
  bool is(const std::uint64_t stamp[5]) const {
    if (fd_ < 0 || stamp[1] == 0) return false;  // a regular file's inode number is never 0
    std::uint64_t now[5];
    fileStamp(fd_, now);
    return std::equal(now, now + 5, stamp);
  }
  // The n bytes at pos into *buf (grown as needed, never shrunk); false unless all were read.
  bool read(std::uint64_t pos, std::uint32_t n, std::vector<std::uint8_t>* buf) const {
    if (buf->size() < std::max<std::uint32_t>(n, 1)) buf->resize(std::max<std::uint32_t>(n, 1));
    std::uint64_t got = 0;
    while (got < n) {
      const ssize_t r = ::pread(fd_, buf->data() + got, n - got, static_cast<off_t>(pos + got));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) return false;
      got += static_cast<std::uint64_t>(r);
    }
    return true;
  }

 private:
  int fd_;
};

// Where the data of the message record at `offset` of a chunk's `n` data bytes lie: into
// *data (offset in the chunk's data) and *size. False when the record does not fit or its header
// is longer than kRosHeaderFieldLimit.
bool messageData(const std::uint8_t* chunk, std::uint64_t n, std::uint64_t offset,
                 std::uint32_t* data, std::uint32_t* size) {
  std::uint32_t header_len = 0;
  if (offset > n || n - offset < 4) return false;
  std::memcpy(&header_len, chunk + offset, 4);
  const std::uint64_t at = offset + 4 + std::uint64_t{header_len};  // the data length
  if (header_len > kRosHeaderFieldLimit || at > n || n - at < 4) return false;
  std::memcpy(size, chunk + at, 4);
  if (n - at - 4 < *size) return false;
  *data = static_cast<std::uint32_t>(at + 4);
  return true;
}

// A View of one topic whose index entries can be read (rosbag::View keeps its ranges
// protected).
class IndexView : public rosbag::View {
 public:
  IndexView(const rosbag::Bag& bag, const std::string& topic)
      : View(bag, rosbag::TopicQuery(topic)) {}
  // The only connection range holding messages (the View iterates it in its order), null when
  // none or several do.
  const rosbag::MessageRange* onlyRange() const {
    const rosbag::MessageRange* only = nullptr;
    for (const rosbag::MessageRange* r : ranges_) {
      if (r->begin == r->end) continue;
      if (only != nullptr) return nullptr;
      only = r;
    }
    return only;
  }
};

// The topic's messages for direct reading, in rosbag::View's order, into *out (their record's
// offset in `offset`, size 0); false (and *out empty) when rosbag must read them: messages not
// all indexed, an encryptor, an unknown file, several connections holding messages, a type other
// than SignalChunk as compiled, a compressed chunk or a chunk header rosbag may parse otherwise.
bool directMessages(const rosbag::Bag& bag, const std::string& topic, const BagStructure& s,
                    std::vector<BagSignalInfo::DirectMessage>* out) {
  out->clear();
  if (!s.messages_indexed || s.encrypted || s.stamp[1] == 0) return false;
  const IndexView view(bag, topic);
  const rosbag::MessageRange* range = view.onlyRange();
  if (range == nullptr || range->connection_info->datatype != kChunkType ||
      range->connection_info->md5sum !=
          ros::message_traits::MD5Sum<gear_damping::SignalChunk>::value())
    return false;
  for (auto e = range->begin; e != range->end; ++e) {
    const auto c = std::lower_bound(
        s.chunks.begin(), s.chunks.end(), e->chunk_pos,
        [](const BagStructure::Chunk& a, std::uint64_t pos) { return a.start < pos; });
    if (c == s.chunks.end() || c->start != e->chunk_pos || !c->uncompressed ||
        c->data_pos - c->start - 8 > kRosHeaderFieldLimit) {
      out->clear();
      return false;
    }
    out->push_back({c->data_pos, c->data_len, e->offset, 0});
  }
  return true;
}

// The scan of scanSignalBag done by streamSignalBag's reader in the same pass
// (scanStreamSignalBag); defined after ChunkScan.
struct PassScan;
// The message `d` of a chunk's data `chunk` (its record's offset in d.offset) scanned as
// scanDirect scans it, its fields into *c; false when the scan failed or must be redone (status
// in `pass`).
bool scanMessage(PassScan* pass, const std::uint8_t* chunk, const BagSignalInfo::DirectMessage& d,
                 size_t i, RawChunk* c);
void finishPass(PassScan* pass);
void failPass(PassScan* pass);

// The end of a reader thread's owner: sets *stop under `mutex`, wakes the waiters of `cv` and
// joins `thread`.
void stopAndJoin(std::mutex& mutex, std::condition_variable& cv, bool* stop, std::thread& thread) {
  {
    std::lock_guard<std::mutex> lock(mutex);
    *stop = true;
  }
  cv.notify_all();
  thread.join();
}

// Reads the messages of a SignalChunk topic on a thread of its own, so that what the caller does
// with one chunk overlaps the read of the next (issue 18: `analyze` reads and computes at the
// same time). The queue between them is bounded by samples, so memory stays at about
// kQueueSamples samples (or one item when items are larger); the byte buffers are recycled.
// Messages the scan read directly (BagSignalInfo::direct) are read the same way while the file
// is the one scanned, a chunk's data per item; otherwise through rosbag::View, one message per
// item: with BagSignalInfo::messages_indexed a SignalChunk is passed on as its serialized bytes,
// its fields read in place (chunkLayout), not deserialised; any other message goes through
// rosbag's deserialisation as before. A message that does not instantiate as a SignalChunk
// arrives with valid == false; an exception of the read ends the stream and is reported by
// error().
class ChunkReader {
 public:
  struct Message {
    RawChunk c;  // its fields, in the item's bytes
    bool valid = false;
  };
  struct Chunk {
    std::vector<std::uint8_t> bytes;  // a serialized message, or a chunk's data (direct)
    std::vector<Message> messages;    // in `bytes`
  };
  static constexpr size_t kQueueSamples = size_t{1} << 16;

  // `pass`: the scan done on the way (info.direct's record offsets, scanStreamSignalBag).
  explicit ChunkReader(const BagSignalInfo& info, PassScan* pass = nullptr)
      : info_(info), pass_(pass), thread_([this] { run(); }) {}
  ~ChunkReader() { stopAndJoin(mutex_, cv_, &stop_, thread_); }
  ChunkReader(const ChunkReader&) = delete;
  ChunkReader& operator=(const ChunkReader&) = delete;

  /// The next item into *c (whose previous bytes are recycled); false at the end of the
  /// topic or after a read error.
  bool next(Chunk* c) {
    std::unique_lock<std::mutex> lock(mutex_);
    if (c->bytes.capacity() > 0) spare_.push_back(std::move(c->bytes));
    consumer_waiting_ = true;
    cv_.wait(lock, [this] { return !queue_.empty() || done_; });
    consumer_waiting_ = false;
    if (queue_.empty()) return false;
    *c = std::move(queue_.front());
    queue_.pop_front();
    queued_ -= samples(*c);
    if (producer_waiting_) cv_.notify_all();  // (a wake-up per item costs two system calls)
    return true;
  }
  /// The read error (empty when none); valid once next() returned false.
  const std::string& error() const { return error_; }

 private:
  static size_t samples(const Chunk& c) {
    size_t n = 0;
    for (const Message& m : c.messages) n += m.valid ? m.c.dte.size() : 0;
    return n;
  }

  void read(const rosbag::MessageInstance& m, Message* item,
            std::vector<std::uint8_t>* bytes) const {
    if (info_.messages_indexed && m.getDataType() == kChunkType &&
        m.isType<gear_damping::SignalChunk>()) {
      const std::uint32_t n = copyMessage(m, bytes);
      item->valid = chunkLayout(bytes->data(), n, &item->c).empty();
      if (item->valid) return;
    }
    const auto p = m.instantiate<gear_damping::SignalChunk>();
    item->valid = p != nullptr;
    if (!p) return;
    layoutDeserialised(*p, bytes, &item->c);
  }

  // An item with recycled bytes when there are some.
  Chunk emptyItem() {
    Chunk item;
    std::lock_guard<std::mutex> lock(mutex_);
    if (!spare_.empty()) {
      item.bytes = std::move(spare_.back());
      spare_.pop_back();
    }
    return item;
  }

  // Waits until the queue has room; false when the reader is to stop.
  bool room() {
    std::unique_lock<std::mutex> lock(mutex_);
    producer_waiting_ = true;
    cv_.wait(lock, [this] { return stop_ || queue_.empty() || queued_ < kQueueSamples; });
    producer_waiting_ = false;
    return !stop_;
  }

  // Queues an item once there is room; false when the reader is to stop.
  bool push(Chunk item) {
    const size_t n = samples(item);
    if (!room()) return false;
    std::unique_lock<std::mutex> lock(mutex_);
    if (stop_) return false;
    queue_.push_back(std::move(item));
    queued_ += n;
    if (consumer_waiting_) cv_.notify_all();
    return true;
  }

  // The messages of info_.direct, a chunk's data per item; false (nothing read) when the file is
  // not the one scanned.
  bool runDirect() {
    const auto& direct = info_.direct;
    if (direct.empty()) return false;
    const DirectFile file(info_.path);
    if (!file.is(info_.stamp)) return false;
    // A chunk is read only once the queue has room: it holds about kQueueSamples samples of
    // chunks or one larger chunk, so with the consumer's at most two large chunks' data are held
    // (rosbag held one chunk and copies of the queued messages).
    for (size_t i = 0; i < direct.size() && room();) {
      Chunk item = emptyItem();
      const BagSignalInfo::DirectMessage& first = direct[i];
      if (!file.read(first.chunk_pos, first.chunk_len, &item.bytes))
        throw std::runtime_error("the file was changed while it was read");
      for (; i < direct.size() && direct[i].chunk_pos == first.chunk_pos; ++i) {
        const BagSignalInfo::DirectMessage& d = direct[i];
        Message m;
        m.valid = d.offset <= first.chunk_len && d.size <= first.chunk_len - d.offset &&
                  chunkLayout(item.bytes.data() + d.offset, d.size, &m.c).empty();
        item.messages.push_back(m);
      }
      if (!push(std::move(item))) break;
    }
    return true;
  }

  // runDirect with the scan: each message's record found in its chunk and scanned before it is
  // queued; the reading stops at the first scan error.
  void runScanned() {
    const auto& direct = info_.direct;
    const DirectFile file(info_.path);
    const std::runtime_error stop("the scan of the bag stopped");  // the pass has the reason
    if (!file.is(info_.stamp)) {
      failPass(pass_);
      throw stop;
    }
    for (size_t i = 0; i < direct.size() && room();) {
      Chunk item = emptyItem();
      const BagSignalInfo::DirectMessage& first = direct[i];
      if (!file.read(first.chunk_pos, first.chunk_len, &item.bytes)) {
        failPass(pass_);
        throw stop;
      }
      for (; i < direct.size() && direct[i].chunk_pos == first.chunk_pos; ++i) {
        Message m;
        if (!scanMessage(pass_, item.bytes.data(), direct[i], i, &m.c)) throw stop;
        m.valid = true;
        item.messages.push_back(m);
      }
      if (!push(std::move(item))) return;
    }
    finishPass(pass_);
  }

  void runView() {
    rosbag::Bag bag;
    bag.open(info_.path, rosbag::bagmode::Read);
    rosbag::View view(bag, rosbag::TopicQuery(info_.topic));
    for (const rosbag::MessageInstance& m : view) {
      Chunk item = emptyItem();
      item.messages.resize(1);
      read(m, &item.messages[0], &item.bytes);
      if (!push(std::move(item))) break;
    }
  }

  void run() {
    std::string error;
    try {
      if (pass_ != nullptr)
        runScanned();
      else if (!runDirect())
        runView();
    } catch (const std::exception& e) {
      error = openError(info_.path, e);
    }
    std::lock_guard<std::mutex> lock(mutex_);
    error_ = error;
    done_ = true;
    cv_.notify_all();
  }

  const BagSignalInfo& info_;
  PassScan* const pass_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Chunk> queue_;
  std::vector<std::vector<std::uint8_t>> spare_;  // buffers the caller is done with
  size_t queued_ = 0;                             // samples in queue_
  bool stop_ = false, done_ = false;
  bool consumer_waiting_ = false, producer_waiting_ = false;  // in cv_.wait (notify only then)
  std::string error_;
  std::thread thread_;  // last: started once the members above exist
};

// The SignalChunk topic to read: `topic` when given (it must exist and have that type), else the
// only one in the bag. Also notes the first GearParams topic.
Status chooseTopic(const rosbag::Bag& bag, const std::string& path, const std::string& topic,
                   BagSignalInfo* out) {
  rosbag::View all(bag);
  std::vector<std::string> chunk_topics, params_topics;
  std::string topic_type;
  for (const rosbag::ConnectionInfo* c : all.getConnections()) {
    if (c->datatype == kChunkType &&
        std::find(chunk_topics.begin(), chunk_topics.end(), c->topic) == chunk_topics.end())
      chunk_topics.push_back(c->topic);
    if (c->datatype == kParamsType &&
        std::find(params_topics.begin(), params_topics.end(), c->topic) == params_topics.end())
      params_topics.push_back(c->topic);
    if (c->topic == topic) topic_type = c->datatype;
  }
  if (!params_topics.empty()) out->params_topic = params_topics.front();
  if (!topic.empty()) {
    if (topic_type.empty()) {
      return Status::invalidInput(path + ": no topic " + gear_sim::quoteForMessage(topic) +
                                  " in the bag");
    }
    if (topic_type != kChunkType) {
      return Status::invalidInput(path + ": topic " + gear_sim::quoteForMessage(topic) +
                                  " has type " + gear_sim::quoteForMessage(topic_type) + ", not " +
                                  kChunkType);
    }
    out->topic = topic;
  } else if (chunk_topics.size() == 1) {
    out->topic = chunk_topics.front();
  } else if (chunk_topics.empty()) {
    return Status::invalidInput(path + ": no topic of type " + std::string(kChunkType) +
                                " in the bag");
  } else {
    std::string list;
    for (const auto& t : chunk_topics)
      list += (list.empty() ? "" : ", ") + gear_sim::quoteForMessage(t);
    return Status::invalidInput(path + ": several topics of type " + std::string(kChunkType) +
                                " (" + list + "): choose one with --topic");
  }
  return {};
}

// The last GearParams message of out->params_topic (if any) into out->params, or the reason
// it is unusable into out->params_error.
void readBagParams(const rosbag::Bag& bag, BagSignalInfo* out) {
  if (out->params_topic.empty()) return;
  rosbag::View pv(bag, rosbag::TopicQuery(out->params_topic));
  gear_damping::GearParams::ConstPtr last;
  for (const rosbag::MessageInstance& m : pv) last = m.instantiate<gear_damping::GearParams>();
  const Status s =
      last ? fromMsg(*last, &out->params) : Status::invalidInput("no readable message");
  if (s.ok())
    out->has_params = true;
  else
    out->params_error = gear_sim::quoteForMessage(out->params_topic) + ": " + s.message();
}

// The channel flags of `channels` (channelSet's bits) into *out.
void setChannels(unsigned channels, BagSignalInfo* out) {
  out->dte_velocity = channels & 1u;
  out->stiffness = channels & 2u;
  out->torque = channels & 4u;
  out->mesh_state = channels & 8u;
  out->mesh_phase = channels & 16u;
  out->damping = channels & 32u;
}

// A channel's values as the record read whole holds them: a finite value outside the channel's
// plausible range reads as NaN (the block filling's rule).
struct PlausibleValues {
  const RawArray& a;
  PlausibleRange range;
  double operator[](size_t i) const {
    const double x = a[i];
    return inRange(range, x) || !finite(x) ? x : std::numeric_limits<double>::quiet_NaN();
  }
};

// The stiffness of chunk `c`, whose first sample is the record's sample `position`, that lies in
// the default window's prefix, added to *sum (in order: the sum's bits fix the window). An
// implausible value is missing there, as in the record read whole (a stiffness of 1e14 among
// the prefix had given the streamed read another window than the whole one).
void addPrefix(const RawChunk& c, std::uint64_t position, gear_sim::FiniteSum* sum) {
  const auto prefix = static_cast<std::uint64_t>(gear_sim::kWindowPrefixSamples);
  if (position < prefix)
    sum->add(PlausibleValues{c.stiffness, kPlausibleRanges[2]}, 0,
             std::min<size_t>(c.stiffness.size(), prefix - position));
}

// The pass over the chunks of one topic: each chunk is checked on its own and against the
// previous ones (rate, channels, increasing indices), gaps are counted, and the totals,
// plausibility warnings and channel flags are filled in at the end.
class ChunkScan {
 public:
  // `raw`: the bag's messages all name indexed connections (BagStructure::messages_indexed),
  // so a SignalChunk whose layout fits is read in place, as deserialising it would read it.
  ChunkScan(const std::string& path, BagSignalInfo* out, bool raw)
      : path_(path), out_(*out), raw_(raw) {}

  Status add(const rosbag::MessageInstance& m) {
    RawChunk c;
    if (m.getDataType() == kChunkType) {
      const std::uint32_t n = copyMessage(m, &buffer_);
      if (Status s = layout(buffer_.data(), n, &c); !s.ok()) return s;
      if (raw_ && m.isType<gear_damping::SignalChunk>()) return add(c);
    }
    // rosbag's deserialisation, with its checks and exceptions
    const auto p = m.instantiate<gear_damping::SignalChunk>();
    if (!p) {
      return Status::invalidInput(path_ + ": " + gear_sim::quoteForMessage(out_.topic) +
                                  " message " + std::to_string(out_.chunks + 1) +
                                  " (first_index ?): not a " + std::string(kChunkType));
    }
    layoutDeserialised(*p, &buffer_, &c);
    return add(c);
  }

  // A SignalChunk's `n` serialized bytes read in place (as add(m) reads an indexed one).
  Status addInPlace(const std::uint8_t* bytes, std::uint32_t n) {
    RawChunk c;
    return addInPlace(bytes, n, &c);
  }
  // The same, its fields into *c.
  Status addInPlace(const std::uint8_t* bytes, std::uint32_t n, RawChunk* c) {
    c->plausible = false;  // (a reused RawChunk keeps no verdict of the chunk before)
    if (Status s = layout(bytes, n, c); !s.ok()) return s;
    const std::int64_t counted = out_.non_finite_values + out_.out_of_range_values;
    if (Status s = add(*c); !s.ok()) return s;
    // (each channel adds the values outside its range, the non-finite ones included)
    c->plausible = out_.non_finite_values + out_.out_of_range_values == counted;
    return {};
  }

  using Where = std::function<std::string()>;

  Status add(const RawChunk& c) {
    // The chunk's name for a message, made only when a message needs it (not for each of a long
    // record's 10^4 chunks)
    const Where where = [&] {
      return path_ + ": " + gear_sim::quoteForMessage(out_.topic) + " message " +
             std::to_string(out_.chunks + 1) + " (first_index " + std::to_string(c.first_index) +
             ")";
    };
    if (Status st = checkChunk(c, where); !st.ok()) return st;
    if (out_.chunks == 0) {
      out_.sample_rate = c.sample_rate;
      out_.first_index = c.first_index;
      channels_ = channelSet(c);
    } else if (Status st = checkSequence(c, where); !st.ok()) {
      return st;
    }
    next_ = c.first_index + c.dte.size();
    out_.real_samples += static_cast<std::int64_t>(c.dte.size());
    chunk_max_.push_back(countImplausible(c, &out_));
    addPrefix(c, c.first_index - out_.first_index, &k_prefix_);
    ++out_.chunks;
    return {};
  }

  Status finish() {
    if (out_.chunks == 0) {
      return Status::invalidInput(path_ + ": topic " + gear_sim::quoteForMessage(out_.topic) +
                                  " has no messages");
    }
    if (out_.gaps > kMaxGapWarnings)
      out_.warnings.push_back(std::to_string(out_.gaps) + " gaps in all, " +
                              std::to_string(out_.gap_samples) + " samples missing");
    out_.samples = static_cast<std::int64_t>(next_ - out_.first_index);
    if (static_cast<double>(out_.gap_samples) >
        kMaxGapRatio * static_cast<double>(out_.real_samples)) {
      return Status::invalidInput(
          largest_gap_at_ + ": gaps hold " + std::to_string(out_.gap_samples) +
          " missing samples, more than the " + std::to_string(out_.real_samples) +
          " present (at most " + formatNumber(kMaxGapRatio) +
          "x): a corrupt first_index? The largest gap, of " + std::to_string(largest_gap_) +
          " samples, ends before this message");
    }
    addPlausibilityWarnings(chunk_max_, &out_);
    out_.stiffness_mean = k_prefix_.mean();
    setChannels(channels_, &out_);
    return {};
  }

 private:
  // The layout of a SignalChunk's bytes into *c; an error naming the message when it does not fit.
  Status layout(const std::uint8_t* bytes, std::uint32_t n, RawChunk* c) const {
    if (const std::string bad = chunkLayout(bytes, n, c); !bad.empty()) {
      return Status::invalidInput(path_ + ": " + gear_sim::quoteForMessage(out_.topic) +
                                  " message " + std::to_string(out_.chunks + 1) + ": corrupt " +
                                  kChunkType + " (" + bad + ")");
    }
    return {};
  }

  // One chunk on its own: a positive rate, dte samples, channels as long as dte, indices < 2^53.
  static Status checkChunk(const RawChunk& c, const Where& where) {
    if (!(c.sample_rate > 0.0) || !std::isfinite(c.sample_rate)) {
      return Status::invalidInput(where() + ": sample_rate " + formatNumber(c.sample_rate) +
                                  " is not a positive number");
    }
    if (c.dte.empty()) {
      return Status::invalidInput(where() + ": no dte samples");
    }
    if (const std::string bad = channelLengthError(c); !bad.empty())
      return Status::invalidInput(where() + ": channel " + bad + " has " +
                                      "a length other than dte's (" + std::to_string(c.dte.size()) +
                                      ")",
                                  bad);
    if (c.first_index >= kMaxSampleIndex || c.dte.size() > kMaxSampleIndex - c.first_index) {
      return Status::invalidInput(where() + ": sample indices beyond 2^53 (" +
                                  std::to_string(kMaxSampleIndex) +
                                  "): corrupt or wrapped-around first_index");
    }
    // The time stamps a reader gives these indices must resolve the step (the same rule as a
    // record read whole: gear_sim::checkTimeResolution).
    const double last = static_cast<double>(c.first_index + (c.dte.size() - 1)) / c.sample_rate;
    if (Status s = gear_sim::checkTimeResolution(last, 1.0 / c.sample_rate); !s.ok())
      return Status::invalidInput(where() + ": " + s.message(), "time");
    return {};
  }

  // A later chunk against the first ones: same rate and channels, indices increasing; a gap
  // is counted and (the first kMaxGapWarnings) warned about.
  Status checkSequence(const RawChunk& c, const Where& where) {
    if (c.sample_rate != out_.sample_rate) {
      return Status::invalidInput(where() + ": sample_rate changed from " +
                                  formatNumber(out_.sample_rate) + " to " +
                                  formatNumber(c.sample_rate) + " Hz");
    }
    if (channelSet(c) != channels_) {
      return Status::invalidInput(where() +
                                  ": carries a different set of channels than the first chunk");
    }
    if (c.first_index < next_) {
      return Status::invalidInput(
          where() + ": sample indices not increasing (the previous chunk ended at " +
          std::to_string(next_ - 1) + "): a duplicated or out-of-order chunk");
    }
    if (c.first_index > next_) {
      const std::uint64_t missing = c.first_index - next_;
      ++out_.gaps;
      if (missing > largest_gap_) {
        largest_gap_ = missing;
        largest_gap_at_ = where();
      }
      out_.gap_samples += static_cast<std::int64_t>(missing);
      if (out_.gaps <= kMaxGapWarnings)
        out_.warnings.push_back("gap of " + std::to_string(missing) + " samples before " +
                                gear_sim::quoteForMessage(out_.topic) + " message " +
                                std::to_string(out_.chunks + 1) + " (indices " +
                                std::to_string(next_) + " to " + std::to_string(c.first_index - 1) +
                                "): the segments there are not identifiable");
    }
    return {};
  }

  const std::string& path_;
  BagSignalInfo& out_;
  const bool raw_;
  std::vector<std::uint8_t> buffer_;  // the current message's serialized bytes
  std::uint64_t next_ = 0;            // global index after the previous chunk
  unsigned channels_ = 0;
  gear_sim::FiniteSum k_prefix_;  // the default window's stiffness prefix
  std::uint64_t largest_gap_ = 0;
  std::string largest_gap_at_;
  std::vector<double> chunk_max_;  // max |dte| per chunk, for the outlier check
};

struct PassScan {
  explicit PassScan(BagSignalInfo start) : out(std::move(start)), scan(out.path, &out, true) {}
  BagSignalInfo out;  // what the scan fills in (its direct offsets become the data's)
  ChunkScan scan;
  Status status;
  bool redo = false;      // not scanned as scanSignalBag scans
  bool finished = false;  // every message scanned, finish() done
};

bool scanMessage(PassScan* pass, const std::uint8_t* chunk, const BagSignalInfo::DirectMessage& d,
                 size_t i, RawChunk* c) {
  BagSignalInfo::DirectMessage& at = pass->out.direct[i];
  if (!messageData(chunk, d.chunk_len, d.offset, &at.offset, &at.size)) {
    failPass(pass);
    return false;
  }
  pass->status = pass->scan.addInPlace(chunk + at.offset, at.size, c);
  return pass->status.ok();
}

void finishPass(PassScan* pass) {
  pass->status = pass->scan.finish();
  pass->finished = true;
}

void failPass(PassScan* pass) {
  pass->redo = true;
  pass->status = Status::invalidInput("the bag cannot be scanned in the same pass");
}

}  // namespace

// ROS deserialises an array or a string by resizing it to the length it reads and only then
// checking that the bytes are there: a corrupt length in a SignalChunk allocated (and zeroed) up
// to 32 GB, one in a rig bag's JointState 4 GB (both found by fuzz_bag). The serialized layout
// is walked first: every length must fit in the message's bytes.
namespace {

class LayoutWalk {
 public:
  LayoutWalk(const std::uint8_t* bytes, std::uint32_t n) : n_(n), buf_(bytes) {}
  bool skip(std::uint64_t bytes) {
    if (bytes > n_ - k_) return false;
    k_ += bytes;
    return true;
  }
  // An array of `len` elements of `element` bytes (a string: element 1); where it lies into
  // *out when given.
  std::string array(std::uint64_t element, const char* name, RawArray* out = nullptr) {
    std::uint32_t len = 0;
    if (std::string e = length(name, &len); !e.empty()) return e;
    if (out != nullptr) *out = {buf_ + k_, len};
    return skip(element * len) ? std::string() : claims(name, len);
  }
  // string[]: a count, then each string's length and bytes.
  std::string strings(const char* name) {
    std::uint32_t len = 0;
    if (std::string e = length(name, &len); !e.empty()) return e;
    if (len > n_ - k_) return claims(name, len);  // every string takes 4 bytes at least
    for (std::uint32_t i = 0; i < len; ++i)
      if (std::string e = array(1, name); !e.empty()) return e;
    return {};
  }
  // std_msgs/Header: seq, stamp, frame_id.
  std::string header() { return skip(12) ? array(1, "header.frame_id") : "cut in its header"; }
  std::uint64_t position() const { return k_; }

 private:
  std::string length(const char* name, std::uint32_t* len) {
    if (n_ - k_ < 4) return std::string("cut before the length of ") + name;
    std::memcpy(len, buf_ + k_, 4);
    k_ += 4;
    return {};
  }
  std::string claims(const char* name, std::uint32_t len) const {
    return std::string(name) + " claims " + std::to_string(len) + " elements in a message of " +
           std::to_string(n_) + " bytes";
  }
  std::uint32_t n_;
  const std::uint8_t* buf_;
  std::uint64_t k_ = 0;
};

std::uint32_t copyMessage(const rosbag::MessageInstance& m, std::vector<std::uint8_t>* buf) {
  const std::uint32_t n = m.size();
  if (buf->size() < n) buf->resize(n);
  ros::serialization::OStream out(buf->data(), n);
  m.write(out);
  return n;
}

void layoutDeserialised(const gear_damping::SignalChunk& p, std::vector<std::uint8_t>* buf,
                        RawChunk* c) {
  const std::uint32_t n = ros::serialization::serializationLength(p);
  if (buf->size() < n) buf->resize(n);
  ros::serialization::OStream out(buf->data(), n);
  ros::serialization::serialize(out, p);
  chunkLayout(buf->data(), n, c);  // fits: serialised by ROS
}

std::string chunkLayout(const std::uint8_t* bytes, std::uint32_t n, RawChunk* c) {
  LayoutWalk w(bytes, n);
  if (std::string e = w.header(); !e.empty()) return e;
  const std::uint64_t at = w.position();
  if (!w.skip(16)) return "cut before sample_rate and first_index";
  std::memcpy(&c->sample_rate, bytes + at, 8);
  std::memcpy(&c->first_index, bytes + at + 8, 8);
  const std::tuple<std::uint64_t, const char*, RawArray*> arrays[] = {
      {8, "dte", &c->dte},
      {8, "dte_velocity", &c->dte_velocity},
      {8, "stiffness", &c->stiffness},
      {8, "torque", &c->torque},
      {1, "mesh_state", &c->mesh_state},
      {8, "mesh_phase", &c->mesh_phase},
      {8, "damping", &c->damping}};
  for (const auto& [size, name, out] : arrays)
    if (std::string e = w.array(size, name, out); !e.empty()) return e;
  return {};
}

// The problem of checkMessageLayout, empty when the layout fits (LayoutWalk's convention).
std::string layoutProblem(const rosbag::MessageInstance& m) {
  const std::string& type = m.getDataType();
  std::vector<std::uint8_t> buf;
  const std::uint32_t n = copyMessage(m, &buf);
  if (type == kChunkType) {
    RawChunk c;
    return chunkLayout(buf.data(), n, &c);
  }
  LayoutWalk w(buf.data(), n);
  if (type == "sensor_msgs/JointState") {
    if (std::string e = w.header(); !e.empty()) return e;
    if (std::string e = w.strings("name"); !e.empty()) return e;
    for (const char* name : {"position", "velocity", "effort"})
      if (std::string e = w.array(8, name); !e.empty()) return e;
  } else if (type == "geometry_msgs/WrenchStamped") {
    return w.header();  // then six float64
  }
  return {};
}
}  // namespace

namespace {
// Reads a list of byte ranges of a file in order on a thread of its own, one range ahead of the
// caller, so that the scan's checks of one chunk overlap the read of the next (two buffers).
class Prefetch {
 public:
  Prefetch(const DirectFile& file, std::vector<std::pair<std::uint64_t, std::uint32_t>> reads)
      : file_(file), reads_(std::move(reads)), thread_([this] { run(); }) {}
  ~Prefetch() { stopAndJoin(mutex_, cv_, &stop_, thread_); }
  Prefetch(const Prefetch&) = delete;
  Prefetch& operator=(const Prefetch&) = delete;

  /// The next range's bytes into *buf (swapped with the read-ahead buffer); false when they
  /// could not all be read.
  bool next(std::vector<std::uint8_t>* buf) {
    std::unique_lock<std::mutex> lock(mutex_);
    cv_.wait(lock, [this] { return full_; });
    buf->swap(ahead_);
    full_ = false;
    cv_.notify_all();
    return ok_;
  }

 private:
  void run() {
    std::vector<std::uint8_t> bytes;
    for (const auto& [pos, len] : reads_) {
      const bool ok = file_.read(pos, len, &bytes);
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait(lock, [this] { return stop_ || !full_; });
      if (stop_) return;
      ahead_.swap(bytes);
      ok_ = ok;
      full_ = true;
      cv_.notify_all();
    }
  }

  const DirectFile& file_;
  const std::vector<std::pair<std::uint64_t, std::uint32_t>> reads_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::vector<std::uint8_t> ahead_;
  bool full_ = false, ok_ = false, stop_ = false;
  std::thread thread_;  // last: started once the members above exist
};

// The scan of the messages in out->direct, read directly (their `offset` and `size` set to their
// data's): false when one cannot be read as rosbag reads it (the file changed since its walk, a
// record that does not fit or has a long header; the caller then scans through rosbag), else
// true with the scan's outcome in *status.
bool scanDirect(const std::string& path, const BagStructure& structure, BagSignalInfo* out,
                Status* status) {
  const DirectFile file(path);
  if (!file.is(structure.stamp)) return false;
  ChunkScan scan(path, out, true);
  // The chunk reads, in the order the messages need them.
  std::vector<std::pair<std::uint64_t, std::uint32_t>> reads;
  for (const BagSignalInfo::DirectMessage& d : out->direct)
    if (reads.empty() || d.chunk_pos != reads.back().first)
      reads.emplace_back(d.chunk_pos, d.chunk_len);
  Prefetch prefetch(file, reads);
  std::vector<std::uint8_t> chunk;
  bool loaded = false;
  std::uint64_t at = 0;  // the loaded chunk's position
  for (BagSignalInfo::DirectMessage& d : out->direct) {
    if (!loaded || d.chunk_pos != at) {
      if (!prefetch.next(&chunk)) return false;
      loaded = true;
      at = d.chunk_pos;
    }
    if (!messageData(chunk.data(), d.chunk_len, d.offset, &d.offset, &d.size)) return false;
    if (Status s = scan.addInPlace(chunk.data() + d.offset, d.size); !s.ok()) {
      *status = s;
      return true;
    }
  }
  *status = scan.finish();
  return true;
}
}  // namespace

Status checkMessageLayout(const rosbag::MessageInstance& m) {
  const std::string problem = layoutProblem(m);
  return problem.empty() ? Status() : Status::invalidInput(problem);
}

namespace {
// A rosbag::Bag constructed on a thread of its own (gear_sim::startAsync): its constructor's
// encryptor plugin loader (pluginlib) crawls the ROS package paths (~7,300 stat and ~590
// getdents calls, ~30 ms), which needs nothing from the file, so it runs while the caller checks
// the file's structure (checkBagStructure), which must pass before rosbag opens the file.
std::future<std::unique_ptr<rosbag::Bag>> constructBag() {
  return gear_sim::startAsync([] { return std::make_unique<rosbag::Bag>(); });
}

// scanSignalBag's steps before its pass over the chunks (the structure checked by the caller):
// the bag opened, the topic chosen, the parameters read, the messages to read directly listed
// (out->direct: their records' offsets; empty when rosbag reads them). rosbag's exceptions pass.
Status prepareScan(rosbag::Bag& bag, const std::string& path, const std::string& topic,
                   const BagStructure& structure, BagSignalInfo* out) {
  out->path = path;
  bag.open(path, rosbag::bagmode::Read);
  if (Status s = chooseTopic(bag, path, topic, out); !s.ok()) return s;
  readBagParams(bag, out);
  out->messages_indexed = structure.messages_indexed;
  directMessages(bag, out->topic, structure, &out->direct);
  return {};
}
}  // namespace

Status scanSignalBag(const std::string& path, const std::string& topic, BagSignalInfo* info) {
  BagSignalInfo out;
  // rosbag trusts the lengths in the file (ROS's header parser reads beyond a corrupt field
  // length): every record is checked first.
  std::future<std::unique_ptr<rosbag::Bag>> pending = constructBag();
  BagStructure structure;
  if (Status s = checkBagStructure(path, &structure); !s.ok()) return s;
  try {
    const std::unique_ptr<rosbag::Bag> owned = pending.get();
    rosbag::Bag& bag = *owned;
    if (Status s = prepareScan(bag, path, topic, structure, &out); !s.ok()) return s;
    if (!out.direct.empty()) {
      BagSignalInfo direct = out;
      Status status;
      if (scanDirect(path, structure, &direct, &status)) {
        if (!status.ok()) return status;
        std::copy(structure.stamp, structure.stamp + 5, direct.stamp);
        *info = std::move(direct);
        return {};
      }
      out.direct.clear();  // rosbag reads them
    }
    ChunkScan scan(path, &out, structure.messages_indexed);
    rosbag::View view(bag, rosbag::TopicQuery(out.topic));
    for (const rosbag::MessageInstance& m : view)
      if (Status s = scan.add(m); !s.ok()) return s;
    if (Status s = scan.finish(); !s.ok()) return s;
  } catch (const std::exception& e) {
    return Status::invalidInput(openError(path, e));
  }
  *info = std::move(out);
  return {};
}

namespace {
// n mesh_state bytes as doubles: 0 and 1 kept, any other byte NaN (counted by the scan); a
// table lookup, no branch.
void meshStates(const std::uint8_t* from, Eigen::Index n, double* out) {
  static const std::array<double, 256> value = [] {
    std::array<double, 256> v;
    v.fill(std::numeric_limits<double>::quiet_NaN());
    v[0] = 0.0;
    v[1] = 1.0;
    return v;
  }();
  for (Eigen::Index q = 0; q < n; ++q) out[q] = value[from[q]];
}

// n float64 values from `from` (little-endian bytes) to `out`, a finite value outside `range`
// as NaN (counted by the scan); branch-free, so the loop vectorises, with an AVX2 clone where
// the machine has it (selects and copies only, so both clones write the same bits).
GEAR_AVX2_CLONES void plausibleCopy(const std::uint8_t* from, Eigen::Index n, PlausibleRange range,
                                    double* out) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (Eigen::Index q = 0; q < n; ++q) {
    double x;
    std::memcpy(&x, from + 8 * q, 8);
    const bool keep = ((x >= range.low) & (x <= range.high)) | !finite(x);  // no branches
    out[q] = keep ? x : nan;
  }
}

// The time stamps of samples first .. first + n - 1 (n < 2^31): index / sample_rate, the
// indices exact as doubles (below 2^53) and the division correctly rounded, so the same bits as
// one sample at a time; the int offsets let the loop vectorise.
void sampleTimes(std::uint64_t first, Eigen::Index n, double sample_rate, double* out) {
  const double base = static_cast<double>(first);
  const int m = static_cast<int>(n);
  for (int i = 0; i < m; ++i) out[i] = (base + static_cast<double>(i)) / sample_rate;
}

// The blocks of streamSignalBag's ranges, filled from the chunks in order: the current range
// r's channels are written where chunks cover them; the samples up to `filled` are written,
// those of a gap are set to NaN when the next chunk or the range's end shows it. A range that
// begins before the previous one ends starts with the overlap copied from that block.
class RangeBlocks {
 public:
  using Ranges = std::vector<std::pair<Eigen::Index, Eigen::Index>>;
  using Sink = std::function<Status(const gear_sim::SignalTable&, size_t)>;
  RangeBlocks(const BagSignalInfo& info, const Ranges& ranges, const Sink& sink,
              gear_sim::SignalTable& block, const StreamColumns& columns)
      : info_(info), ranges_(ranges), sink_(sink), block_(block), columns_(columns) {
    start();
  }
  // Emits every range that ends at or before sample `upto` (gap samples NaN).
  Status flushUpTo(Eigen::Index upto) {
    while (r_ < ranges_.size() && ranges_[r_].second <= upto)
      if (Status s = emit(); !s.ok()) return s;
    return {};
  }
  // Chunk c (its first sample b, global) into the ranges it covers, each emitted when complete.
  Status take(const RawChunk& c, Eigen::Index b) {
    const Eigen::Index e = b + static_cast<Eigen::Index>(c.dte.size());
    if (Status s = flushUpTo(b); !s.ok()) return s;
    while (r_ < ranges_.size() && ranges_[r_].first < e) {
      const Eigen::Index lo = std::max(b, ranges_[r_].first), hi = std::min(e, ranges_[r_].second);
      copy(c, b, lo, hi);
      if (hi < ranges_[r_].second) break;  // the range continues in the next chunk
      if (Status s = emit(); !s.ok()) return s;
    }
    return {};
  }

 private:
  std::array<Eigen::VectorXd*, 7> channels() {
    return {&block_.dte,        &block_.dte_velocity, &block_.stiffness, &block_.torque,
            &block_.mesh_state, &block_.mesh_phase,   &block_.damping};
  }
  // Range r_'s block sized, its time column set, its overlap with the previous range (carry_)
  // written (the columns left out empty).
  void start() {
    const Eigen::Index n = ranges_[r_].second - ranges_[r_].first;
    auto make = [&](bool present, Eigen::VectorXd& v) { v.resize(present ? n : 0); };
    block_.time.resize(columns_.time ? n : 0);
    const Eigen::Index times = block_.time.size();
    const std::uint64_t first = info_.first_index + static_cast<std::uint64_t>(ranges_[r_].first);
    if (times < std::numeric_limits<int>::max()) {
      sampleTimes(first, times, info_.sample_rate, block_.time.data());
    } else {
      for (Eigen::Index i = 0; i < times; ++i)
        block_.time[i] =
            static_cast<double>(first + static_cast<std::uint64_t>(i)) / info_.sample_rate;
    }
    make(true, block_.dte);
    make(info_.dte_velocity && columns_.dte_velocity, block_.dte_velocity);
    make(info_.stiffness, block_.stiffness);
    make(info_.torque, block_.torque);
    make(info_.mesh_state, block_.mesh_state);
    make(info_.mesh_phase, block_.mesh_phase);
    make(info_.damping && columns_.damping, block_.damping);
    filled_ = std::min<Eigen::Index>(carried_, n);
    const auto to = channels();
    for (size_t k = 0; k < to.size(); ++k)
      if (to[k]->size() > 0) to[k]->head(filled_) = carry_[k].head(filled_);
  }
  void gapUpTo(Eigen::Index to) {  // NaN over [filled_, to) of every channel present
    if (to <= filled_) return;
    for (Eigen::VectorXd* v : channels())
      if (v->size() > 0) v->segment(filled_, to - filled_).setConstant(kNaN);
    filled_ = to;
  }
  // The current range to the sink, the next one started (and emitted too when its overlap with
  // the previous one completes it).
  Status emit() {
    for (;;) {
      const Eigen::Index n = ranges_[r_].second - ranges_[r_].first;
      gapUpTo(n);
      const bool next = r_ + 1 < ranges_.size();
      carried_ = next ? std::max<Eigen::Index>(ranges_[r_].second - ranges_[r_ + 1].first, 0) : 0;
      const auto from = channels();
      for (size_t k = 0; carried_ > 0 && k < from.size(); ++k)
        carry_[k] = from[k]->size() > 0 ? from[k]->tail(carried_).eval() : Eigen::VectorXd();
      if (Status s = sink_(block_, r_); !s.ok()) return s;
      ++r_;
      if (!next) return {};
      start();
      if (carried_ == 0 || filled_ < ranges_[r_].second - ranges_[r_].first) return {};
    }
  }
  // Samples [lo, hi) (global, from chunk sample b) of chunk c into the current range.
  void copy(const RawChunk& c, Eigen::Index b, Eigen::Index lo, Eigen::Index hi) {
    const Eigen::Index i0 = lo - ranges_[r_].first, n = hi - lo;
    const size_t j0 = static_cast<size_t>(lo - b);
    gapUpTo(i0);
    auto channel = [&](const RawArray& from, size_t k, Eigen::VectorXd& to) {
      if (to.size() == 0) return;
      if (c.plausible)  // (the same bits as plausibleCopy's, with a fraction of its instructions)
        std::memcpy(to.data() + i0, from.p + 8 * j0, 8 * static_cast<size_t>(n));
      else
        plausibleCopy(from.p + 8 * j0, n, kPlausibleRanges[k], to.data() + i0);
    };
    channel(c.dte, 0, block_.dte);
    channel(c.dte_velocity, 1, block_.dte_velocity);
    channel(c.stiffness, 2, block_.stiffness);
    channel(c.torque, 3, block_.torque);
    if (block_.mesh_state.size() > 0)
      meshStates(c.mesh_state.p + j0, n, block_.mesh_state.data() + i0);
    channel(c.mesh_phase, 4, block_.mesh_phase);
    channel(c.damping, 5, block_.damping);
    filled_ = std::max(filled_, i0 + n);
  }

  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  const BagSignalInfo& info_;
  const Ranges& ranges_;
  const Sink& sink_;
  gear_sim::SignalTable& block_;
  const StreamColumns columns_;
  size_t r_ = 0;
  Eigen::Index filled_ = 0;
  Eigen::Index carried_ = 0;              // samples of carry_ (the overlap)
  std::array<Eigen::VectorXd, 7> carry_;  // the previous block's last carried_ samples
};

// streamSignalBag with the ranges' samples in `block` (the caller's storage: a record read whole
// is read into its table, not copied out of the stream's).
Status streamInto(const BagSignalInfo& info,
                  const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges,
                  const std::function<Status(const gear_sim::SignalTable&, size_t)>& sink,
                  gear_sim::SignalTable& block, PassScan* pass = nullptr,
                  const StreamColumns& columns = {}) {
  if (ranges.empty()) return {};
  for (size_t k = 0; k < ranges.size(); ++k)
    if (ranges[k].second < ranges[k].first || ranges[k].second > info.samples ||
        (k > 0 &&
         (ranges[k].first < ranges[k - 1].first || ranges[k].second < ranges[k - 1].second)) ||
        ranges[k].first < 0) {
      return Status::invalidInput(
          info.path + ": sample range " + std::to_string(k) + " [" +
          std::to_string(ranges[k].first) + ", " + std::to_string(ranges[k].second) +
          ") is not ascending within the record's " + std::to_string(info.samples) + " samples");
    }
  RangeBlocks blocks(info, ranges, sink, block, columns);
  try {
    // Reads ahead on its own thread.
    ChunkReader reader(info, pass);
    const unsigned channels = channelSet(info);
    // One message into the ranges. Validated by scanSignalBag; a chunk of a bag changed since is
    // not read out of bounds (outside the scanned indices, other channels or channels of other
    // lengths: its samples stay a gap).
    auto take = [&](const ChunkReader::Message& m) {
      const RawChunk& c = m.c;
      if (!m.valid || c.first_index < info.first_index ||
          c.first_index - info.first_index > static_cast<std::uint64_t>(info.samples) ||
          channelSet(c) != channels || !channelLengthError(c).empty())
        return Status();
      return blocks.take(c, static_cast<Eigen::Index>(c.first_index - info.first_index));
    };
    ChunkReader::Chunk item;
    while (reader.next(&item))
      for (const ChunkReader::Message& m : item.messages)
        if (Status s = take(m); !s.ok()) return s;
    if (!reader.error().empty()) return Status::invalidInput(reader.error());
    if (Status s = blocks.flushUpTo(std::numeric_limits<Eigen::Index>::max()); !s.ok()) return s;
  } catch (const std::exception& e) {
    return Status::invalidInput(openError(info.path, e));
  }
  return {};
}

// Fills the ranges' blocks (streamInto) on a thread of its own while the caller's sink works on
// the previous block: the plausibility copy of the chunks into a block overlaps the analysis of
// the block before (issue 18: reading and computing overlapped). One block waits at most; the
// blocks are handed over by swapping tables, so two are held.
class BlockPipe {
 public:
  BlockPipe(const BagSignalInfo& info,
            const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges,
            PassScan* pass = nullptr, const StreamColumns& columns = {})
      : thread_([this, &info, &ranges, pass, columns] { run(info, ranges, pass, columns); }) {}
  ~BlockPipe() { stopAndJoin(mutex_, cv_, &stop_, thread_); }
  BlockPipe(const BlockPipe&) = delete;
  BlockPipe& operator=(const BlockPipe&) = delete;

  /// Every block to `sink` in order, then the stream's outcome; a failed sink stops it.
  Status drain(const std::function<Status(const gear_sim::SignalTable&, size_t)>& sink) {
    for (;;) {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait(lock, [this] { return full_ || done_; });
      if (!full_) return status_;  // done, every block handed over
      lock.unlock();
      // `ready_` is the caller's until full_ is cleared.
      if (Status s = sink(ready_, range_); !s.ok()) return s;  // the destructor stops the thread
      lock.lock();
      full_ = false;
      cv_.notify_all();
    }
  }

 private:
  void run(const BagSignalInfo& info,
           const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges, PassScan* pass,
           const StreamColumns& columns) {
    gear_sim::SignalTable block;
    const Status s = streamInto(
        info, ranges,
        [&](const gear_sim::SignalTable&, size_t r) {
          std::unique_lock<std::mutex> lock(mutex_);
          cv_.wait(lock, [this] { return stop_ || !full_; });
          if (stop_) return Status::invalidInput("stopped");  // never seen: the caller left
          std::swap(block, ready_);                           // every column's storage, no copy
          range_ = r;
          full_ = true;
          cv_.notify_all();
          return Status();
        },
        block, pass, columns);
    std::lock_guard<std::mutex> lock(mutex_);
    status_ = s;
    done_ = true;
    cv_.notify_all();
  }

  std::mutex mutex_;
  std::condition_variable cv_;
  gear_sim::SignalTable ready_;  // the block handed over (full_)
  size_t range_ = 0;
  bool full_ = false, done_ = false, stop_ = false;
  Status status_;
  std::thread thread_;  // last: started once the members above exist
};

}  // namespace

Status streamSignalBag(const BagSignalInfo& info,
                       const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges,
                       const std::function<Status(const gear_sim::SignalTable&, size_t)>& sink,
                       const StreamColumns& columns) {
  BlockPipe pipe(info, ranges, nullptr, columns);
  return pipe.drain(sink);
}

namespace {
// The fields of the direct message `d` (its record's offset) into *c, its chunk's data read into
// *bytes (which *c points into); false when it cannot be read or its layout does not fit.
bool readDirectMessage(const DirectFile& file, const BagSignalInfo::DirectMessage& d,
                       std::vector<std::uint8_t>* bytes, RawChunk* c) {
  std::uint32_t offset = 0, size = 0;
  return file.read(d.chunk_pos, d.chunk_len, bytes) &&
         messageData(bytes->data(), d.chunk_len, d.offset, &offset, &size) &&
         chunkLayout(bytes->data() + offset, size, c).empty();
}

// A chunk as ChunkScan's checks of one chunk would pass it.
bool chunkFits(const RawChunk& c) {
  return c.sample_rate > 0.0 && std::isfinite(c.sample_rate) && !c.dte.empty() &&
         channelLengthError(c).empty() && c.first_index < kMaxSampleIndex &&
         c.dte.size() <= kMaxSampleIndex - c.first_index;
}

// The mean stiffness of the default window's prefix as ChunkScan gives it, from the direct
// messages from the first (`first`) on, their chunks read once each; false when a message does
// not fit or does not follow the previous one (the scan refuses or reads such a bag its way).
bool previewPrefix(const DirectFile& file, const std::vector<BagSignalInfo::DirectMessage>& direct,
                   const RawChunk& first, double* mean) {
  const auto prefix = static_cast<std::uint64_t>(gear_sim::kWindowPrefixSamples);
  gear_sim::FiniteSum k;
  std::vector<std::uint8_t> bytes;
  std::uint64_t next = first.first_index;
  for (size_t i = 0; i < direct.size() && next - first.first_index < prefix; ++i) {
    const BagSignalInfo::DirectMessage& d = direct[i];
    if ((i == 0 || d.chunk_pos != direct[i - 1].chunk_pos) &&
        !file.read(d.chunk_pos, d.chunk_len, &bytes))
      return false;
    std::uint32_t offset = 0, size = 0;
    RawChunk c;
    if (!messageData(bytes.data(), d.chunk_len, d.offset, &offset, &size) ||
        !chunkLayout(bytes.data() + offset, size, &c).empty() || !chunkFits(c) ||
        c.sample_rate != first.sample_rate || channelSet(c) != channelSet(first) ||
        c.first_index < next)
      return false;
    addPrefix(c, c.first_index - first.first_index, &k);
    next = c.first_index + c.dte.size();
  }
  *mean = k.mean();
  return true;
}

// What scanSignalBag knows of `info` before its pass (prepareScan's fields).
BagSignalInfo scanStart(const BagSignalInfo& info) {
  BagSignalInfo out;
  out.path = info.path;
  out.topic = info.topic;
  out.params_topic = info.params_topic;
  out.has_params = info.has_params;
  out.params_error = info.params_error;
  out.params = info.params;
  out.messages_indexed = info.messages_indexed;
  out.direct = info.direct;
  std::copy(info.stamp, info.stamp + 5, out.stamp);
  return out;
}
}  // namespace

bool previewSignalBag(const std::string& path, const std::string& topic, BagSignalInfo* info) {
  BagSignalInfo out;
  std::future<std::unique_ptr<rosbag::Bag>> pending = constructBag();
  BagStructure structure;
  if (!checkBagStructure(path, &structure).ok()) return false;
  try {
    if (!prepareScan(*pending.get(), path, topic, structure, &out).ok() || out.direct.empty())
      return false;
  } catch (const std::exception&) {
    return false;
  }
  std::copy(structure.stamp, structure.stamp + 5, out.stamp);
  const DirectFile file(path);
  std::vector<std::uint8_t> first_bytes, last_bytes;
  RawChunk first, last;
  if (!file.is(out.stamp) || !readDirectMessage(file, out.direct.front(), &first_bytes, &first) ||
      !readDirectMessage(file, out.direct.back(), &last_bytes, &last) || !chunkFits(first) ||
      !chunkFits(last) || last.sample_rate != first.sample_rate ||
      channelSet(last) != channelSet(first) ||
      (out.direct.size() > 1 && last.first_index < first.first_index + first.dte.size()))
    return false;
  out.sample_rate = first.sample_rate;
  out.first_index = first.first_index;
  out.samples = static_cast<std::int64_t>(last.first_index + last.dte.size() - first.first_index);
  // The scan refuses gaps of more than kMaxGapRatio x the samples present, at most the chunks'
  // bytes / 8: a longer span (a corrupt first_index) is left to it before anything is allocated.
  std::uint64_t bytes = 0;
  for (size_t i = 0; i < out.direct.size(); ++i)
    if (i == 0 || out.direct[i].chunk_pos != out.direct[i - 1].chunk_pos)
      bytes += out.direct[i].chunk_len;
  if (static_cast<double>(out.samples) > (1.0 + kMaxGapRatio) * static_cast<double>(bytes / 8))
    return false;
  if (!previewPrefix(file, out.direct, first, &out.stiffness_mean)) return false;
  setChannels(channelSet(first), &out);
  *info = std::move(out);
  return true;
}

Status scanStreamSignalBag(BagSignalInfo* info,
                           const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges,
                           const std::function<Status(const gear_sim::SignalTable&, size_t)>& sink,
                           const StreamColumns& columns) {
  PassScan pass(scanStart(*info));
  Status s;
  {
    BlockPipe pipe(*info, ranges, &pass, columns);
    s = pipe.drain(sink);
  }  // the reader threads joined
  if (!pass.status.ok()) return pass.status;
  if (!s.ok()) return s;
  const BagSignalInfo& out = pass.out;
  // (the stiffness means compared as bits: the default window depends on them)
  if (!pass.finished || out.samples != info->samples || out.sample_rate != info->sample_rate ||
      out.first_index != info->first_index || channelSet(out) != channelSet(*info) ||
      std::memcmp(&out.stiffness_mean, &info->stiffness_mean, sizeof(double)) != 0)
    return Status::invalidInput(info->path + ": the scan differs from the preview");
  *info = std::move(pass.out);
  return {};
}

Status readSignalBag(const BagSignalInfo& info, gear_sim::SignalTable* out) {
  *out = gear_sim::SignalTable{};  // one range: the record, read into *out
  return streamInto(
      info, {{0, static_cast<Eigen::Index>(info.samples)}},
      [](const gear_sim::SignalTable&, size_t) { return Status(); }, *out);
}

Status checkBagTimes(const gear_sim::SignalTable& t, double sample_rate) {
  if (t.size() == 0) return Status::invalidInput("no samples");
  const double first = t.time[0], last = t.time[t.size() - 1];
  if (!(first >= 0.0) || !(last <= kMaxBagTime))
    return Status::invalidInput(
        "time " + formatNumber(first < 0.0 || !std::isfinite(first) ? first : last) +
            " s outside [0, " + formatNumber(kMaxBagTime) +
            "] s, the range a bag's time stamps (ros::Time) can hold",
        "time");
  if (!(first * sample_rate + static_cast<double>(t.size()) < static_cast<double>(kMaxSampleIndex)))
    return Status::invalidInput(
        "sample indices (time x sample_rate " + formatNumber(sample_rate) + " Hz) beyond 2^53",
        "time");
  return {};
}

Status writeSignalBag(const std::string& path, const gear_sim::SignalTable& t, double sample_rate,
                      const gear_sim::GearModel* params, long chunk_size, const std::string& topic,
                      const std::string& params_topic) {
  if (!(chunk_size > 0) || t.size() == 0 || !(sample_rate > 0.0))
    return Status::invalidInput(
        path + ": nothing to write (empty record, chunk size or sample rate not positive)");
  if (Status s = checkBagTimes(t, sample_rate); !s.ok()) return s.withContext(path);
  return writeBagStaged(path, params, params_topic, [&](rosbag::Bag& bag, const ros::Time& base) {
    const std::uint64_t first =
        static_cast<std::uint64_t>(std::llround(std::max(0.0, t.time[0] * sample_rate)));
    gear_damping::SignalChunk chunk;
    for (Eigen::Index b = 0; b < t.size(); b += chunk_size) {
      const Eigen::Index n = std::min<Eigen::Index>(chunk_size, t.size() - b);
      toChunk(t, b, n, sample_rate, first + static_cast<std::uint64_t>(b), &chunk);
      chunk.header.seq = static_cast<std::uint32_t>(b / chunk_size);
      chunk.header.stamp = base + ros::Duration(t.time[b]);
      bag.write(topic, chunk.header.stamp, chunk);
    }
  });
}

void discardBag(std::unique_ptr<rosbag::Bag> bag, const std::string& path) noexcept {
  if (!bag) return;
  try {
    bag->close();
  } catch (...) {
    (void)::truncate(path.c_str(), 0);
    try {
      bag->close();
    } catch (...) {
      (void)bag.release();
    }
  }
}

Status writeBagStaged(const std::string& path, const gear_sim::GearModel* params,
                      const std::string& params_topic,
                      const std::function<void(rosbag::Bag&, const ros::Time&)>& fill) {
  return gear_sim::writeAtomically(path, [&](const std::string& tmp) {
    std::unique_ptr<rosbag::Bag> bag;
    try {
      bag = std::make_unique<rosbag::Bag>(tmp, rosbag::bagmode::Write);
      const ros::Time base(1.0);
      if (params) {
        auto p = toMsg(*params);
        p.header.stamp = base;
        bag->write(params_topic, base, p);
      }
      fill(*bag, base);
      bag->close();
    } catch (const std::exception& e) {
      discardBag(std::move(bag), tmp);  // (a full disk: no throwing destructor)
      return Status::ioError(path + ": cannot write (" + e.what() + ")");
    }
    return Status();
  });
}

}  // namespace gear_sim_ros
