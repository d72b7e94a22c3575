// Structural check of a rosbag file (bag format 2.0) before rosbag reads it.
//
// rosbag trusts the lengths in a bag: ROS's header parser (ros::Header::parse) reads a field
// length and copies that many bytes without comparing them with the header's size, and the
// records inside a chunk are parsed at the offsets the index gives without bounds checks. A
// corrupt bag is then read out of bounds (found by the bag fuzz target under AddressSanitizer).
// checkBagStructure walks every record the way the format defines it and refuses the file,
// naming the byte offset, unless every length stays inside its record, chunk and file:
//   - the version line `#ROSBAG V2.0`;
//   - every record: header_len, each header field's length (`name=value`, a one-byte `op`),
//     data_len; op codes 0x02 (message data), 0x03 (bag header, first), 0x04 (index data),
//     0x05 (chunk), 0x06 (chunk info), 0x07 (connection);
//   - the bag header's index_pos (a record start; 0: unindexed), its counts;
//   - chunks: compression none/bz2/lz4 (compressed chunks are decompressed to check them), the
//     uncompressed size, and the message-data and connection records inside;
//   - connection records: the connection header in their data (the same field layout);
//   - index data records: version 1, count x 12 bytes, every offset a message-data record of
//     the chunk they follow; chunk info records: version 1, count x 8 bytes, chunk_pos a chunk.
#pragma once

#include <cstdint>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "gear_sim/status.hpp"

namespace gear_sim_ros {

/// Largest record header or connection header accepted [bytes] (ROS refuses fields above 1e6).
constexpr unsigned kMaxBagHeaderBytes = 16u << 20;
/// Largest uncompressed chunk accepted [bytes] (rosbag allocates it; its default is 768 KiB).
constexpr unsigned kMaxBagChunkBytes = 1u << 30;

/// What the walk learnt besides soundness.
struct BagStructure {
  /// Every message data record names a connection of the bag's index (rosbag's deserialisation
  /// throws "Unknown connection ID" for the others; the raw readers of bag_io need it).
  bool messages_indexed = false;
  /// A chunk record: where it starts and where its data lie in the file.
  struct Chunk {
    std::uint64_t start = 0;     ///< the chunk record's first byte
    std::uint64_t data_pos = 0;  ///< its data's first byte
    std::uint32_t data_len = 0;  ///< its data's length
    bool uncompressed = false;   ///< compression "none": the data are the records
  };
  /// Every chunk record, in file order (ascending `start`).
  std::vector<Chunk> chunks;
  /// The bag header names an encryptor (rosbag decrypts its chunks on reading).
  bool encrypted = false;
  /// A connection record: its header's topic and its connection header's type ("" if none).
  struct Connection {
    std::string topic;
    std::string type;
    bool operator<(const Connection& o) const {
      return std::tie(topic, type) < std::tie(o.topic, o.type);
    }
  };
  /// The distinct (topic, type) pairs of every connection record of the file (top level and
  /// inside chunks, where rosbag repeats them per chunk): a superset of the connections rosbag
  /// reads (those at index_pos), with the same fields.
  std::set<Connection> connections;
  /// The walked file's identity (device, inode, size, modification and status-change times in
  /// ns); all 0 when unknown (not a regular file).
  std::uint64_t stamp[5] = {0, 0, 0, 0, 0};
};

/// The identity of an open file as BagStructure::stamp holds it; all 0 when unknown.
void fileStamp(int fd, std::uint64_t out[5]);

/// Ok when `path` is a structurally sound bag of format 2.0; else InvalidInput (IoError when it
/// cannot be opened) with a one-line message ("<path>: cannot read as a bag (<reason> at byte N)").
/// The last file's result is remembered (by device, inode, size, modification and status-change
/// times) when the file was last changed more than 2 s before its walk: a bag checked twice in a
/// row is then walked once. `structure` (optional) receives what the walk learnt.
gear_sim::Status checkBagStructure(const std::string& path, BagStructure* structure = nullptr);

}  // namespace gear_sim_ros
