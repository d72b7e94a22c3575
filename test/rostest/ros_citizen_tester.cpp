// Integration tests of the package as a ROS citizen (issue 14). One tester, several .test files,
// each selecting its case with --gtest_filter:
// - Namespaces.*     (namespaces.test): two pipelines in namespaces a and b on one master, with
//                    different records; each namespace sees only its own data.
// - RealtimeRecord.* (realtime_record.test): pace realtime waits for its subscribers and delivers
//                    the whole record; record:=true records every chunk and every segment.
// - Reconfigure.*    (reconfigure.test): `rosrun dynamic_reconfigure dynparam set` changes
//                    damping_id_node's segment length and refinement and wavelet_node's band at
//                    the next segment boundary, logged; invalid values are refused.
// - InstallSpace.*   (install_space.test): `catkin_make install` into a temporary workspace,
//                    `roslaunch gear_damping pipeline.launch` from the install space.
// Every wait has a generous wall-clock deadline; nothing asserts a duration.
#include <gtest/gtest.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <rosgraph_msgs/Log.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "../unit/support/status_support.hpp"
#include "gear_damping/DampingArray.h"
#include "gear_damping/DampingSample.h"
#include "gear_damping/GearParams.h"
#include "gear_damping/SignalChunk.h"
#include "gear_damping_id/integral_method.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "gear_sim_ros/topics.hpp"
#include "run_command.hpp"
#include "tester_support.hpp"

namespace gd = gear_damping_id;
namespace fs = std::filesystem;
using gear_test::CraftedStream;
using gear_test::runCommand;
using gear_test::simConfigFromParams;
using gear_test::waitFor;

namespace {

// Live and offline run the same core on the same samples (see pipeline_tester.cpp).
constexpr double kLiveVsOfflineRelTol = 1e-9;
// DampingSample stamps are ros::Time (ns resolution) of start + t_end with start ~1.7e9 s: a
// double holds that to ~0.2 us, so stamp - t_end equals the record start to within 1 us.
constexpr double kStampTol = 1e-6;

std::string packagePath() { return ros::package::getPath("gear_damping"); }

std::string ns(const std::string& n, const char* topic) { return "/" + n + "/" + topic; }

// Everything one pipeline (namespace `n`) publishes that these tests look at.
struct PipelineTap {
  gear_damping::DampingArray cumulative;
  std::vector<gear_damping::DampingSample> series;
  std::vector<gear_damping::SignalChunk> chunks;
  ros::Subscriber damping_sub, series_sub, signal_sub;

  PipelineTap(ros::NodeHandle& nh, const std::string& n) {
    damping_sub = nh.subscribe<gear_damping::DampingArray>(
        ns(n, gear_sim_ros::kDampingTopic), 10,
        [this](const gear_damping::DampingArray::ConstPtr& m) { cumulative = *m; });
    series_sub = nh.subscribe<gear_damping::DampingSample>(
        ns(n, gear_sim_ros::kDampingSeriesTopic), 10000,
        [this](const gear_damping::DampingSample::ConstPtr& m) { series.push_back(*m); });
  }
  // Subscribing to the signal is what releases the simulator (its ~min_subscribers counts this
  // tester): call it once the output subscriptions are connected.
  void listenToSignal(ros::NodeHandle& nh, const std::string& n) {
    signal_sub = nh.subscribe<gear_damping::SignalChunk>(
        ns(n, gear_sim_ros::kSignalTopic), 10000,
        [this](const gear_damping::SignalChunk::ConstPtr& m) { chunks.push_back(*m); });
  }
  bool outputsConnected() const {
    return damping_sub.getNumPublishers() > 0 && series_sub.getNumPublishers() > 0;
  }
  size_t samples() const {
    size_t n = 0;
    for (const auto& c : chunks) n += c.dte.size();
    return n;
  }
};

// identify() over namespace `n`'s record with the node's default options (refine never, as
// the .test files set, so live = offline exactly) and `segment_length`.
gd::IdentificationResult offlineOf(const gear_sim::SimConfig& cfg, double segment_length) {
  gear_sim::SignalTable t;
  std::string e;
  EXPECT_TRUE(gear_test::ok(gear_sim::simulate(cfg, &t), &e)) << e;
  gd::IdentificationOptions o;
  o.refine = gd::IdentificationOptions::Refine::Never;
  o.segment_length = segment_length;
  gd::IdentificationResult r;
  EXPECT_TRUE(gear_test::ok(gd::identify(t, gd::gearConstants(cfg.gearModel()), o, &r), &e)) << e;
  return r;
}

// Each live segment equals the offline one with the same t_start.
void expectLiveEqualsOffline(const gear_damping::DampingArray& live,
                             const gd::IdentificationResult& off, const std::string& what) {
  ASSERT_EQ(live.segments.size(), off.segments.size()) << what;
  for (size_t i = 0; i < off.segments.size(); ++i) {
    EXPECT_NEAR(live.segments[i].t_start, off.segments[i].t_start, 1e-12) << what << " " << i;
    EXPECT_NEAR(live.segments[i].C, off.segments[i].C, kLiveVsOfflineRelTol * off.segments[i].C)
        << what << " segment " << i;
  }
}

// The series of one pipeline: one sample per segment, equal to the cumulative estimate, stamped
// at record start + t_end where the record start is the first chunk's stamp.
void expectSeriesMatches(const PipelineTap& tap, const std::string& what) {
  ASSERT_FALSE(tap.chunks.empty()) << what;
  ASSERT_EQ(tap.series.size(), tap.cumulative.segments.size()) << what;
  const double start = tap.chunks.front().header.stamp.toSec();
  for (size_t i = 0; i < tap.series.size(); ++i) {
    const auto& s = tap.series[i];
    EXPECT_EQ(s.segment.t_start, tap.cumulative.segments[i].t_start) << what << " " << i;
    EXPECT_EQ(s.segment.C, tap.cumulative.segments[i].C) << what << " " << i;
    EXPECT_TRUE(s.segment.identifiable) << what << " " << i << ": " << s.segment.reason;
    EXPECT_NEAR(s.header.stamp.toSec() - s.segment.t_end, start, kStampTol) << what << " " << i;
    EXPECT_GT(s.fit_percent, 90.0) << what << " " << i;  // modeled response published too
  }
}

// ------------------------------------------------------------------------------------------
TEST(Namespaces, TwoPipelinesRunSideBySideWithoutCrosstalk) {
  ros::NodeHandle nh;
  PipelineTap a(nh, "a"), b(nh, "b");
  ASSERT_TRUE(waitFor([&] { return a.outputsConnected() && b.outputsConnected(); }, 60.0));
  a.listenToSignal(nh, "a");
  b.listenToSignal(nh, "b");
  gear_sim::SimConfig cfg_a, cfg_b;
  std::string e;
  ASSERT_TRUE(simConfigFromParams("/a/gear_sim", &cfg_a, &e)) << e;
  ASSERT_TRUE(simConfigFromParams("/b/gear_sim", &cfg_b, &e)) << e;
  const auto off_a = offlineOf(cfg_a, 1e-3), off_b = offlineOf(cfg_b, 1e-3);
  ASSERT_EQ(off_a.segments.size(), 10u);  // table1.yaml: 10 ms
  ASSERT_EQ(off_b.segments.size(), 5u);   // short_record.yaml: 5 ms, other damping
  ASSERT_TRUE(waitFor(
      [&] {
        return a.cumulative.segments.size() == 10 && b.cumulative.segments.size() == 5 &&
               a.series.size() == 10 && b.series.size() == 5;
      },
      90.0))
      << "a: " << a.cumulative.segments.size() << " segments, b: " << b.cumulative.segments.size();
  expectLiveEqualsOffline(a.cumulative, off_a, "a");
  expectLiveEqualsOffline(b.cumulative, off_b, "b");
  // Each namespace's signal carries only its own record.
  EXPECT_EQ(a.samples(), 10000u);
  EXPECT_EQ(b.samples(), 5000u);
  expectSeriesMatches(a, "a");
  expectSeriesMatches(b, "b");
  // Nothing is published outside the namespaces (apart from the global /diagnostics, /rosout).
  ros::master::V_TopicInfo topics;
  ASSERT_TRUE(ros::master::getTopics(topics));
  for (const auto& t : topics) {
    EXPECT_TRUE(t.name.rfind("/a/", 0) == 0 || t.name.rfind("/b/", 0) == 0 ||
                t.name == "/diagnostics" || t.name.rfind("/rosout", 0) == 0)
        << t.name;
  }
  std::printf("[namespaces] a: %zu segments (C[0] %.6g 1/s), b: %zu segments (C[0] %.6g 1/s)\n",
              a.cumulative.segments.size(), a.cumulative.segments[0].C,
              b.cumulative.segments.size(), b.cumulative.segments[0].C);
}

// ------------------------------------------------------------------------------------------
// The newest complete bag written with prefix `prefix` (rosbag record -o PREFIX), "" if none.
std::string findBag(const std::string& prefix) {
  const fs::path p(prefix);
  std::string best;
  std::error_code ec;
  for (const auto& f : fs::directory_iterator(p.parent_path(), ec)) {
    const std::string name = f.path().filename().string();
    if (name.rfind(p.filename().string(), 0) == 0 && f.path().extension() == ".bag" &&
        f.path().string() > best) {
      best = f.path().string();
    }
  }
  return best;
}

TEST(RealtimeRecord, RealtimePaceDeliversAndRecordsTheWholeStream) {
  ros::NodeHandle nh, pnh("~");
  std::string bag_prefix;
  ASSERT_TRUE(pnh.getParam("bag_prefix", bag_prefix));
  PipelineTap rt(nh, "rt");
  ASSERT_TRUE(waitFor([&] { return rt.outputsConnected(); }, 60.0));
  rt.listenToSignal(nh, "rt");
  gear_sim::SimConfig cfg;
  std::string e;
  ASSERT_TRUE(simConfigFromParams("/rt/gear_sim", &cfg, &e)) << e;
  const size_t n_samples =
      static_cast<size_t>(std::llround(cfg.simulation.duration * cfg.simulation.sample_rate));
  const size_t n_segments = 100;  // long_record.yaml: 0.1 s of 1 ms segments
  ASSERT_TRUE(waitFor(
      [&] {
        return rt.samples() == n_samples && rt.cumulative.segments.size() == n_segments &&
               rt.series.size() == n_segments;
      },
      120.0))
      << rt.samples() << " samples, " << rt.cumulative.segments.size() << " segments";
  expectSeriesMatches(rt, "rt");
  // Reported, not asserted (no wall-clock assertions): the publication span of the chunks.
  const double span = (rt.chunks.back().header.stamp - rt.chunks.front().header.stamp).toSec();
  const double record = cfg.simulation.duration;
  RecordProperty("realtime_stream_span_s", std::to_string(span));
  std::printf("[realtime] %zu chunks published over %.4f s of wall time for a %.4f s record\n",
              rt.chunks.size(), span, record);

  // Stop the recorder (it closes the bag on shutdown) and read the bag back.
  const auto kill = runCommand("rosnode kill /rt/record_gear");
  ASSERT_EQ(kill.first, 0) << kill.second;
  std::string bag;
  ASSERT_TRUE(waitFor(
      [&] {
        bag = findBag(bag_prefix);
        return !bag.empty();
      },
      30.0))
      << "no bag " << bag_prefix << "*.bag";
  rosbag::Bag in(bag, rosbag::bagmode::Read);
  size_t bag_samples = 0, bag_chunks = 0, bag_series = 0, bag_params = 0;
  for (const rosbag::MessageInstance& m : rosbag::View(in)) {
    if (m.getTopic() == ns("rt", gear_sim_ros::kSignalTopic)) {
      auto c = m.instantiate<gear_damping::SignalChunk>();
      ASSERT_TRUE(c);
      bag_samples += c->dte.size();
      ++bag_chunks;
    } else if (m.getTopic() == ns("rt", gear_sim_ros::kDampingSeriesTopic)) {
      ++bag_series;
    } else if (m.getTopic() == ns("rt", gear_sim_ros::kParamsTopic)) {
      ++bag_params;
    }
  }
  in.close();
  EXPECT_EQ(bag_samples, n_samples);
  EXPECT_EQ(bag_chunks, rt.chunks.size());
  EXPECT_EQ(bag_series, n_segments);
  EXPECT_EQ(bag_params, 1u);
  std::printf("[record] %s: %zu chunks (%zu samples), %zu series samples\n", bag.c_str(),
              bag_chunks, bag_samples, bag_series);
  std::remove(bag.c_str());
}

// ------------------------------------------------------------------------------------------

bool hasLine(const std::vector<std::string>& log, const std::string& needle) {
  for (const auto& l : log) {
    if (l.find(needle) != std::string::npos) return true;
  }
  return false;
}

std::pair<int, std::string> dynparam(const std::string& args) {
  return runCommand("timeout 30 rosrun dynamic_reconfigure dynparam " + args);
}

TEST(Reconfigure, DynparamSetAppliesAtTheNextSegmentBoundary) {
  ros::NodeHandle nh;
  std::vector<std::string> log;
  // The nodes' log lines, straight from /rosout (what every node publishes its log to).
  auto log_sub =
      nh.subscribe<rosgraph_msgs::Log>("/rosout", 1000, [&](const rosgraph_msgs::Log::ConstPtr& m) {
        if (m->name == "/damping_id" || m->name == "/wavelet") log.push_back(m->msg);
      });
  gear_damping::DampingArray cumulative;
  auto damping_sub = nh.subscribe<gear_damping::DampingArray>(
      gear_sim_ros::kDampingTopic, 10,
      [&](const gear_damping::DampingArray::ConstPtr& m) { cumulative = *m; });
  CraftedStream rig;
  ASSERT_TRUE(rig.ok()) << rig.error();
  ASSERT_TRUE(rig.waitForSubscribers(2)) << "damping_id_node and wavelet_node must subscribe";
  ros::WallDuration(0.5).sleep();  // the latched parameters
  // Chunks 0-4 with the 1 ms segments of damping_id.yaml (flushed at the end-of-stream pause).
  for (int k = 0; k < 5; ++k) rig.publish(rig.chunk(k));
  ASSERT_TRUE(waitFor([&] { return cumulative.segments.size() == 5; }, 60.0))
      << cumulative.segments.size();

  // 2 ms segments from here; an invalid refine value is refused (the old value stays).
  auto r = dynparam("set /damping_id segment_length 0.002");
  ASSERT_EQ(r.first, 0) << r.second;
  r = dynparam("set /damping_id refine sometimes");
  EXPECT_EQ(r.first, 0) << r.second;
  r = dynparam("get /damping_id");
  ASSERT_EQ(r.first, 0) << r.second;
  EXPECT_NE(r.second.find("'segment_length': 0.002"), std::string::npos) << r.second;
  EXPECT_NE(r.second.find("'refine': 'never'"), std::string::npos) << r.second;
  ASSERT_TRUE(waitFor([&] { return hasLine(log, "reconfigured: segment_length 0.002"); }, 30.0))
      << "no 'reconfigured' log line from damping_id";
  ASSERT_TRUE(waitFor([&] { return cumulative.segments.empty(); }, 30.0))
      << "a reconfigure starts a new cumulative estimate";

  // Chunks 5-9 on the new grid (multiples of 2 ms): [5, 6) ms (the grid's partial piece),
  // [6, 8), [8, 10) ms.
  for (int k = 5; k < 10; ++k) rig.publish(rig.chunk(k));
  ASSERT_TRUE(waitFor([&] { return cumulative.segments.size() == 3; }, 60.0))
      << cumulative.segments.size();
  EXPECT_NEAR(cumulative.segments[0].t_start, 0.005, 1e-12);
  EXPECT_NEAR(cumulative.segments[1].t_start, 0.006, 1e-12);
  EXPECT_NEAR(cumulative.segments[1].t_end, 0.008, 1e-12);
  EXPECT_NEAR(cumulative.segments[2].t_end, 0.010, 1e-12);
  // The full 2 ms segments equal the offline identification with segment_length 0.002.
  const auto off = offlineOf(rig.config(), 2e-3);
  ASSERT_EQ(off.segments.size(), 5u);
  for (int i : {1, 2}) {
    EXPECT_NEAR(cumulative.segments[i].C, off.segments[i + 2].C,
                kLiveVsOfflineRelTol * off.segments[i + 2].C)
        << i;
  }

  // wavelet_node: the band, logged, and an inverted band refused.
  r = dynparam("set /wavelet \"{'f_min': 2000.0, 'f_max': 40000.0}\"");
  ASSERT_EQ(r.first, 0) << r.second;
  r = dynparam("set /wavelet f_min 50000.0");  // above f_max: refused
  EXPECT_EQ(r.first, 0) << r.second;
  r = dynparam("get /wavelet");
  ASSERT_EQ(r.first, 0) << r.second;
  EXPECT_NE(r.second.find("'f_max': 40000.0"), std::string::npos) << r.second;
  EXPECT_NE(r.second.find("'f_min': 2000.0"), std::string::npos) << r.second;
  EXPECT_TRUE(
      waitFor([&] { return hasLine(log, "reconfigured: f_min 2000 Hz, f_max 40000 Hz"); }, 30.0))
      << "no 'reconfigured' log line from wavelet";
}

// ------------------------------------------------------------------------------------------
TEST(InstallSpace, PipelineLaunchesFromTheInstallSpace) {
  ros::NodeHandle nh;
  // The build under test: the workspace whose devel space this test runs from (first entry of
  // CMAKE_PREFIX_PATH); its install rules are applied into a temporary directory. Without one
  // (e.g. run from an install space), the script builds a temporary workspace instead.
  const char* prefix_path = std::getenv("CMAKE_PREFIX_PATH");
  const fs::path devel =
      prefix_path ? std::string(prefix_path).substr(0, std::string(prefix_path).find(':')) : "";
  const fs::path build = devel.parent_path() / "build";
  const std::string build_arg =
      devel.filename() == "devel" && fs::exists(build / "CMakeCache.txt") ? build.string() : "";
  char templ[] = "/tmp/gear_damping_install_XXXXXX";
  ASSERT_NE(mkdtemp(templ), nullptr);
  const std::string dir = templ;
  const std::string script = packagePath() + "/test/install/install_space.sh";
  // Install, then launch in namespace `installed` on this test's master.
  const auto r = runCommand("bash " + script + " " + dir + " installed " + build_arg);
  std::printf("%s\n", r.second.c_str());
  ASSERT_EQ(r.first, 0) << r.second;
  gear_damping::DampingArray cumulative;
  auto sub = nh.subscribe<gear_damping::DampingArray>(
      ns("installed", gear_sim_ros::kDampingTopic), 10,
      [&](const gear_damping::DampingArray::ConstPtr& m) { cumulative = *m; });
  const bool got = waitFor([&] { return cumulative.segments.size() == 10; }, 120.0);
  runCommand("bash " + script + " " + dir + " --stop");
  EXPECT_TRUE(got) << cumulative.segments.size() << " segments on /installed/gear/damping\n"
                   << runCommand("cat " + dir + "/launch.log").second;
  for (const auto& s : cumulative.segments) EXPECT_TRUE(s.identifiable) << s.reason;
  runCommand("rm -rf " + dir);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "ros_citizen_tester");
  ros::NodeHandle nh;
  return RUN_ALL_TESTS();
}
