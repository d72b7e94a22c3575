// Bag input of `analyze` and the CSV <-> bag converter: identical results from both inputs,
// and every bad-bag case of issue 7 with its one-line message and documented exit code
// (0 with a warning where the analysis proceeds on the intact part, 1 usage, 2 invalid input).
#include <gear_damping/GearParams.h>
#include <gear_damping/SignalChunk.h>
#include <gtest/gtest.h>
#include <rosbag/bag.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <tuple>

#include "gear_damping_id/integral_method.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/signal_csv.hpp"
#include "gear_sim/simulator.hpp"
#include "gear_sim/window_prefix.hpp"
#include "gear_sim_ros/bag_io.hpp"
#include "gear_sim_ros/conversions.hpp"
#include "status_support.hpp"
#include "tool_runner.hpp"

namespace fs = std::filesystem;
using gear_test::readText;
using gear_test::ToolRun;

namespace {

const std::string kParams = std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml";

class AnalyzeBag : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scratch_ = new gear_test::ScratchDir("analyze_bag_test");
    std::string e;
    ASSERT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(kParams, &config_), &e)) << e;
    config_.simulation.duration = 4e-3;  // four 1 ms segments
    ASSERT_TRUE(gear_test::ok(gear_sim::simulate(config_, &table_), &e)) << e;
  }
  static void TearDownTestSuite() { delete scratch_; }
  static fs::path dir() { return scratch_->path(); }

  // Writes the simulated record as a bag, chunk by chunk, letting `edit` change or drop each
  // chunk (return false to drop it) before it is written.
  static fs::path writeBag(const std::string& name,
                           const std::function<bool(size_t, gear_damping::SignalChunk*)>& edit,
                           bool with_params = true, const std::string& topic = "/gear/signal") {
    const fs::path p = dir() / name;
    rosbag::Bag bag(p.string(), rosbag::bagmode::Write);
    const ros::Time base(1.0);
    if (with_params) bag.write("/gear/params", base, gear_sim_ros::toMsg(config_.gearModel()));
    gear_damping::SignalChunk c;
    const Eigen::Index chunk = 500;
    for (Eigen::Index b = 0, k = 0; b < table_.size(); b += chunk, ++k) {
      gear_sim_ros::toChunk(table_, b, std::min(chunk, table_.size() - b),
                            config_.simulation.sample_rate, static_cast<std::uint64_t>(b), &c);
      if (!edit(static_cast<size_t>(k), &c)) continue;
      bag.write(topic, base + ros::Duration(1e-3 * static_cast<double>(k + 1)), c);
    }
    bag.close();
    return p;
  }
  static fs::path intactBag() {
    return writeBag("intact.bag", [](size_t, gear_damping::SignalChunk*) { return true; });
  }
  static ToolRun analyze(const std::string& args) {
    return gear_test::runTool("analyze", args, dir());
  }

  static gear_test::ScratchDir* scratch_;
  static gear_sim::SimConfig config_;
  static gear_sim::SignalTable table_;
};
gear_test::ScratchDir* AnalyzeBag::scratch_ = nullptr;
gear_sim::SimConfig AnalyzeBag::config_;
gear_sim::SignalTable AnalyzeBag::table_;

TEST_F(AnalyzeBag, BagAndCsvInputsGiveIdenticalResults) {
  const fs::path bag = intactBag(), csv = dir() / "roundtrip.csv", back = dir() / "back.bag";
  // The converter both ways: bag -> CSV -> bag.
  ToolRun r =
      gear_test::runTool("convert", "--input " + bag.string() + " --output " + csv.string(), dir());
  ASSERT_EQ(r.code, 0) << r.err;
  r = gear_test::runTool(
      "convert", "--input " + csv.string() + " --output " + back.string() + " --params " + kParams,
      dir());
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string models = " --model piecewise --model constant --model load_law";
  const fs::path jb = dir() / "bag.json", jc = dir() / "csv.json", jbb = dir() / "back.json";
  // Parameters from the bag's GearParams message for the bags, from the YAML for the CSV.
  r = analyze("--input " + bag.string() + " --output " + jb.string() + models);
  ASSERT_EQ(r.code, 0) << r.err;
  r = analyze("--input " + csv.string() + " --params " + kParams + " --output " + jc.string() +
              models);
  ASSERT_EQ(r.code, 0) << r.err;
  r = analyze("--input " + back.string() + " --output " + jbb.string() + models);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto b = nlohmann::json::parse(readText(jb)), c = nlohmann::json::parse(readText(jc)),
             bb = nlohmann::json::parse(readText(jbb));
  EXPECT_EQ(b.at("identification"), c.at("identification"));
  EXPECT_EQ(b.at("runs"), c.at("runs"));
  EXPECT_EQ(bb.at("runs"), c.at("runs"));
  EXPECT_EQ(b.at("identification").at("segments").size(), 4u);
}

TEST_F(AnalyzeBag, StreamingAgreesWithTheWholeRecordOnNoiseFreeData) {
  const fs::path bag = intactBag(), jw = dir() / "whole.json", js = dir() / "stream.json",
                 out = dir() / "results.bag";
  ToolRun r = analyze("--input " + bag.string() + " --refine never --output " + jw.string());
  ASSERT_EQ(r.code, 0) << r.err;
  r = analyze("--input " + bag.string() + " --refine never --max-in-memory 1500 --output " +
              js.string() + " --bag-out " + out.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const auto w = nlohmann::json::parse(readText(jw)), s = nlohmann::json::parse(readText(js));
  EXPECT_TRUE(s.at("input").at("streaming").get<bool>());
  const auto& ws = w.at("identification").at("segments");
  const auto& ss = s.at("identification").at("segments");
  ASSERT_EQ(ws.size(), ss.size());
  // Piecewise unknowns are segment-local: the streamed estimate is the whole-record one.
  for (size_t i = 0; i < ws.size(); ++i) {
    const double a = ws[i].at("C").get<double>(), b = ss[i].at("C").get<double>();
    EXPECT_NEAR(b, a, 1e-9 * a) << i;
  }
  gear_sim_ros::BagSignalInfo info;
  std::string e;
  EXPECT_FALSE(gear_test::ok(gear_sim_ros::scanSignalBag(out.string(), "", &info),
                             &e));  // results, no signal
  EXPECT_NE(e.find("no topic of type"), std::string::npos) << e;
  EXPECT_TRUE(fs::is_regular_file(out));
}

// A bag whose sample indices start at 1e12 (t = 1e6 s at 1 MHz, as a rig's counter after eleven
// days) is analysed the same read whole and streamed, with the estimates of the same samples from
// index 0 (within the rounding of the stamps: the whole read's step comes from the span of
// stamps resolved to ulp(1e6 s) = 1.2e-10 s, 3e-8 of the 4 ms span; measured 1.2e-8 in C);
// indices whose times a double cannot resolve to 1/1000 of the step (1e15: t = 1e9 s)
// are refused both ways with one message and exit code 2. (Found by a hostile test: the whole
// read refused the first case, "not uniformly sampled", while the streamed read analysed it.)
TEST_F(AnalyzeBag, AFarFirstIndexIsTreatedAlikeWholeAndStreamed) {
  auto shifted = [&](const std::string& name, std::uint64_t offset) {
    return writeBag(name, [offset](size_t, gear_damping::SignalChunk* c) {
      c->first_index += offset;
      return true;
    });
  };
  const fs::path j0 = dir() / "origin.json";
  ToolRun r =
      analyze("--input " + intactBag().string() + " --refine never --output " + j0.string());
  ASSERT_EQ(r.code, 0) << r.err;
  const auto ref = nlohmann::json::parse(readText(j0)).at("identification").at("segments");
  const fs::path far = shifted("far.bag", 1000000000000ULL);
  const double span = static_cast<double>(table_.size() - 1) / config_.simulation.sample_rate;
  const double rel = 20.0 * gear_sim::timeResolution(1e6) / span;  // C moves ~dt's error
  for (const std::string mode : {"", " --max-in-memory 1500"}) {
    const fs::path j = dir() / "far.json";
    r = analyze("--input " + far.string() + " --refine never --output " + j.string() + mode);
    ASSERT_EQ(r.code, 0) << mode << ": " << r.err;
    const auto segs = nlohmann::json::parse(readText(j)).at("identification").at("segments");
    ASSERT_EQ(segs.size(), ref.size()) << mode;
    for (size_t i = 0; i < segs.size(); ++i) {
      const double a = ref[i].at("C").get<double>(), b = segs[i].at("C").get<double>();
      EXPECT_NEAR(b, a, rel * a) << mode << " segment " << i;
    }
  }
  const fs::path coarse = shifted("coarse.bag", 1000000000000000ULL);
  for (const std::string mode : {"", " --max-in-memory 1500"}) {
    const fs::path j = dir() / "coarse.json";
    r = analyze("--input " + coarse.string() + " --refine never --output " + j.string() + mode);
    EXPECT_EQ(r.code, 2) << mode << ": " << r.err;
    EXPECT_NE(r.err.find("re-base the time"), std::string::npos) << mode << ": " << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << mode << ": " << r.err;
    EXPECT_FALSE(fs::exists(j)) << mode;
  }
}

// One implausible stiffness sample (1e14 N/m, above the 1e13 of the plausibility range) reads as
// missing in the record read whole; the streamed read's default window must skip it too (its
// prefix sum had added it: a window 46 % shorter than the whole read's and C up to 7.7 SE apart,
// found by this session's hostile test).
TEST_F(AnalyzeBag, AnImplausibleStiffnessGivesTheSameWindowWholeAndStreamed) {
  const fs::path bag = writeBag("implausible_k.bag", [](size_t k, gear_damping::SignalChunk* c) {
    if (k == 3) c->stiffness[0] = 1e14;
    return true;
  });
  std::vector<nlohmann::json> ids;
  for (const std::string mode : {"", " --max-in-memory 1500"}) {
    const fs::path j = dir() / "implausible_k.json";
    const ToolRun r =
        analyze("--input " + bag.string() + " --refine never --output " + j.string() + mode);
    ASSERT_EQ(r.code, 0) << mode << ": " << r.err;
    EXPECT_NE(r.err.find("plausible range"), std::string::npos) << mode << ": " << r.err;
    ids.push_back(nlohmann::json::parse(readText(j)).at("identification"));
  }
  EXPECT_EQ(ids[1].at("window_length").get<double>(), ids[0].at("window_length").get<double>());
  const auto &w = ids[0].at("segments"), &s = ids[1].at("segments");
  ASSERT_EQ(w.size(), s.size());
  int identified = 0;
  for (size_t i = 0; i < w.size(); ++i) {  // (the segment holding the missing value: neither)
    ASSERT_EQ(s[i].at("identifiable"), w[i].at("identifiable")) << "segment " << i;
    if (!w[i].at("identifiable").get<bool>()) continue;
    ++identified;
    const double a = w[i].at("C").get<double>(), b = s[i].at("C").get<double>();
    EXPECT_NEAR(b, a, 1e-9 * a) << "segment " << i;
  }
  EXPECT_EQ(identified, static_cast<int>(w.size()) - 1);
}

// A bag changed between its scan and its read (here: another file with the stiffness channel
// dropped from every chunk, read with the first bag's scan) is not read out of bounds: the
// chunks whose channels differ from the scan's are skipped, their samples a gap (NaN).
TEST_F(AnalyzeBag, ABagChangedSinceItsScanIsNotReadOutOfBounds) {
  const fs::path bag = intactBag();
  const fs::path changed = writeBag("changed.bag", [](size_t, gear_damping::SignalChunk* c) {
    c->stiffness.clear();
    return true;
  });
  gear_sim_ros::BagSignalInfo info;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::scanSignalBag(bag.string(), "", &info), &e)) << e;
  ASSERT_TRUE(info.stiffness);
  gear_sim::SignalTable whole;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::readSignalBag(info, &whole), &e)) << e;
  EXPECT_TRUE(std::isfinite(whole.dte[0]));  // the scanned bag itself reads
  info.path = changed.string();
  gear_sim::SignalTable t;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::readSignalBag(info, &t), &e)) << e;
  ASSERT_EQ(t.size(), table_.size());
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    ASSERT_TRUE(std::isnan(t.dte[i])) << i;
    ASSERT_TRUE(std::isnan(t.stiffness[i])) << i;
  }
}

// A bag's chunks read from the file directly (one connection, uncompressed chunks) and through
// rosbag (the same chunks lz4-compressed, and the same bag on two connections of the topic):
// the same scan (counts, warnings, flags, stiffness mean), the same record and the same streamed
// ranges, bit for bit; implausible values, a NaN chunk and a gap included.
TEST_F(AnalyzeBag, DirectReadingEqualsReadingThroughRosbag) {
  const auto write = [&](const std::string& name, rosbag::compression::CompressionType type,
                         bool two_connections) {
    const fs::path p = dir() / name;
    rosbag::Bag bag(p.string(), rosbag::bagmode::Write);
    bag.setCompression(type);
    bag.setChunkThreshold(3000);  // a few messages per chunk
    gear_damping::SignalChunk c;
    for (Eigen::Index b = 0, k = 0; b < table_.size(); b += 300, ++k) {
      if (k == 3) continue;  // a gap
      gear_sim_ros::toChunk(table_, b, std::min<Eigen::Index>(300, table_.size() - b),
                            config_.simulation.sample_rate, static_cast<std::uint64_t>(b), &c);
      if (k == 5) c.dte[7] = 2.0;                                         // out of range
      if (k == 6) c.torque[0] = std::numeric_limits<double>::infinity();  // non-finite
      if (k == 8) std::fill(c.dte.begin(), c.dte.end(), std::nan(""));
      if (k == 9) c.mesh_state[3] = 7;
      auto header = boost::make_shared<ros::M_string>();
      using Traits = ros::message_traits::DataType<gear_damping::SignalChunk>;
      (*header)["type"] = Traits::value();
      (*header)["md5sum"] = ros::message_traits::MD5Sum<gear_damping::SignalChunk>::value();
      (*header)["message_definition"] =
          ros::message_traits::Definition<gear_damping::SignalChunk>::value();
      (*header)["callerid"] = two_connections && k % 2 ? "/b" : "/a";
      bag.write("/gear/signal", ros::Time(1.0 + 1e-3 * static_cast<double>(k)), c, header);
    }
    bag.close();
    return p.string();
  };
  const std::string direct = write("direct.bag", rosbag::compression::Uncompressed, false);
  std::string e;
  gear_sim_ros::BagSignalInfo a;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::scanSignalBag(direct, "", &a), &e)) << e;
  EXPECT_FALSE(a.direct.empty());
  EXPECT_EQ(a.gaps, 1);
  EXPECT_GT(a.non_finite_values, 300);
  EXPECT_EQ(a.out_of_range_values, 1);
  EXPECT_EQ(a.bad_mesh_states, 1);
  gear_sim::SignalTable ta;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::readSignalBag(a, &ta), &e)) << e;
  const auto same = [](const Eigen::VectorXd& x, const Eigen::VectorXd& y) {
    return x.size() == y.size() &&
           std::memcmp(x.data(), y.data(), sizeof(double) * static_cast<size_t>(x.size())) == 0;
  };
  for (const auto& [name, type, two] :
       {std::tuple{"lz4.bag", rosbag::compression::LZ4, false},
        std::tuple{"two_connections.bag", rosbag::compression::Uncompressed, true}}) {
    gear_sim_ros::BagSignalInfo b;
    ASSERT_TRUE(gear_test::ok(gear_sim_ros::scanSignalBag(write(name, type, two), "", &b), &e))
        << e;
    EXPECT_TRUE(b.direct.empty()) << name;
    EXPECT_EQ(a.warnings, b.warnings) << name;
    EXPECT_EQ(std::tie(a.chunks, a.samples, a.gaps, a.gap_samples, a.real_samples,
                       a.non_finite_values, a.out_of_range_values, a.bad_mesh_states,
                       a.outlier_chunks, a.first_index, a.sample_rate, a.has_params),
              std::tie(b.chunks, b.samples, b.gaps, b.gap_samples, b.real_samples,
                       b.non_finite_values, b.out_of_range_values, b.bad_mesh_states,
                       b.outlier_chunks, b.first_index, b.sample_rate, b.has_params))
        << name;
    EXPECT_EQ(std::memcmp(&a.stiffness_mean, &b.stiffness_mean, sizeof(double)), 0) << name;
    gear_sim::SignalTable tb;
    ASSERT_TRUE(gear_test::ok(gear_sim_ros::readSignalBag(b, &tb), &e)) << e;
    for (const auto& [x, y] : {std::pair{&ta.time, &tb.time},
                               {&ta.dte, &tb.dte},
                               {&ta.dte_velocity, &tb.dte_velocity},
                               {&ta.stiffness, &tb.stiffness},
                               {&ta.torque, &tb.torque},
                               {&ta.mesh_state, &tb.mesh_state},
                               {&ta.mesh_phase, &tb.mesh_phase},
                               {&ta.damping, &tb.damping}})
      EXPECT_TRUE(same(*x, *y)) << name;
    const std::vector<std::pair<Eigen::Index, Eigen::Index>> ranges = {
        {0, 250}, {280, 950}, {1000, 1001}, {2500, 4000}};
    std::vector<Eigen::VectorXd> ra, rb;
    // A plain pair, not a structured binding: clang 14 (CI's sanitizer build) refuses a lambda
    // capturing a structured binding under C++17.
    for (const auto& io : {std::pair{&a, &ra}, {&b, &rb}}) {
      std::vector<Eigen::VectorXd>* out = io.second;
      auto keep = [out](const gear_sim::SignalTable& t, size_t) {
        out->push_back(t.dte);
        out->push_back(t.torque);
        return gear_sim::Status();
      };
      ASSERT_TRUE(gear_test::ok(gear_sim_ros::streamSignalBag(*io.first, ranges, keep), &e)) << e;
    }
    ASSERT_EQ(ra.size(), rb.size()) << name;
    for (size_t k = 0; k < ra.size(); ++k) EXPECT_TRUE(same(ra[k], rb[k])) << name << " " << k;
  }
  // Cut after its scan: no longer the file walked, so rosbag reads it (and refuses it).
  fs::resize_file(direct, fs::file_size(direct) / 2);
  EXPECT_FALSE(gear_test::ok(gear_sim_ros::readSignalBag(a, &ta), &e));
  EXPECT_NE(e.find("cannot read as a bag"), std::string::npos) << e;
}

// Ranges that overlap (each beginning before the previous one ends, as analyze's streamed
// groups with their left context): every block holds its range's samples as the record read
// whole has them, the overlap in both blocks, across a gap (a dropped chunk: NaN) and a value
// read as NaN, an overlap whose chunk is already behind the stream, a range inside the previous
// one's end and an empty one; ranges whose begins or ends go backwards are refused.
TEST_F(AnalyzeBag, OverlappingRangesHoldTheOverlapInBothBlocks) {
  const fs::path bag = writeBag("overlap.bag", [](size_t k, gear_damping::SignalChunk* c) {
    if (k == 1) c->torque[95] = 1e12;  // outside the plausible range: read as NaN
    return k != 3;                     // samples 1500-1999 missing
  });
  gear_sim_ros::BagSignalInfo info;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::scanSignalBag(bag.string(), "", &info), &e)) << e;
  gear_sim::SignalTable whole;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::readSignalBag(info, &whole), &e)) << e;
  ASSERT_TRUE(std::isnan(whole.torque[595]));
  ASSERT_TRUE(std::isnan(whole.dte[1700]));
  // (samples 2990-2999 of the range from 2990 come from the previous block only: its chunk is
  // behind the stream when that range starts)
  const std::vector<std::pair<Eigen::Index, Eigen::Index>> ranges = {
      {0, 600},     {590, 1200},  {1190, 1200}, {1195, 1700},
      {1690, 2600}, {2600, 3010}, {2990, 4000}, {4000, 4000}};
  const auto same = [](const Eigen::VectorXd& x, const Eigen::VectorXd& y) {  // bit for bit
    return x.size() == y.size() &&
           (x.size() == 0 ||  // (an empty block's columns have no data to compare)
            std::memcmp(x.data(), y.data(), sizeof(double) * static_cast<size_t>(x.size())) == 0);
  };
  std::vector<size_t> seen;
  auto check = [&](const gear_sim::SignalTable& t, size_t r) {
    seen.push_back(r);
    const Eigen::Index a = ranges[r].first, n = ranges[r].second - a;
    for (const auto& [x, y] : {std::pair{&t.time, &whole.time},
                               {&t.dte, &whole.dte},
                               {&t.stiffness, &whole.stiffness},
                               {&t.torque, &whole.torque},
                               {&t.mesh_state, &whole.mesh_state},
                               {&t.mesh_phase, &whole.mesh_phase}}) {
      EXPECT_EQ(x->size(), n) << r;
      if (x->size() == n) {
        EXPECT_TRUE(same(*x, y->segment(a, n).eval())) << r;
      }
    }
    return gear_sim::Status();
  };
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::streamSignalBag(info, ranges, check), &e)) << e;
  EXPECT_EQ(seen, (std::vector<size_t>{0, 1, 2, 3, 4, 5, 6, 7}));
  for (const auto& bad : {std::vector<std::pair<Eigen::Index, Eigen::Index>>{{100, 600}, {50, 700}},
                          {{0, 600}, {100, 500}},
                          {{-1, 600}}}) {
    EXPECT_FALSE(gear_test::ok(
        gear_sim_ros::streamSignalBag(
            info, bad, [](const gear_sim::SignalTable&, size_t) { return gear_sim::Status(); }),
        &e));
    EXPECT_NE(e.find("is not ascending"), std::string::npos) << e;
  }
}

// A bag that cannot be written (a full disk; here a file size limit of 4 to 48 KiB with SIGXFSZ
// ignored, so writes fail with EFBIG) is an I/O error with its message and documented exit code,
// leaving no output behind: analyze's result bag (code 3, whole and streamed) and simulate's
// record (code 2). Before, a failed write threw out of the stream and rosbag's destructor retried
// the failed close and threw out of itself (std::terminate, exit 134, at 8 KiB and above).
TEST_F(AnalyzeBag, ABagThatCannotBeWrittenIsAnIoErrorNotACrash) {
  const fs::path bag = intactBag(), out = dir() / "full_out.bag", json = dir() / "full.json";
  const auto limited = [&](int kib, const std::string& tool, const std::string& args) {
    SCOPED_TRACE(tool + " at " + std::to_string(kib) + " KiB" + args);
    const ToolRun r =
        gear_test::runShell("bash -c \"trap '' XFSZ; ulimit -f " + std::to_string(kib) + "; exec " +
                                std::string(GEAR_TOOL_DIR) + "/" + tool + args + "\"",
                            dir(), "full_out");
    EXPECT_EQ(r.code, tool == "analyze" ? 3 : 2) << r.err;
    EXPECT_NE(r.err.find(": cannot write"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out));
    EXPECT_FALSE(fs::exists(out.string() + ".partial"));
    EXPECT_FALSE(fs::exists(json));
  };
  for (const int kib : {4, 8, 16, 48}) {
    for (const std::string streamed : {"", " --max-in-memory 1000"})
      limited(kib, "analyze",
              " --input " + bag.string() + " --output " + json.string() + " --bag-out " +
                  out.string() + streamed);
    limited(kib, "simulate",
            " --config " + std::string(kParams) + " --duration 0.1 -q --output " + out.string());
  }
}

// A streamed record whose last group of 64 segments reads no new sample (65 segments of 2
// samples: the 65th lies in the 64th's right context): its block holds the group's samples as
// the record read whole does, so every segment reads as it does whole (before, the empty read
// gave a view without channels: "missing channel dte", a shifted t_start, and with --wavelet a
// null read and a segmentation fault; found by the session's hostile tester).
TEST_F(AnalyzeBag, AnEmptyLastReadGivesTheSegmentsOfTheWholeRecord) {
  const fs::path bag = dir() / "s130.bag", jw = dir() / "s130_whole.json",
                 js = dir() / "s130_streamed.json";
  ToolRun r = gear_test::runTool(
      "simulate", "--config " + kParams + " --duration 0.00013 -q --output " + bag.string(), dir());
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string args = "--input " + bag.string() + " --segment 0.000002 --refine never";
  r = analyze(args + " --output " + jw.string());
  const int code = r.code;
  EXPECT_TRUE(code == 0 || code == 4) << r.err;
  r = analyze(args + " --max-in-memory 1 --output " + js.string());
  EXPECT_EQ(r.code, code) << r.err;
  const auto w = nlohmann::json::parse(readText(jw)), s = nlohmann::json::parse(readText(js));
  const auto& ws = w.at("identification").at("segments");
  ASSERT_EQ(ws.size(), 65u);
  EXPECT_EQ(s.at("identification").at("segments"), ws);
  r = analyze(args + " --max-in-memory 1 --wavelet --output " + js.string());
  EXPECT_TRUE(r.code == 0 || r.code == 4) << r.code << ": " << r.err;
}

// --threads N identifies segments in parallel (the segment driver): the same JSON as one thread,
// for the record read whole and streamed, for segment-local and shared unknowns; the default
// (one thread per core) and --threads 0 too.
TEST_F(AnalyzeBag, ThreadsGiveTheSameResultsAsOneThreadWholeAndStreamed) {
  const fs::path bag = intactBag();
  for (const std::string mode : {"", " --max-in-memory 1500"}) {
    const fs::path j1 = dir() / "t1.json";
    const std::string common =
        " --model piecewise --model constant --formulation known "
        "--formulation greybox" +
        mode + " --output ";
    ToolRun r = analyze("--input " + bag.string() + common + j1.string() + " --threads 1");
    ASSERT_EQ(r.code, 0) << r.err;
    const auto a = nlohmann::json::parse(readText(j1));
    for (const std::string threads : {" --threads 3", " --threads 0", ""}) {
      const fs::path jn = dir() / "tn.json";
      r = analyze("--input " + bag.string() + common + jn.string() + threads);
      ASSERT_EQ(r.code, 0) << threads << ": " << r.err;
      const auto b = nlohmann::json::parse(readText(jn));
      EXPECT_EQ(a.at("identification"), b.at("identification")) << mode << threads;
      EXPECT_EQ(a.at("runs"), b.at("runs")) << mode << threads;
    }
  }
}

TEST_F(AnalyzeBag, AGapOrANanChunkMakesOnlyItsSegmentNotIdentifiable) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const fs::path gap =
      writeBag("gap.bag", [](size_t k, gear_damping::SignalChunk*) { return k != 3; });
  const fs::path bad = writeBag("nan.bag", [&](size_t k, gear_damping::SignalChunk* c) {
    if (k == 5) c->dte[17] = nan;
    return true;
  });
  for (const auto& [bag, warning] : {std::make_pair(gap, std::string("gap of 500 samples")),
                                     std::make_pair(bad, std::string())}) {
    const fs::path j = dir() / "partial.json";
    const ToolRun r = analyze("--input " + bag.string() + " --output " + j.string());
    ASSERT_EQ(r.code, 0) << bag << ": " << r.err;
    if (!warning.empty()) {
      EXPECT_NE(r.err.find(warning), std::string::npos) << r.err;
    }
    const auto segs = nlohmann::json::parse(readText(j)).at("identification").at("segments");
    ASSERT_EQ(segs.size(), 4u) << bag;
    // Chunk 3 (samples 1500-1999) lies in segment 1, chunk 5 in segment 2.
    const size_t hit = bag == gap ? 1 : 2;
    for (size_t i = 0; i < 4; ++i) {
      EXPECT_EQ(segs[i].at("identifiable").get<bool>(), i != hit) << bag << " segment " << i;
      EXPECT_EQ(segs[i].at("C").is_number(), i != hit) << bag << " segment " << i;
    }
  }
}

// The modeled response around a gap, a NaN DTE sample and an implausible torque sample (read as
// NaN), whole and streamed. Read whole, the re-simulation (driven by the stiffness and torque,
// not the DTE) turns non-finite at the gap's or the torque sample's first sample, less the stage
// interpolation's reach of up to two samples, and restarts at the next segment; a NaN DTE sample
// leaves it finite (the fit skips the sample). Streamed, each segment is re-simulated on its own
// and a segment without a response (not identifiable) counts whole. The fit stays a number.
TEST_F(AnalyzeBag, ABadSampleCostsTheResponseUpToTheNextSegmentOnly) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  struct Case {
    fs::path bag;
    Eigen::Index first_bad;  // the first bad sample (1 ms segments: 1000 samples)
    bool drives;             // in a channel that drives the re-simulation
  };
  const std::vector<Case> cases = {
      {writeBag("r_gap.bag", [](size_t k, gear_damping::SignalChunk*) { return k != 3; }), 1500,
       true},
      {writeBag("r_dte.bag",
                [&](size_t k, gear_damping::SignalChunk* c) {
                  if (k == 5) c->dte[17] = nan;
                  return true;
                }),
       2517, false},
      {writeBag("r_torque.bag",
                [&](size_t k, gear_damping::SignalChunk* c) {
                  if (k == 5) c->torque[17] = 1e12;
                  return true;
                }),
       2517, true}};
  for (const Case& c : cases) {
    for (const std::string mode : {"", " --max-in-memory 1500"}) {
      const fs::path j = dir() / "resp.json";
      const ToolRun r = analyze("--input " + c.bag.string() + mode + " --output " + j.string());
      ASSERT_EQ(r.code, 0) << c.bag << mode << ": " << r.err;
      const auto resp = nlohmann::json::parse(readText(j)).at("response");
      EXPECT_TRUE(resp.at("fit_percent").is_number()) << c.bag << mode << ": " << resp.dump();
      const Eigen::Index to_next = (c.first_bad / 1000 + 1) * 1000 - c.first_bad;
      const Eigen::Index lo = !mode.empty() ? 1000
                              : c.drives    ? to_next
                                            : 0,
                         hi = !mode.empty() ? 1000
                              : c.drives    ? to_next + 2
                                            : 0;
      const Eigen::Index unmodeled =
          resp.contains("unmodeled_samples") ? resp.at("unmodeled_samples").get<Eigen::Index>() : 0;
      EXPECT_GE(unmodeled, lo) << c.bag << mode;
      EXPECT_LE(unmodeled, hi) << c.bag << mode;
    }
  }
}

TEST_F(AnalyzeBag, RejectsBadBagsWithAOneLineMessageAndExitCode) {
  const fs::path intact = intactBag();
  const fs::path empty = dir() / "empty.bag", corrupt = dir() / "corrupt.bag",
                 truncated = dir() / "truncated.bag";
  std::ofstream(empty.string()).close();
  {
    std::ofstream f(corrupt.string(), std::ios::binary);
    for (int i = 0; i < 4096; ++i) f.put(static_cast<char>((i * 7919) & 0xff));
  }
  {
    const std::string bytes = readText(intact);
    std::ofstream f(truncated.string(), std::ios::binary);
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size() / 2));
  }
  const fs::path dup = writeBag("dup.bag", [](size_t k, gear_damping::SignalChunk* c) {
    if (k == 4) c->first_index -= 500;  // repeats chunk 3's indices
    return true;
  });
  const fs::path rate = writeBag("rate.bag", [](size_t k, gear_damping::SignalChunk* c) {
    if (k == 2) c->sample_rate *= 2;
    return true;
  });
  const fs::path slow = writeBag("slow.bag", [](size_t, gear_damping::SignalChunk* c) {
    c->sample_rate = 40e3;  // 4 samples per natural period (about 10 kHz)
    return true;
  });
  const fs::path noparams = writeBag(
      "noparams.bag", [](size_t, gear_damping::SignalChunk*) { return true; }, false);
  const fs::path shortrec =
      writeBag("short.bag", [](size_t k, gear_damping::SignalChunk*) { return k == 0; });
  {  // two signal topics
    rosbag::Bag b((dir() / "two.bag").string(), rosbag::bagmode::Write);
    gear_damping::SignalChunk c;
    gear_sim_ros::toChunk(table_, 0, 100, 1e6, 0, &c);
    b.write("/a/signal", ros::Time(1.0), c);
    b.write("/b/signal", ros::Time(1.0), c);
  }
  struct Case {
    std::string name, args;
    int code;
    std::string message;
  };
  const std::string i = "--input ";
  const std::vector<Case> cases = {
      {"empty file", i + empty.string(), 2, "cannot read as a bag"},
      {"corrupt file", i + corrupt.string(), 2, "cannot read as a bag"},
      {"truncated file", i + truncated.string(), 2, "cannot read as a bag"},
      {"missing topic", i + intact.string() + " --topic /nope", 2, "no topic '/nope'"},
      {"wrong message type", i + intact.string() + " --topic /gear/params", 2,
       "has type 'gear_damping/GearParams'"},
      {"two candidate topics", i + (dir() / "two.bag").string(), 2, "'/a/signal', '/b/signal'"},
      {"duplicated indices", i + dup.string(), 2, "duplicated or out-of-order"},
      {"sample rate change", i + rate.string(), 2, "sample_rate changed"},
      {"sample rate too low", i + slow.string(), 2, "too low for the natural frequency"},
      {"no gear parameters", i + noparams.string(), 1, "--params"},
      {"shorter than a segment", i + shortrec.string(), 2, "shorter than one damping segment"},
  };
  // In memory and streamed (read in one pass: the same message, nothing written).
  for (const std::string mode : {"", " --max-in-memory 1500"}) {
    for (const auto& c : cases) {
      const fs::path out = dir() / "never.json";
      const ToolRun r = analyze(c.args + mode + " --output " + out.string());
      EXPECT_EQ(r.code, c.code) << c.name << mode << ": " << r.err;
      EXPECT_NE(r.err.find(c.message), std::string::npos) << c.name << mode << ": " << r.err;
      EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << c.name << mode << ": " << r.err;
      EXPECT_FALSE(fs::exists(out)) << c.name << mode;
    }
  }
}

// The one-pass reading (previewSignalBag, then scanStreamSignalBag) gives what the scan and then
// the stream give, bit for bit: the scan's counts, warnings and stiffness mean (the preview's is
// the record's prefix's, here all of it), and the streamed ranges; a scan error late in the
// record fails the pass.
TEST_F(AnalyzeBag, OnePassEqualsTheScanThenTheStream) {
  const fs::path bag = writeBag("one_pass.bag", [](size_t k, gear_damping::SignalChunk* c) {
    if (k == 3) return false;  // a gap
    if (k == 0)
      for (double& x : c->stiffness) x *= 2.0;  // the first chunk's mean is not the record's
    if (k == 5) c->dte[7] = 2.0;                // out of range
    if (k == 6) c->torque[0] = std::numeric_limits<double>::infinity();
    return true;
  });
  std::string e;
  gear_sim_ros::BagSignalInfo a, p;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::scanSignalBag(bag.string(), "", &a), &e)) << e;
  ASSERT_TRUE(gear_sim_ros::previewSignalBag(bag.string(), "", &p));
  EXPECT_EQ(std::tie(p.samples, p.first_index, p.sample_rate, p.stiffness, p.torque, p.has_params),
            std::tie(a.samples, a.first_index, a.sample_rate, a.stiffness, a.torque, a.has_params));
  EXPECT_EQ(std::memcmp(&p.stiffness_mean, &a.stiffness_mean, sizeof(double)), 0);
  const std::vector<std::pair<Eigen::Index, Eigen::Index>> ranges = {
      {0, 250}, {280, 950}, {1000, 1001}, {2500, 4000}};
  std::vector<Eigen::VectorXd> ra, rp;
  const auto keep = [](std::vector<Eigen::VectorXd>* out) {
    return [out](const gear_sim::SignalTable& t, size_t) {
      for (const Eigen::VectorXd* v : {&t.time, &t.dte, &t.stiffness, &t.torque, &t.mesh_state})
        out->push_back(*v);
      return gear_sim::Status();
    };
  };
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::streamSignalBag(a, ranges, keep(&ra)), &e)) << e;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::scanStreamSignalBag(&p, ranges, keep(&rp)), &e)) << e;
  ASSERT_EQ(ra.size(), rp.size());
  for (size_t k = 0; k < ra.size(); ++k) {
    ASSERT_EQ(ra[k].size(), rp[k].size()) << k;
    EXPECT_EQ(std::memcmp(ra[k].data(), rp[k].data(), sizeof(double) * ra[k].size()), 0) << k;
  }
  EXPECT_EQ(p.warnings, a.warnings);
  EXPECT_EQ(std::tie(p.chunks, p.samples, p.gaps, p.gap_samples, p.real_samples,
                     p.non_finite_values, p.out_of_range_values, p.outlier_chunks),
            std::tie(a.chunks, a.samples, a.gaps, a.gap_samples, a.real_samples,
                     a.non_finite_values, a.out_of_range_values, a.outlier_chunks));
  EXPECT_EQ(std::memcmp(&p.stiffness_mean, &a.stiffness_mean, sizeof(double)), 0);
  EXPECT_EQ(a.gaps, 1);
  EXPECT_EQ(a.out_of_range_values, 1);
  // The next to last chunk repeats the indices before it: the preview, which reads the default
  // window's prefix (here the whole record), refuses the bag as the scan does (the pass failing
  // after the preview: TheDefaultWindowIsThePrefixRuleOnEveryPath).
  const fs::path dup = writeBag("one_pass_dup.bag", [](size_t k, gear_damping::SignalChunk* c) {
    if (k == 6) c->first_index -= 500;
    return true;
  });
  EXPECT_FALSE(gear_sim_ros::previewSignalBag(dup.string(), "", &p));
  EXPECT_FALSE(gear_test::ok(gear_sim_ros::scanSignalBag(dup.string(), "", &a), &e));
}

// Blocks without the columns a sink leaves out (StreamColumns): those are empty, every other
// column has the bits of the full blocks, on both streaming paths (the one-pass scan copies a
// plausible chunk as it is, an implausible one value by value).
TEST_F(AnalyzeBag, ColumnsLeftOutOfTheBlocksAreEmptyAndTheOthersUnchanged) {
  const fs::path bag = writeBag("columns.bag", [](size_t k, gear_damping::SignalChunk* c) {
    if (k == 2) c->dte[3] = 2.0;  // out of range: read as NaN
    if (k == 4) c->dte_velocity[1] = std::numeric_limits<double>::quiet_NaN();
    return k != 6;  // a gap
  });
  std::string e;
  gear_sim_ros::BagSignalInfo info;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::scanSignalBag(bag.string(), "", &info), &e)) << e;
  ASSERT_TRUE(info.dte_velocity && info.damping);
  const std::vector<std::pair<Eigen::Index, Eigen::Index>> ranges = {
      {0, 700}, {698, 1800}, {2900, 3600}, {3500, 4000}};
  using Blocks = std::vector<gear_sim::SignalTable>;
  const auto keep = [](Blocks* out) {
    return [out](const gear_sim::SignalTable& t, size_t) {
      out->push_back(t);
      return gear_sim::Status();
    };
  };
  gear_sim_ros::StreamColumns none;
  none.time = none.dte_velocity = none.damping = false;
  Blocks full, part, pass;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::streamSignalBag(info, ranges, keep(&full)), &e)) << e;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::streamSignalBag(info, ranges, keep(&part), none), &e));
  gear_sim_ros::BagSignalInfo preview;
  ASSERT_TRUE(gear_sim_ros::previewSignalBag(bag.string(), "", &preview));
  ASSERT_TRUE(
      gear_test::ok(gear_sim_ros::scanStreamSignalBag(&preview, ranges, keep(&pass), none), &e))
      << e;
  ASSERT_EQ(full.size(), ranges.size());
  const auto same = [](const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
    return a.size() == b.size() &&
           std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<size_t>(a.size())) == 0;
  };
  for (const Blocks* b : {&part, &pass}) {
    ASSERT_EQ(b->size(), full.size());
    for (size_t k = 0; k < full.size(); ++k) {
      const gear_sim::SignalTable &f = full[k], &t = (*b)[k];
      EXPECT_EQ(f.time.size(), ranges[k].second - ranges[k].first) << k;
      EXPECT_EQ(t.time.size() + t.dte_velocity.size() + t.damping.size(), 0) << k;
      EXPECT_TRUE(same(f.dte, t.dte) && same(f.stiffness, t.stiffness) &&
                  same(f.torque, t.torque) && same(f.mesh_state, t.mesh_state) &&
                  same(f.mesh_phase, t.mesh_phase))
          << k;
    }
  }
  EXPECT_TRUE(full[0].dte.hasNaN() || full[1].dte.hasNaN());  // the out-of-range value
}

// `analyze` on a streamed bag reads it once (with --bag-out: scan, then stream): the same
// outputs, also when the first chunk's stiffness differs from the rest and when the scan fails
// late (the record is then analysed again: the scan's message and exit code).
TEST_F(AnalyzeBag, OnePassGivesTheOutputsOfTheScanThenTheStream) {
  const fs::path intact = intactBag();
  const fs::path stiff = writeBag("stiff_first.bag", [](size_t k, gear_damping::SignalChunk* c) {
    if (k == 0)
      for (double& x : c->stiffness) x *= 4.0;
    return true;
  });
  const fs::path dup = writeBag("late_dup.bag", [](size_t k, gear_damping::SignalChunk* c) {
    if (k == 6) c->first_index -= 500;
    return true;
  });
  for (const fs::path& bag : {intact, stiff, dup}) {
    std::vector<ToolRun> runs;
    std::vector<std::string> docs;
    for (const std::string& extra :
         {std::string(), std::string(" --bag-out ") + (dir() / "r.bag").string()}) {
      const fs::path j = dir() / "one_pass.json";
      fs::remove(j);
      runs.push_back(analyze("--input " + bag.string() + " --refine never --max-in-memory 1500" +
                             " --output " + j.string() + extra));
      nlohmann::json doc = fs::exists(j) ? nlohmann::json::parse(readText(j)) : nlohmann::json();
      if (doc.is_object()) doc.erase("metadata");
      docs.push_back(doc.dump());
    }
    EXPECT_EQ(runs[0].code, runs[1].code) << bag;
    EXPECT_EQ(runs[0].out, runs[1].out) << bag;
    EXPECT_EQ(runs[0].err, runs[1].err) << bag;
    EXPECT_EQ(docs[0], docs[1]) << bag;
    EXPECT_EQ(runs[0].code, bag == dup ? 2 : 0) << bag << ": " << runs[0].err;
  }
}

// The default window is the prefix rule (the mean of the finite stiffness samples among the
// record's first kWindowPrefixSamples) on a record longer than the prefix, read whole (the
// defaultWindowLength of its table), scanned (scanSignalBag), previewed (previewSignalBag: the
// one-pass read), and `analyze` gives the same window and estimates read whole, streamed, and
// streamed in one pass. The stiffness after the prefix is doubled (the whole record's mean is
// not the prefix's), NaN in places (skipped) and not a whole number (the sum's order shows in
// its bits); chunks of 1000 samples with a gap in the prefix. A chunk after the prefix that
// repeats indices fails the one pass after its preview: `analyze` then reports the scan's error.
TEST_F(AnalyzeBag, TheDefaultWindowIsThePrefixRuleOnEveryPath) {
  namespace gd = gear_damping_id;
  constexpr Eigen::Index kPrefix = gear_sim::kWindowPrefixSamples;
  gear_sim::SimConfig cfg = config_;
  cfg.simulation.duration = 0.16;  // 160000 samples at 1 MHz
  gear_sim::SignalTable t;
  std::string e;
  ASSERT_TRUE(gear_test::ok(gear_sim::simulate(cfg, &t), &e)) << e;
  ASSERT_GT(t.size(), kPrefix + 20000);
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    t.stiffness[i] *= 1.0 + 1e-7 * std::sin(0.37 * static_cast<double>(i));
    if (i >= kPrefix) t.stiffness[i] *= 2.0;
    if (i % 9973 == 5) t.stiffness[i] = std::numeric_limits<double>::quiet_NaN();
  }
  const Eigen::Index chunk = 1000, gap = 37;  // chunk 37 (samples 37000-37999) missing
  for (Eigen::Index b = gap * chunk; b < (gap + 1) * chunk; ++b)
    t.stiffness[b] = std::numeric_limits<double>::quiet_NaN();  // as a gap reads
  const auto write = [&](const std::string& name, Eigen::Index repeat) {
    const fs::path p = dir() / name;
    rosbag::Bag w(p.string(), rosbag::bagmode::Write);
    w.write("/gear/params", ros::Time(1.0), gear_sim_ros::toMsg(cfg.gearModel()));
    gear_damping::SignalChunk c;
    for (Eigen::Index b = 0, k = 0; b < t.size(); b += chunk, ++k) {
      if (k == gap) continue;
      gear_sim_ros::toChunk(t, b, std::min(chunk, t.size() - b), cfg.simulation.sample_rate,
                            static_cast<std::uint64_t>(b), &c);
      if (k == repeat) c.first_index -= 500;
      w.write("/gear/signal", ros::Time(1.0) + ros::Duration(1e-4 * static_cast<double>(k + 1)), c);
    }
    return p;
  };
  const fs::path bag = write("long_prefix.bag", -1), late = write("long_late_dup.bag", 150);
  // The rule, written out: the finite samples of the prefix summed in order.
  double sum = 0.0, all = 0.0;
  long long count = 0, count_all = 0;
  for (Eigen::Index i = 0; i < t.size(); ++i) {
    if (!std::isfinite(t.stiffness[i])) continue;
    all += t.stiffness[i];
    ++count_all;
    if (i >= kPrefix) continue;
    sum += t.stiffness[i];
    ++count;
  }
  const double mean = sum / static_cast<double>(count);
  const gd::GearConstants gear = gd::gearConstants(cfg.gearModel());
  const double rule = 2.0 * 2.0 * M_PI / std::sqrt(mean / gear.equivalent_mass);
  const double whole_mean = all / static_cast<double>(count_all);
  EXPECT_GT(whole_mean, 1.1 * mean);  // the whole record's mean would give another window
  EXPECT_EQ(gd::defaultWindowLength(gd::SignalView::of(t), gear), rule);
  gear_sim::SignalTable read;
  gear_sim_ros::BagSignalInfo scan, preview;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::scanSignalBag(bag.string(), "", &scan), &e)) << e;
  ASSERT_TRUE(gear_test::ok(gear_sim_ros::readSignalBag(scan, &read), &e)) << e;
  ASSERT_TRUE(gear_sim_ros::previewSignalBag(bag.string(), "", &preview));
  EXPECT_EQ(scan.gaps, 1);
  EXPECT_EQ(scan.stiffness_mean, mean);
  EXPECT_EQ(preview.stiffness_mean, mean);
  EXPECT_EQ(gd::defaultWindowLength(gd::SignalView::of(read), gear), rule);
  // A record no longer than the prefix: the mean of all its finite samples, as before.
  gear_sim::SignalTable head = t;
  for (Eigen::VectorXd* v : {&head.time, &head.dte, &head.stiffness})
    v->conservativeResize(kPrefix);
  for (Eigen::VectorXd* v : {&head.dte_velocity, &head.torque, &head.mesh_state, &head.mesh_phase,
                             &head.damping, &head.theta1, &head.theta2})
    v->resize(0);
  EXPECT_DOUBLE_EQ(gd::defaultWindowLength(gd::SignalView::of(head), gear), rule);
  // `analyze`: whole, streamed in one pass, streamed scan then stream (--bag-out).
  std::vector<nlohmann::json> docs;
  for (const std::string& mode :
       {std::string(), std::string(" --max-in-memory 20000"),
        " --max-in-memory 20000 --bag-out " + (dir() / "prefix_out.bag").string()}) {
    const fs::path j = dir() / "prefix.json";
    fs::remove(j);
    const ToolRun r = analyze("--input " + bag.string() + " --refine never --model piecewise" +
                              " --model constant --output " + j.string() + mode);
    ASSERT_EQ(r.code, 0) << mode << ": " << r.err;
    docs.push_back(nlohmann::json::parse(readText(j)));
  }
  for (size_t m = 0; m < docs.size(); ++m) {
    const auto& runs = docs[m].at("runs");
    ASSERT_EQ(runs.size(), 2u);
    for (size_t k = 0; k < runs.size(); ++k)
      EXPECT_EQ(runs[k].at("window_length").get<double>(), rule) << m << k;
    const auto& segs = docs[m].at("identification").at("segments");
    const auto& ref = docs[0].at("identification").at("segments");
    ASSERT_EQ(segs.size(), ref.size());
    for (size_t i = 0; i < segs.size(); ++i) {
      EXPECT_EQ(segs[i].at("C"), ref[i].at("C")) << m << " " << i;
      EXPECT_EQ(segs[i].at("C_std"), ref[i].at("C_std")) << m << " " << i;
    }
  }
  docs[1].erase("metadata");
  docs[2].erase("metadata");
  EXPECT_EQ(docs[1], docs[2]);
  ASSERT_TRUE(gear_sim_ros::previewSignalBag(late.string(), "", &preview));
  const auto none = [](const gear_sim::SignalTable&, size_t) { return gear_sim::Status(); };
  EXPECT_FALSE(gear_test::ok(gear_sim_ros::scanStreamSignalBag(&preview, {{0, 1000}}, none), &e));
  std::vector<ToolRun> runs;
  for (const std::string& mode :
       {std::string(), " --bag-out " + (dir() / "prefix_out.bag").string()})
    runs.push_back(analyze("--input " + late.string() + " --refine never --max-in-memory 20000" +
                           " --output " + (dir() / "late.json").string() + mode));
  EXPECT_EQ(runs[0].code, 2) << runs[0].err;
  EXPECT_NE(runs[0].err.find("first_index"), std::string::npos) << runs[0].err;
  EXPECT_EQ(runs[0].err, runs[1].err);
  EXPECT_EQ(runs[0].out, runs[1].out);
  EXPECT_FALSE(fs::exists(dir() / "late.json"));
}

}  // namespace
