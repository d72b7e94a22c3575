// Every file in config/ loads through the loader or parameter reader that consumes it, with no
// parameter server: simulator configurations through loadSimConfigFile (and the encoder section
// through loadEncoderOptions), the node parameter files through the nodes' own readers
// (damping_id_params.hpp, wavelet_params.hpp), the diagnostic_aggregator analyzers by structure.
// A new file in config/ that no case claims fails the test.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "damping_id_params.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/encoder_yaml.hpp"
#include "status_support.hpp"
#include "wavelet_params.hpp"
#include "yaml_params.hpp"

namespace {

namespace nodes = gear_damping_nodes;

std::string configPath(const std::string& name) {
  return std::string(GEAR_SOURCE_DIR) + "/config/" + name;
}

nodes::ParamReader readerOf(const std::string& file) {
  return nodes::ParamReader(std::make_shared<gear_test::YamlParams>(YAML::LoadFile(file)));
}

// What each shipped file is; a file in config/ missing here fails ShippedFilesAreAllKnown.
const std::set<std::string> kSimulatorFiles = {"table1.yaml", "ste_example.yaml",
                                               "rig_example.yaml"};
const std::set<std::string> kNodeFiles = {"damping_id.yaml", "wavelet.yaml",
                                          "diagnostic_analyzers.yaml"};

TEST(ShippedConfig, ShippedFilesAreAllKnown) {
  int n = 0;
  for (const auto& f : std::filesystem::directory_iterator(configPath(""))) {
    if (f.path().extension() != ".yaml") continue;
    const std::string name = f.path().filename().string();
    ++n;
    EXPECT_TRUE(kSimulatorFiles.count(name) + kNodeFiles.count(name) == 1)
        << name << ": add it to a case of shipped_config_test.cpp";
  }
  EXPECT_EQ(n, static_cast<int>(kSimulatorFiles.size() + kNodeFiles.size()));
}

TEST(ShippedConfig, SimulatorFilesLoadAndValidate) {
  for (const std::string& name : kSimulatorFiles) {
    gear_sim::SimConfig c;
    std::string e;
    EXPECT_TRUE(gear_test::ok(gear_sim::loadSimConfigFile(configPath(name), &c), &e))
        << name << ": " << e;
    EXPECT_TRUE(c.check().ok()) << name << ": " << c.check().message();
    const YAML::Node root = YAML::LoadFile(configPath(name));
    if (root["encoder"]) {
      gear_sim::EncoderOptions enc;
      EXPECT_TRUE(gear_test::ok(gear_sim::loadEncoderOptions(root, &enc), &e)) << name << ": " << e;
      EXPECT_TRUE(enc.check().ok()) << name << ": " << enc.check().message();
    }
  }
}

TEST(ShippedConfig, DampingIdFileIsReadByTheNodesReaderWithoutUnknownKeys) {
  nodes::ParamReader p = readerOf(configPath("damping_id.yaml"));
  nodes::DampingIdNodeOptions o;
  ASSERT_TRUE(nodes::readDampingIdParameters(p, &o));
  EXPECT_TRUE(o.id.check().ok()) << o.id.check().message();
  EXPECT_TRUE(o.stream.check().ok()) << o.stream.check().message();
  // The file sets values (not only defaults): a few of them reach the options.
  const YAML::Node root = YAML::LoadFile(configPath("damping_id.yaml"));
  EXPECT_EQ(o.id.segment_length, root["segment_length"].as<double>());
  EXPECT_EQ(o.stream.segment_length, o.id.segment_length);
  EXPECT_EQ(o.intake.queue_size, root["queue_size"].as<int>());
  EXPECT_EQ(o.history_segments, root["history_segments"].as<int>());
}

TEST(ShippedConfig, WaveletFileIsReadByTheNodesReaderWithoutUnknownKeys) {
  nodes::ParamReader p = readerOf(configPath("wavelet.yaml"));
  nodes::WaveletNodeOptions o;
  ASSERT_TRUE(nodes::readWaveletParameters(p, &o));
  EXPECT_TRUE(o.wavelet.check().ok()) << o.wavelet.check().message();
  EXPECT_TRUE(o.stream.check().ok()) << o.stream.check().message();
  const YAML::Node root = YAML::LoadFile(configPath("wavelet.yaml"));
  EXPECT_EQ(o.window, root["window"].as<double>());
  EXPECT_EQ(o.stream.segment_length, o.window);
  EXPECT_EQ(o.wavelet.n_scales, root["n_scales"].as<int>());
  EXPECT_EQ(o.wavelet.peak_omega0, root["peak_omega0"].as<double>());
  EXPECT_EQ(o.wavelet.threads, root["threads"].as<int>());
}

// The same readers refuse a typo and a wrong type in a copy of a shipped file: the test above
// could not pass with a reader that accepts anything.
TEST(ShippedConfig, NodeReadersRefuseATypoAndAWrongTypeInAShippedFile) {
  YAML::Node typo = YAML::LoadFile(configPath("damping_id.yaml"));
  typo["segment_lenght"] = 1e-3;
  nodes::ParamReader p1(std::make_shared<gear_test::YamlParams>(typo));
  nodes::DampingIdNodeOptions o1;
  EXPECT_FALSE(nodes::readDampingIdParameters(p1, &o1));

  YAML::Node wrong = YAML::LoadFile(configPath("wavelet.yaml"));
  wrong["n_scales"] = "many";
  nodes::ParamReader p2(std::make_shared<gear_test::YamlParams>(wrong));
  nodes::WaveletNodeOptions o2;
  EXPECT_FALSE(nodes::readWaveletParameters(p2, &o2));

  YAML::Node invalid = YAML::LoadFile(configPath("wavelet.yaml"));
  invalid["window"] = -1.0;
  nodes::ParamReader p3(std::make_shared<gear_test::YamlParams>(invalid));
  nodes::WaveletNodeOptions o3;
  EXPECT_FALSE(nodes::readWaveletParameters(p3, &o3));
}

// ~threads of wavelet_node: out of [1, 256], or not an integer (a double, a string, a list, a
// boolean; an integer beyond 32 bits cannot reach the parameter server) stops the node
// at start; the range's ends are read as given.
TEST(ShippedConfig, WaveletReaderChecksTheThreadsParameter) {
  auto readThreads = [](const YAML::Node& value, nodes::WaveletNodeOptions* o) {
    YAML::Node n = YAML::LoadFile(configPath("wavelet.yaml"));
    n["threads"] = value;
    nodes::ParamReader p(std::make_shared<gear_test::YamlParams>(n));
    return nodes::readWaveletParameters(p, o);
  };
  for (const char* bad : {"0", "-1", "257", "2.5", "two", "1e12", "[2]", "true"}) {
    nodes::WaveletNodeOptions o;
    EXPECT_FALSE(readThreads(YAML::Load(bad), &o)) << "threads: " << bad;
  }
  for (int good : {1, 2, 256}) {
    nodes::WaveletNodeOptions o;
    ASSERT_TRUE(readThreads(YAML::Node(good), &o)) << "threads: " << good;
    EXPECT_EQ(o.wavelet.threads, good);
  }
}

// The STE parameters of damping_id_node (~ste, ~ste_damping, ~ste_calibration_segments) on the
// shipped file: a valid spec is read (and turns off the modeled response, which has no STE in it);
// each hostile value stops the node at start instead of running a wrong model.
TEST(ShippedConfig, DampingIdReaderChecksTheSteParameters) {
  auto read = [](const std::map<std::string, YAML::Node>& set, nodes::DampingIdNodeOptions* o) {
    YAML::Node n = YAML::LoadFile(configPath("damping_id.yaml"));
    for (const auto& [k, v] : set) n[k] = v;
    nodes::ParamReader p(std::make_shared<gear_test::YamlParams>(n));
    return nodes::readDampingIdParameters(p, o);
  };
  nodes::DampingIdNodeOptions ok;
  ASSERT_TRUE(read({{"ste", YAML::Node("mesh:3,shaft:1")},
                    {"ste_damping", YAML::Node("dte")},
                    {"publish_modeled_response", YAML::Node(true)}},
                   &ok));
  EXPECT_EQ(ok.ste_options.mesh_orders, 3);
  EXPECT_EQ(ok.ste_options.pinion_orders, 1);
  EXPECT_EQ(ok.ste_options.gear_orders, 1);
  EXPECT_EQ(ok.ste_options.damping, gear_sim::SteDamping::Dte);
  EXPECT_FALSE(ok.publish_modeled_response);

  const std::vector<std::map<std::string, YAML::Node>> hostile = {
      {{"ste", YAML::Node("mesh:x")}},
      {{"ste", YAML::Node("mesh:3,warp:2")}},
      {{"ste", YAML::Node("mesh:3")}, {"ste_damping", YAML::Node("viscous")}},
      {{"ste", YAML::Node("mesh:3")}, {"ste_calibration_segments", YAML::Node(0)}},
      {{"ste", YAML::Node("mesh:3")}, {"ste_calibration_segments", YAML::Node(1000000)}},
      {{"ste", YAML::Node("mesh:3")}, {"model", YAML::Node("constant")}},
      {{"ste", YAML::Node(3)}},
  };
  for (const auto& set : hostile) {
    nodes::DampingIdNodeOptions o;
    std::string shown;
    for (const auto& [k, v] : set) shown += k + "=" + v.as<std::string>() + " ";
    EXPECT_FALSE(read(set, &o)) << shown;
  }
}

TEST(ShippedConfig, DiagnosticAnalyzersCoverEveryLiveNode) {
  const YAML::Node root = YAML::LoadFile(configPath("diagnostic_analyzers.yaml"));
  ASSERT_TRUE(root["analyzers"]) << "no analyzers section";
  ASSERT_GT(root["pub_rate"].as<double>(), 0.0);
  std::set<std::string> paths;
  for (const auto& group : root["analyzers"]) {
    ASSERT_TRUE(group.second["type"]) << group.first.as<std::string>();
    for (const auto& a : group.second["analyzers"]) {
      const YAML::Node n = a.second;
      EXPECT_EQ(n["type"].as<std::string>(), "diagnostic_aggregator/GenericAnalyzer");
      EXPECT_GT(n["timeout"].as<double>(), 0.0) << a.first.as<std::string>();
      paths.insert(n["path"].as<std::string>());
    }
  }
  for (const char* node : {"damping_id", "wavelet"}) EXPECT_EQ(paths.count(node), 1u) << node;
}

}  // namespace
