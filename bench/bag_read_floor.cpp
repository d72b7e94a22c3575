// The I/O floor of `analyze` on a bag (issue 18): a bare rosbag::View pass over a SignalChunk
// topic, each message deserialised (instantiate), nothing else. With --raw the messages are only
// copied out as bytes (no deserialisation). Prints one JSON line: seconds, messages, samples,
// bytes. Used by bench/compare_peers as the "rosbag::View read" floor; not a test.
#include <gear_damping/SignalChunk.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s BAG [--raw] [--topic T]\n", argv[0]);
    return 2;
  }
  bool raw = false;
  std::string topic;
  for (int i = 2; i < argc; ++i) {
    if (std::strcmp(argv[i], "--raw") == 0) raw = true;
    if (std::strcmp(argv[i], "--topic") == 0 && i + 1 < argc) topic = argv[++i];
  }
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
  return 0;
}
