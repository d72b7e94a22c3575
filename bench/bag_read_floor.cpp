// The I/O floor of `analyze` on a bag (issue 18): a bare rosbag::View pass over a SignalChunk
// topic, each message deserialised (instantiate), nothing else. With --raw the messages are only
// copied out as bytes (no deserialisation). Prints one JSON line: seconds, messages, samples,
// bytes. Used by bench/compare_peers as the "rosbag::View read" floor; not a test. Exit codes:
// 0 done, 1 the bag cannot be read, 2 usage (--help: 0), 3 internal error.
#include <gear_damping/SignalChunk.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "gear_sim/tool_main.hpp"

namespace {

constexpr const char* kUsage = "usage: bag_read_floor BAG [--raw] [--topic T]\n";

// Exit codes: 0 done, 1 the bag cannot be read, 2 usage, 3 internal error (runToolMain).
int run(int argc, char** argv) {
  if (argc < 2 || std::strcmp(argv[1], "--help") == 0 || std::strcmp(argv[1], "-h") == 0) {
    std::fputs(kUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  bool raw = false;
  std::string topic;
  for (int i = 2; i < argc; ++i) {
    if (std::strcmp(argv[i], "--raw") == 0) {
      raw = true;
    } else if (std::strcmp(argv[i], "--topic") == 0 && i + 1 < argc) {
      topic = argv[++i];
    } else {
      std::fprintf(stderr, "bag_read_floor: unknown option %s\n%s",
                   gear_sim::quoteForMessage(argv[i]).c_str(), kUsage);
      return 2;
    }
  }
  try {
    const auto t0 = std::chrono::steady_clock::now();
    rosbag::Bag bag(argv[1], rosbag::bagmode::Read);
    if (topic.empty()) {
      rosbag::View all(bag);
      for (const rosbag::ConnectionInfo* c : all.getConnections())
        if (c->datatype == "gear_damping/SignalChunk") topic = c->topic;
    }
    rosbag::View view(bag, rosbag::TopicQuery(topic));
    long long messages = 0, samples = 0, bytes = 0;
    std::vector<std::uint8_t> buffer;
    for (const rosbag::MessageInstance& m : view) {
      ++messages;
      bytes += m.size();
      if (raw) {
        buffer.resize(m.size());
        ros::serialization::OStream s(buffer.data(), static_cast<std::uint32_t>(buffer.size()));
        m.write(s);
      } else {
        const auto c = m.instantiate<gear_damping::SignalChunk>();
        if (c) samples += static_cast<long long>(c->dte.size());
      }
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("{\"seconds\": %.6f, \"messages\": %lld, \"samples\": %lld, \"bytes\": %lld}\n", s,
                messages, samples, bytes);
  } catch (const rosbag::BagException& e) {
    std::fprintf(stderr, "bag_read_floor: cannot read %s: %s\n",
                 gear_sim::quoteForMessage(argv[1]).c_str(),
                 gear_sim::quoteForMessage(e.what()).c_str());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return gear_sim::runToolMain("bag_read_floor", 3, [&] { return run(argc, argv); });
}
