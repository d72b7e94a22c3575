// Signal records in rosbag files: gear_damping/SignalChunk messages on one topic, the gear
// parameters (gear_damping/GearParams) optionally on another. Reading is streaming (memory
// bounded by the block the caller asks for), so records of 1e7 samples and more are fine.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "gear_sim/signal_table.hpp"
#include "gear_sim/sim_config.hpp"
#include "gear_sim/status.hpp"

namespace rosbag {
class MessageInstance;
}

namespace rosbag {
class Bag;
}
namespace ros {
class Time;
}

namespace gear_sim_ros {

/// Largest --chunk-size of the tools writing bags (samples per SignalChunk message).
constexpr long kMaxChunkSize = 10000000;

/// Largest sample index a bag may hold (2^53: sample times index / rate stay exact and no
/// index arithmetic can wrap). A chunk beyond it is refused naming it.
constexpr std::uint64_t kMaxSampleIndex = std::uint64_t{1} << 53;
/// Gaps may hold at most this many missing samples per sample present: readers allocate the
/// record's span (gaps read as NaN), so a forward jump of the index is refused before any
/// allocation, naming the largest gap.
constexpr double kMaxGapRatio = 1.0;
/// Physical plausibility ranges of bag data: the records' (gear_sim/signal_table.hpp).
using gear_sim::kPlausibleRanges;
using gear_sim::PlausibleRange;
/// A chunk whose max |dte| is this many times the record's median chunk maximum is an outlier.
constexpr double kOutlierChunkFactor = 1e6;

/// What scanSignalBag found out about a bag's signal record.
struct BagSignalInfo {
  std::string path;
  std::string topic;         ///< the SignalChunk topic read
  std::string params_topic;  ///< the GearParams topic, empty when none
  bool has_params = false;   ///< `params` is valid (from the latest GearParams message)
  std::string params_error;  ///< why a present GearParams message could not be used
  gear_sim::GearModel params;
  double sample_rate = 0.0;       ///< [Hz] of every chunk
  std::uint64_t first_index = 0;  ///< global index of the first sample
  long chunks = 0;
  std::int64_t samples = 0;      ///< samples from the first to the last, gaps included
  std::int64_t gap_samples = 0;  ///< samples missing in gaps (read as NaN)
  long gaps = 0;
  std::int64_t real_samples = 0;  ///< samples the chunks carry (samples - gap_samples)
  /// Plausibility of the chunk data (see kPlausibleRanges): samples of any channel that are
  /// NaN/Inf, finite but outside their channel's range, and mesh_state values other than 0 or
  /// 1. Out-of-range values and bad mesh states read as NaN; each count gives one warning.
  std::int64_t non_finite_values = 0, out_of_range_values = 0, bad_mesh_states = 0;
  /// Chunks whose largest |dte| exceeds kOutlierChunkFactor x the median over the chunks of
  /// that maximum (the record's scale): likely corrupt payloads, counted and warned about.
  long outlier_chunks = 0;
  std::vector<std::string> warnings;  ///< one line per gap (the first few) and similar remarks
  /// [N/m] mean of the finite stiffness samples among the record's first
  /// gear_sim::kWindowPrefixSamples (the default window's, defaultWindowLength; 0: none)
  double stiffness_mean = 0.0;
  /// Optional channels present (every chunk must carry the same set).
  bool dte_velocity = false, stiffness = false, torque = false, mesh_state = false,
       mesh_phase = false, damping = false;
  /// Every message record names a connection of the bag's index (BagStructure): the chunks are
  /// read in place from their bytes instead of through rosbag's deserialisation.
  bool messages_indexed = false;
  /// Where the scan read each chunk message when it read them from the file itself (one
  /// connection on the topic, uncompressed chunks, no encryptor, every message indexed), in
  /// rosbag::View's order; empty when rosbag read them. streamSignalBag reads the same bytes the
  /// same way while the file is the one walked (`stamp`, BagStructure::stamp).
  struct DirectMessage {
    std::uint64_t chunk_pos = 0;  ///< the first byte of its chunk's data in the file
    std::uint32_t chunk_len = 0;  ///< the chunk's data length
    std::uint32_t offset = 0;     ///< its data's offset in the chunk's data
    std::uint32_t size = 0;       ///< its data's length
  };
  std::vector<DirectMessage> direct;
  std::uint64_t stamp[5] = {0, 0, 0, 0, 0};
};

/// Opens `path` and validates its signal record in one pass: the topic is `topic` or, when
/// empty, the only topic of type gear_damping/SignalChunk (an error lists the candidates when
/// there are several); every chunk has the same finite, positive sample rate, the same set of
/// channels with the length of dte, and a first_index beyond the previous chunk's last sample
/// (a duplicated, overlapping or out-of-order chunk is an error naming it; a gap is a warning:
/// its samples read as NaN, so the analysers report the segments there as not identifiable).
/// Limits: indices below kMaxSampleIndex, gaps at most kMaxGapRatio x the samples present;
/// the plausibility counts of BagSignalInfo are filled and warned about.
/// The gear parameters come from the latest GearParams message on any topic.
/// InvalidInput with a one-line message: cannot open / not a bag / corrupt or truncated, no
/// such topic, wrong message type, no chunks, inconsistent chunks (field: the channel concerned,
/// when one is).
gear_sim::Status scanSignalBag(const std::string& path, const std::string& topic,
                               BagSignalInfo* info);

/// The columns of a stream's blocks (streamSignalBag, scanStreamSignalBag): by default the time
/// and every channel the record has; a sink that reads none of some leaves them out (those
/// columns of its blocks are then empty: neither computed nor copied).
struct StreamColumns {
  bool time = true;
  bool dte_velocity = true;
  bool damping = true;
};

/// Streams the record scanned into `info` as SignalTable blocks, one per range [begin, end) of
/// sample numbers counted from info.first_index (within [0, info.samples), begins and ends
/// ascending; a range may begin before the previous one ends, its block then holds the overlap
/// too): sink(table, range_index) gets the samples of each range (gaps as NaN, time = global
/// index / sample_rate). Samples outside the ranges are skipped. A failed Status from the sink
/// stops the stream and is returned as is. `columns`: the blocks' columns.
gear_sim::Status streamSignalBag(
    const BagSignalInfo& info, const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges,
    const std::function<gear_sim::Status(const gear_sim::SignalTable&, size_t)>& sink,
    const StreamColumns& columns = {});

/// One pass instead of scanSignalBag's and streamSignalBag's (issue 18: `analyze` reads the bag
/// once). previewSignalBag does what scanSignalBag does before its pass (the topic, the
/// parameters), reads the first and the last chunk message: sample_rate, first_index, the
/// channels and `samples` (exact when the scan passes), and the messages of the default window's
/// prefix: stiffness_mean (the scan's bits when it passes). False when the bag is not read that
/// way (any bag whose chunks rosbag reads, or whose first, last or prefix messages do not fit or
/// follow each other): the caller scans with scanSignalBag.
bool previewSignalBag(const std::string& path, const std::string& topic, BagSignalInfo* info);

/// streamSignalBag of `info` (from previewSignalBag; ranges from its numbers) with
/// scanSignalBag's scan done in the same pass on the reading thread; then *info is what
/// scanSignalBag gives. Any error (a scan error, a read error, a scan that cannot be done in the
/// pass or that differs from the preview: its span, rate, channels or stiffness_mean) says only
/// that this pass failed, after the sink may have seen some blocks: the caller does it again with
/// scanSignalBag and streamSignalBag, which give the error to report.
gear_sim::Status scanStreamSignalBag(
    BagSignalInfo* info, const std::vector<std::pair<Eigen::Index, Eigen::Index>>& ranges,
    const std::function<gear_sim::Status(const gear_sim::SignalTable&, size_t)>& sink,
    const StreamColumns& columns = {});

/// The whole record as one table (gaps as NaN).
gear_sim::Status readSignalBag(const BagSignalInfo& info, gear_sim::SignalTable* out);

/// Latest sample time a bag can stamp [s]: ros::Time holds 32-bit seconds and the stamps are
/// 1 s + the sample time.
constexpr double kMaxBagTime = 4294967294.0;

/// Whether `table` can be written as a bag at `sample_rate`: InvalidInput (field "time") for
/// times outside [0, kMaxBagTime] s or sample indices beyond kMaxSampleIndex. Checked by
/// writeSignalBag too.
gear_sim::Status checkBagTimes(const gear_sim::SignalTable& table, double sample_rate);

/// Closes a bag being written to file `path` after a failed write or close, so that nothing
/// throws (rosbag's destructor closes an open bag again and throws out of itself, std::terminate,
/// when that fails, as on a full disk): a failed close truncates the file (freeing its space)
/// and closes again; a bag that still cannot close is let go without its destructor (its memory
/// and descriptor stay the process's, which then ends on its error path). The caller removes the
/// file.
void discardBag(std::unique_ptr<rosbag::Bag> bag, const std::string& path) noexcept;

/// Writes a bag staged: into PATH.partial, first the gear parameters on `params_topic` (when
/// `params` is not null) stamped at the base time 1 s, then what `fill` writes (given the bag and
/// that base time); renamed onto PATH only when everything succeeded, removed otherwise.
/// IoError when it cannot be written.
gear_sim::Status writeBagStaged(const std::string& path, const gear_sim::GearModel* params,
                                const std::string& params_topic,
                                const std::function<void(rosbag::Bag&, const ros::Time&)>& fill);

/// Writes `table` (uniform time) as SignalChunk messages of `chunk_size` samples on
/// `topic` (first_index = round(time[0] * sample_rate) + i) and, when `params` is not null, the
/// gear parameters on `params_topic` first. Bag time stamps are 1 s + the sample time. Writes a
/// temporary file renamed on success. InvalidInput for a record a bag cannot hold, IoError when
/// the file cannot be written.
gear_sim::Status writeSignalBag(const std::string& path, const gear_sim::SignalTable& table,
                                double sample_rate, const gear_sim::GearModel* params,
                                long chunk_size, const std::string& topic = "/gear/signal",
                                const std::string& params_topic = "/gear/params");

/// Where a serialized SignalChunk, sensor_msgs/JointState or geometry_msgs/WrenchStamped in a bag
/// claims an array or string longer than its bytes (ROS would allocate the claimed length before
/// noticing): InvalidInput naming the problem, ok when the layout fits (and for other types).
gear_sim::Status checkMessageLayout(const rosbag::MessageInstance& m);

}  // namespace gear_sim_ros
