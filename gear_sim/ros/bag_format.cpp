#include "gear_sim_ros/bag_format.hpp"

#include <bzlib.h>
#include <fcntl.h>
#include <roslz4/lz4s.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <ctime>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "gear_sim/message_text.hpp"

namespace gear_sim_ros {
namespace {

enum Op : std::uint8_t {
  kMessageData = 0x02,
  kBagHeader = 0x03,
  kIndexData = 0x04,
  kChunk = 0x05,
  kChunkInfo = 0x06,
  kConnection = 0x07,
};

using Fields = std::map<std::string, std::string>;

std::uint32_t le32(const char* p) {
  std::uint32_t v;
  std::memcpy(&v, p, 4);  // the bag format is little-endian, like the hosts ROS runs on
  return v;
}

// Thrown by the walker with the reason and the byte offset; turned into the error message.
struct Corrupt {
  std::string what;
  std::uint64_t at;
  bool truncated = false;
};

// Parses `n` bytes as header fields (each a 4-byte length, then `name=value`), as
// ros::Header::parse does, but with every length checked against what is left.
Fields parseFields(const char* p, std::uint64_t n, std::uint64_t at, const char* what) {
  Fields fields;
  std::uint64_t k = 0;
  while (k < n) {
    if (n - k < 4)
      throw Corrupt{std::string(what) + ": a field length cut by the end of the header", at + k};
    const std::uint32_t len = le32(p + k);
    k += 4;
    if (len > n - k)
      throw Corrupt{std::string(what) + ": a field of " + std::to_string(len) +
                        " bytes where the header has " + std::to_string(n - k) + " left",
                    at + k - 4};
    const std::string field(p + k, len);
    const size_t eq = field.find('=');
    if (eq == std::string::npos)
      throw Corrupt{std::string(what) + ": a field without '='", at + k - 4};
    fields[field.substr(0, eq)] = field.substr(eq + 1);
    k += len;
  }
  return fields;
}

// A numeric field of exactly sizeof(T) bytes, as rosbag requires.
template <typename T>
T field(const Fields& f, const char* name, std::uint64_t at, const char* what) {
  const auto it = f.find(name);
  if (it == f.end()) throw Corrupt{std::string(what) + " without its '" + name + "' field", at};
  if (it->second.size() != sizeof(T))
    throw Corrupt{std::string(what) + ": field '" + name + "' of " +
                      std::to_string(it->second.size()) + " bytes, not " +
                      std::to_string(sizeof(T)),
                  at};
  T v;
  std::memcpy(&v, it->second.data(), sizeof(T));
  return v;
}

const char* opName(std::uint8_t op) {
  switch (op) {
    case kMessageData:
      return "message data record";
    case kBagHeader:
      return "bag header record";
    case kIndexData:
      return "index data record";
    case kChunk:
      return "chunk record";
    case kChunkInfo:
      return "chunk info record";
    case kConnection:
      return "connection record";
    default:
      return "record";
  }
}

// One record: where it starts, its op code and fields, where and how long its data is.
struct Record {
  std::uint64_t start = 0;
  std::uint8_t op = 0;
  Fields fields;
  std::uint64_t data_pos = 0;
  std::uint32_t data_len = 0;
};

// Reads records from a byte source (the file, or a chunk's bytes in memory) within
// [begin, end), checking every length.
class RecordSource {
 public:
  virtual ~RecordSource() = default;
  // Reads n bytes at pos into out; false when the source ends first.
  virtual bool read(std::uint64_t pos, std::uint64_t n, std::string* out) = 0;

  Record next(std::uint64_t pos, std::uint64_t end, const char* where) {
    Record r;
    r.start = pos;
    std::string b;
    if (end - pos < 4 || !read(pos, 4, &b))
      throw Corrupt{std::string("a record header length cut by the end of the ") + where, pos,
                    true};
    const std::uint32_t header_len = le32(b.data());
    if (header_len > end - pos - 4)
      throw Corrupt{"a record header of " + std::to_string(header_len) + " bytes where the " +
                        where + " has " + std::to_string(end - pos - 4) + " left",
                    pos, true};
    if (header_len > kMaxBagHeaderBytes)
      throw Corrupt{"a record header of " + std::to_string(header_len) + " bytes", pos};
    if (!read(pos + 4, header_len, &b))
      throw Corrupt{"a record header cut by the end of the " + std::string(where), pos, true};
    r.fields = parseFields(b.data(), header_len, pos + 4, "record header");
    const auto op = r.fields.find("op");
    if (op == r.fields.end() || op->second.size() != 1)
      throw Corrupt{"a record without a one-byte 'op' field", pos};
    r.op = static_cast<std::uint8_t>(op->second[0]);
    const std::uint64_t len_pos = pos + 4 + header_len;
    if (end - len_pos < 4 || !read(len_pos, 4, &b))
      throw Corrupt{std::string("a data length cut by the end of the ") + where, len_pos, true};
    r.data_len = le32(b.data());
    r.data_pos = len_pos + 4;
    if (r.data_len > end - r.data_pos)
      throw Corrupt{"a " + std::string(opName(r.op)) + " with " + std::to_string(r.data_len) +
                        " data bytes where the " + where + " has " +
                        std::to_string(end - r.data_pos) + " left",
                    len_pos, true};
    return r;
  }

  // A connection record: its conn and topic fields, and the connection header in its data.
  // Returns its topic and the connection header's type ("" when it has none).
  BagStructure::Connection checkConnection(const Record& r) {
    field<std::uint32_t>(r.fields, "conn", r.start, "connection record");
    if (r.fields.find("topic") == r.fields.end())
      throw Corrupt{"connection record without its 'topic' field", r.start};
    if (r.data_len > kMaxBagHeaderBytes)
      throw Corrupt{"a connection header of " + std::to_string(r.data_len) + " bytes", r.data_pos};
    std::string b;
    if (!read(r.data_pos, r.data_len, &b))
      throw Corrupt{"a connection header cut by the end of the file", r.data_pos, true};
    const Fields header = parseFields(b.data(), r.data_len, r.data_pos, "connection header");
    const auto type = header.find("type");
    return {r.fields.find("topic")->second, type == header.end() ? std::string() : type->second};
  }
};

// The file through a small read-ahead window (pread): a record's length, header and data
// length are read with one system call instead of a seek and a read each (the walk of a bag
// of 1e4 messages made ~1.5e5 system calls through an ifstream). Larger reads go direct.
class FileSource : public RecordSource {
 public:
  explicit FileSource(int fd) : fd_(fd), window_(kWindow) {}
  bool read(std::uint64_t pos, std::uint64_t n, std::string* out) override {
    if (pos >= start_ && n <= have_ && pos - start_ <= have_ - n) {
      out->assign(window_.data() + (pos - start_), n);
      return true;
    }
    if (n > kWindow) {
      out->resize(n);
      return readAt(pos, n, out->data()) == n;
    }
    start_ = pos;
    have_ = readAt(pos, kWindow, window_.data());
    if (have_ < n) return false;
    out->assign(window_.data(), n);
    return true;
  }

 private:
  static constexpr std::uint64_t kWindow = 4096;
  // Bytes read at pos (fewer at the end of the file or on an error).
  std::uint64_t readAt(std::uint64_t pos, std::uint64_t n, char* to) const {
    std::uint64_t got = 0;
    while (got < n) {
      const ssize_t r = ::pread(fd_, to + got, n - got, static_cast<off_t>(pos + got));
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) break;
      got += static_cast<std::uint64_t>(r);
    }
    return got;
  }
  int fd_;
  std::vector<char> window_;
  std::uint64_t start_ = 0, have_ = 0;  // the window holds [start_, start_ + have_)
};

class MemorySource : public RecordSource {
 public:
  MemorySource(const char* bytes, std::uint64_t size) : b_(bytes), size_(size) {}
  bool read(std::uint64_t pos, std::uint64_t n, std::string* out) override {
    if (pos > size_ || n > size_ - pos) return false;
    out->assign(b_ + pos, n);
    return true;
  }

 private:
  const char* b_;
  std::uint64_t size_;
};

// The records inside a chunk's (uncompressed) bytes [begin, begin + size) of `src`: message
// data and connection records only. Returns the offsets (from the chunk's start) of the
// message-data records, ascending. `base` is the file offset of the chunk's data (for messages).
std::vector<std::uint32_t> checkChunkRecords(RecordSource* src, std::uint64_t begin,
                                             std::uint64_t size, std::uint64_t base, bool in_file,
                                             std::set<std::uint32_t>* conns,
                                             std::set<BagStructure::Connection>* connections) {
  std::vector<std::uint32_t> messages;
  const std::uint64_t end = begin + size;
  for (std::uint64_t pos = begin; pos < end;) {
    Record r;
    try {
      r = src->next(pos, end, "chunk");
    } catch (Corrupt& c) {
      if (!in_file) c.at = base;  // offsets inside compressed data mean nothing to the reader
      c.truncated = false;
      throw;
    }
    const std::uint64_t at = in_file ? r.start : base;
    if (r.op == kMessageData) {
      conns->insert(field<std::uint32_t>(r.fields, "conn", at, "message data record"));
      field<std::uint64_t>(r.fields, "time", at, "message data record");
      messages.push_back(static_cast<std::uint32_t>(r.start - begin));
    } else if (r.op == kConnection) {
      try {
        connections->insert(src->checkConnection(r));
      } catch (Corrupt& c) {
        if (!in_file) c.at = base;
        throw;
      }
    } else {
      throw Corrupt{
          "a " + std::string(opName(r.op)) + " (op " + std::to_string(r.op) + ") inside a chunk",
          at};
    }
    pos = r.data_pos + r.data_len;
  }
  return messages;
}

// The chunk's `size` bytes, uncompressed (the buffer is left uninitialised: a corrupt size
// claims address space, not memory, as in rosbag).
std::unique_ptr<char[]> decompress(const std::string& compression, std::string* in,
                                   std::uint32_t size, std::uint64_t at) {
  std::unique_ptr<char[]> out(new char[std::max<std::uint32_t>(size, 1)]);
  unsigned int produced = size;
  if (compression == "bz2") {
    if (BZ2_bzBuffToBuffDecompress(out.get(), &produced, in->data(),
                                   static_cast<unsigned int>(in->size()), 0, 0) != BZ_OK)
      throw Corrupt{"a bz2 chunk that does not decompress", at};
  } else if (roslz4_buffToBuffDecompress(in->data(), static_cast<unsigned int>(in->size()),
                                         out.get(), &produced) != ROSLZ4_OK) {
    throw Corrupt{"an lz4 chunk that does not decompress", at};
  }
  if (produced != size)
    throw Corrupt{"a chunk of " + std::to_string(produced) + " bytes uncompressed, not " +
                      std::to_string(size) + " as its header says",
                  at};
  return out;
}

// The structure check of a whole bag: the version line, then every top-level record in order
// (bag header first, chunks with the records inside them, index data against the chunk before
// it, chunk infos, connections), then the cross-references (index_pos, chunk_pos).
class BagWalker {
 public:
  BagWalker(int fd, std::uint64_t file_size) : src_(fd), file_size_(file_size) {}

  // The chunk records (BagStructure::chunks).
  const std::vector<BagStructure::Chunk>& chunks() const { return chunks_; }
  bool encrypted() const { return encrypted_; }
  const std::set<BagStructure::Connection>& connections() const { return connections_; }

  // Whether every message data record names a connection of the index (checkBagStructure).
  bool messagesIndexed() const {
    // rosbag reads conn_count connection records from index_pos on (refusing other records);
    // deserialising a message whose record names another connection throws.
    const auto first = std::lower_bound(starts_.begin(), starts_.end(), index_pos_);
    std::set<std::uint32_t> known;
    for (std::uint64_t c = 0; c < conn_count_; ++c) {
      const auto at = first + static_cast<std::ptrdiff_t>(c);
      if (at >= starts_.end()) return false;
      const auto conn = top_connections_.find(*at);
      if (conn == top_connections_.end()) return false;
      known.insert(conn->second);
    }
    return std::includes(known.begin(), known.end(), message_conns_.begin(), message_conns_.end());
  }

  void walk() {
    checkVersion();
    for (std::uint64_t pos = kVersionLength; pos < file_size_;) {
      const Record r = src_.next(pos, file_size_, "file");
      starts_.push_back(r.start);
      if (starts_.size() == 1 && r.op != kBagHeader)
        throw Corrupt{"the first record is not the bag header", r.start};
      record(r);
      pos = r.data_pos + r.data_len;
    }
    checkReferences();
  }

 private:
  static constexpr char kVersion[] = "#ROSBAG V2.0\n";
  static constexpr std::uint64_t kVersionLength = sizeof(kVersion) - 1;

  void checkVersion() {
    std::string b;
    if (src_.read(0, kVersionLength, &b) && b == kVersion) return;
    std::string line;
    src_.read(0, std::min<std::uint64_t>(file_size_, 64), &line);
    line = line.substr(0, line.find('\n'));
    if (line.rfind("#ROSBAG V", 0) == 0)
      throw Corrupt{
          "bag format " + gear_sim::quoteForMessage(line.substr(9)) + ": only version 2.0 is read",
          0};
    throw Corrupt{"no '#ROSBAG V2.0' line: not a bag", 0};
  }

  void record(const Record& r) {
    switch (r.op) {
      case kBagHeader:
        if (starts_.size() != 1) throw Corrupt{"a second bag header record", r.start};
        index_pos_ = field<std::uint64_t>(r.fields, "index_pos", r.start, "bag header");
        conn_count_ = field<std::uint32_t>(r.fields, "conn_count", r.start, "bag header");
        field<std::uint32_t>(r.fields, "chunk_count", r.start, "bag header");
        encrypted_ = r.fields.count("encryptor") > 0;
        break;
      case kChunk:
        chunk(r);
        break;
      case kIndexData:
        indexData(r);
        break;
      case kChunkInfo:
        chunkInfo(r);
        break;
      case kConnection:
        connections_.insert(src_.checkConnection(r));
        top_connections_[r.start] =
            field<std::uint32_t>(r.fields, "conn", r.start, "connection record");
        break;
      case kMessageData:
        message_conns_.insert(
            field<std::uint32_t>(r.fields, "conn", r.start, "message data record"));
        field<std::uint64_t>(r.fields, "time", r.start, "message data record");
        break;
      default:
        throw Corrupt{"unknown op code " + std::to_string(r.op), r.start};
    }
  }

  // A chunk: its records (read in place, or decompressed), whose message offsets the index data
  // records after it are checked against.
  void chunk(const Record& r) {
    const auto c = r.fields.find("compression");
    if (c == r.fields.end()) throw Corrupt{"chunk record without 'compression'", r.start};
    const std::uint32_t size = field<std::uint32_t>(r.fields, "size", r.start, "chunk record");
    if (c->second == "none") {
      if (size != r.data_len)
        throw Corrupt{"an uncompressed chunk of " + std::to_string(r.data_len) +
                          " bytes whose header says " + std::to_string(size),
                      r.start};
      chunk_messages_[r.start] = checkChunkRecords(&src_, r.data_pos, r.data_len, r.data_pos, true,
                                                   &message_conns_, &connections_);
    } else if (c->second == "bz2" || c->second == "lz4") {
      if (size > kMaxBagChunkBytes || r.data_len > kMaxBagChunkBytes)
        throw Corrupt{"a compressed chunk of " + std::to_string(size) + " bytes", r.start};
      std::string packed;
      if (!src_.read(r.data_pos, r.data_len, &packed))
        throw Corrupt{"a chunk cut by the end of the file", r.data_pos, true};
      const std::unique_ptr<char[]> bytes = decompress(c->second, &packed, size, r.start);
      MemorySource mem(bytes.get(), size);
      chunk_messages_[r.start] =
          checkChunkRecords(&mem, 0, size, r.start, false, &message_conns_, &connections_);
    } else {
      throw Corrupt{
          "chunk compression " + gear_sim::quoteForMessage(c->second) + " (none, bz2 or lz4)",
          r.start};
    }
    last_chunk_ = r.start;
    chunks_.push_back({r.start, r.data_pos, r.data_len, c->second == "none"});
  }

  // An index data record: every entry points at a message of the chunk before it (read in
  // blocks: a corrupt count claims no memory).
  void indexData(const Record& r) {
    if (field<std::uint32_t>(r.fields, "ver", r.start, "index data record") != 1)
      throw Corrupt{"index data record of a version other than 1", r.start};
    field<std::uint32_t>(r.fields, "conn", r.start, "index data record");
    const std::uint32_t count =
        field<std::uint32_t>(r.fields, "count", r.start, "index data record");
    if (!last_chunk_) throw Corrupt{"an index data record before any chunk", r.start};
    if (std::uint64_t{count} * 12 != r.data_len)
      throw Corrupt{"an index data record of " + std::to_string(count) + " entries in " +
                        std::to_string(r.data_len) + " bytes (12 each)",
                    r.start};
    const auto& messages = chunk_messages_[*last_chunk_];
    const std::uint64_t block = 12 * 4096;
    std::string b;
    for (std::uint64_t k = 0; k < r.data_len; k += block) {
      const std::uint64_t n = std::min<std::uint64_t>(block, r.data_len - k);
      if (!src_.read(r.data_pos + k, n, &b))
        throw Corrupt{"an index cut by the end of the file", r.data_pos + k, true};
      for (std::uint64_t e = 0; e < n; e += 12) {
        const std::uint32_t offset = le32(b.data() + e + 8);
        if (!std::binary_search(messages.begin(), messages.end(), offset))
          throw Corrupt{"an index entry pointing at chunk offset " + std::to_string(offset) +
                            ", not a message of the chunk at byte " + std::to_string(*last_chunk_),
                        r.data_pos + k + e};
      }
    }
  }

  void chunkInfo(const Record& r) {
    if (field<std::uint32_t>(r.fields, "ver", r.start, "chunk info record") != 1)
      throw Corrupt{"chunk info record of a version other than 1", r.start};
    const std::uint64_t chunk_pos =
        field<std::uint64_t>(r.fields, "chunk_pos", r.start, "chunk info record");
    field<std::uint64_t>(r.fields, "start_time", r.start, "chunk info record");
    field<std::uint64_t>(r.fields, "end_time", r.start, "chunk info record");
    const std::uint32_t count =
        field<std::uint32_t>(r.fields, "count", r.start, "chunk info record");
    if (std::uint64_t{count} * 8 != r.data_len)
      throw Corrupt{"a chunk info record of " + std::to_string(count) + " entries in " +
                        std::to_string(r.data_len) + " bytes (8 each)",
                    r.start};
    chunk_refs_.emplace_back(r.start, chunk_pos);
  }

  // index_pos at a record, every chunk info at a chunk.
  void checkReferences() const {
    if (starts_.empty()) throw Corrupt{"no bag header record", kVersionLength, true};
    if (index_pos_ == 0)
      throw Corrupt{"unindexed (index_pos 0): the recording did not finish", kVersionLength, true};
    if (!std::binary_search(starts_.begin(), starts_.end(), index_pos_))
      throw Corrupt{"index_pos " + std::to_string(index_pos_) + " is not the start of a record",
                    kVersionLength, index_pos_ >= file_size_};
    for (const auto& [at, chunk_pos] : chunk_refs_)
      if (chunk_messages_.find(chunk_pos) == chunk_messages_.end())
        throw Corrupt{"chunk_pos " + std::to_string(chunk_pos) + " is not a chunk record", at};
  }

  FileSource src_;
  const std::uint64_t file_size_;
  std::uint64_t index_pos_ = 0;
  std::vector<std::uint64_t> starts_;                                   // top-level record starts
  std::map<std::uint64_t, std::vector<std::uint32_t>> chunk_messages_;  // chunk start -> offsets
  std::vector<std::pair<std::uint64_t, std::uint64_t>> chunk_refs_;     // chunk info: (at, pos)
  std::optional<std::uint64_t> last_chunk_;
  std::uint32_t conn_count_ = 0;
  std::map<std::uint64_t, std::uint32_t> top_connections_;  // top-level connection: start -> conn
  std::set<std::uint32_t> message_conns_;                   // conn of every message data record
  std::vector<BagStructure::Chunk> chunks_;
  std::set<BagStructure::Connection> connections_;  // distinct (topic, type) of connection records
  bool encrypted_ = false;
};

// Walks the file into *structure.
void walk(int fd, std::uint64_t file_size, BagStructure* structure) {
  BagWalker walker(fd, file_size);
  walker.walk();
  structure->messages_indexed = walker.messagesIndexed();
  structure->chunks = walker.chunks();
  structure->encrypted = walker.encrypted();
  structure->connections = walker.connections();
}

}  // namespace

namespace {

// The walk's result for one file, keyed by its identity and status-change time: `analyze` checks
// a bag before it tells a rig bag from a signal bag and again before it scans the signal bag
// (each walk reads every record header of the file). Only a file last changed well before its
// walk started is remembered: a file rewritten since (even within the file system's timestamp
// granularity, as a fuzzer rewrites its input) then shows a later change time.
struct CheckedFile {
  std::string path;
  dev_t dev = 0;
  ino_t ino = 0;
  off_t size = 0;
  timespec mtime{}, ctime{};
  gear_sim::Status status;
  BagStructure structure;
};

bool sameFile(const CheckedFile& c, const std::string& path, const struct stat& st) {
  return c.path == path && c.dev == st.st_dev && c.ino == st.st_ino && c.size == st.st_size &&
         c.mtime.tv_sec == st.st_mtim.tv_sec && c.mtime.tv_nsec == st.st_mtim.tv_nsec &&
         c.ctime.tv_sec == st.st_ctim.tv_sec && c.ctime.tv_nsec == st.st_ctim.tv_nsec;
}

// Whether a file of status `st`, walked from `start` (CLOCK_REALTIME, the file times' clock) on,
// may be remembered: changed at least 2 s before.
bool settled(const struct stat& st, const timespec& start) {
  const auto before = [&](const timespec& t) { return t.tv_sec + 2 < start.tv_sec; };
  return before(st.st_mtim) && before(st.st_ctim);
}

gear_sim::Status walkFile(int fd, const std::string& path, BagStructure* structure) {
  using gear_sim::Status;
  const off_t end = ::lseek(fd, 0, SEEK_END);
  if (end < 0) return Status::ioError(path + ": cannot read as a bag (cannot determine its size)");
  try {
    walk(fd, static_cast<std::uint64_t>(end), structure);
  } catch (const Corrupt& c) {
    *structure = BagStructure{};
    return Status::invalidInput(
        path + ": cannot read as a bag (" + c.what + " at byte " + std::to_string(c.at) + ")" +
        (c.truncated ? "; if it is truncated, `rosbag reindex` may recover it" : ""));
  }
  return {};
}

}  // namespace

namespace {
// BagStructure::stamp of a regular file's status.
void stampOf(const struct stat& st, std::uint64_t out[5]) {
  const auto ns = [](const timespec& t) {
    return static_cast<std::uint64_t>(t.tv_sec) * 1000000000u +
           static_cast<std::uint64_t>(t.tv_nsec);
  };
  out[0] = static_cast<std::uint64_t>(st.st_dev);
  out[1] = static_cast<std::uint64_t>(st.st_ino);
  out[2] = static_cast<std::uint64_t>(st.st_size);
  out[3] = ns(st.st_mtim);
  out[4] = ns(st.st_ctim);
}
}  // namespace

void fileStamp(int fd, std::uint64_t out[5]) {
  struct stat st {};
  std::fill(out, out + 5, 0);
  if (::fstat(fd, &st) == 0 && S_ISREG(st.st_mode)) stampOf(st, out);
}

gear_sim::Status checkBagStructure(const std::string& path, BagStructure* structure) {
  using gear_sim::Status;
  BagStructure ignored;
  if (structure == nullptr) structure = &ignored;
  *structure = BagStructure{};
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Status::ioError(path + ": cannot read as a bag (cannot open the file)");
  timespec start{};
  ::clock_gettime(CLOCK_REALTIME, &start);
  struct stat st {};
  const bool known = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode);
  static std::mutex mutex;
  static CheckedFile last;
  if (known) {
    std::lock_guard<std::mutex> lock(mutex);
    if (sameFile(last, path, st)) {
      ::close(fd);
      *structure = last.structure;
      return last.status;
    }
  }
  Status status = walkFile(fd, path, structure);
  if (known && status.ok()) stampOf(st, structure->stamp);  // as it was before the walk
  ::close(fd);
  if (known && settled(st, start)) {
    std::lock_guard<std::mutex> lock(mutex);
    last = {path, st.st_dev, st.st_ino, st.st_size, st.st_mtim, st.st_ctim, status, *structure};
  }
  return status;
}

}  // namespace gear_sim_ros
