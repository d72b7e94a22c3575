// gear_sim::Status and Result<T> (gear_sim/status.hpp), the one result shape of every fallible
// operation: codes, the field, the message, OptionStatus conversion, context, Result's value.
#include "gear_sim/status.hpp"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "gear_damping_id/signal_view.hpp"
#include "gear_damping_id/ste_model.hpp"
#include "gear_sim/config_yaml.hpp"
#include "gear_sim/option_status.hpp"
#include "gear_sim/signal_csv.hpp"
#include "gear_sim/ste.hpp"

namespace {

using gear_sim::OptionStatus;
using gear_sim::Result;
using gear_sim::Status;
using gear_sim::StatusCode;

TEST(Status, DefaultIsOkWithoutFieldOrMessage) {
  const Status s;
  EXPECT_TRUE(s.ok());
  EXPECT_TRUE(static_cast<bool>(s));
  EXPECT_EQ(s.code(), StatusCode::Ok);
  EXPECT_EQ(s.field(), "");
  EXPECT_EQ(s.message(), "");
}

TEST(Status, EachFactoryKeepsItsCodeFieldAndMessage) {
  const std::vector<std::pair<Status, StatusCode>> cases = {
      {Status::invalidArgument("m", "f"), StatusCode::InvalidArgument},
      {Status::invalidInput("m", "f"), StatusCode::InvalidInput},
      {Status::ioError("m", "f"), StatusCode::IoError},
      {Status::notIdentifiable("m", "f"), StatusCode::NotIdentifiable},
      {Status::resourceLimit("m", "f"), StatusCode::ResourceLimit},
      {Status::internal("m", "f"), StatusCode::Internal}};
  for (const auto& [s, code] : cases) {
    EXPECT_FALSE(s.ok()) << toString(code);
    EXPECT_FALSE(static_cast<bool>(s));
    EXPECT_EQ(s.code(), code);
    EXPECT_EQ(s.field(), "f");
    EXPECT_EQ(s.message(), "m");
  }
}

TEST(Status, AFailureWithoutMessageSaysItsCode) {
  const Status s(StatusCode::IoError, "");
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.message(), "I/O error");
  EXPECT_EQ(s.field(), "");
}

TEST(Status, OptionStatusConvertsKeepingTheFieldAndTheMessage) {
  const OptionStatus bad =
      gear_sim::violated("IdentificationOptions", "segment_length", -0.5, "must be > 0 [s]");
  const Status s = bad;
  EXPECT_EQ(s.code(), StatusCode::InvalidArgument);
  EXPECT_EQ(s.field(), "segment_length");
  EXPECT_EQ(s.message(),
            "`IdentificationOptions::segment_length = -0.5`: violated `must be > 0 [s]`");
  EXPECT_EQ(s.message(), bad.message());
  const Status ok = OptionStatus{};
  EXPECT_TRUE(ok.ok());
  EXPECT_EQ(ok.message(), "");
}

TEST(Status, WithContextPrefixesTheMessageAndKeepsCodeAndField) {
  const Status s = Status::invalidInput("line 3: malformed number", "dte").withContext("x.csv");
  EXPECT_EQ(s.code(), StatusCode::InvalidInput);
  EXPECT_EQ(s.field(), "dte");
  EXPECT_EQ(s.message(), "x.csv: line 3: malformed number");
  EXPECT_TRUE(Status().withContext("x.csv").ok());
  EXPECT_EQ(Status().withContext("x.csv").message(), "");
}

TEST(Status, PrintsCodeFieldAndMessage) {
  std::ostringstream os;
  os << Status::invalidInput("bad", "load.file") << "|" << Status::ioError("gone") << "|"
     << Status();
  EXPECT_EQ(os.str(), "invalid input [load.file]: bad|I/O error: gone|ok");
}

TEST(Result, HoldsAValue) {
  Result<std::vector<int>> r = std::vector<int>{1, 2, 3};
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(r.status().ok());
  EXPECT_EQ(r->size(), 3u);
  EXPECT_EQ((*r)[1], 2);
  r.value().push_back(4);
  EXPECT_EQ(r.value().size(), 4u);
  const std::vector<int> moved = std::move(r).value();
  EXPECT_EQ(moved.size(), 4u);
}

TEST(Result, HoldsAFailureWithoutValue) {
  const Result<double> r = Status::notIdentifiable("no segment", "segment_length");
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::NotIdentifiable);
  EXPECT_EQ(r.status().field(), "segment_length");
  EXPECT_EQ(r.status().message(), "no segment");
}

TEST(Result, AnOkStatusWithoutValueIsAnInternalError) {
  const Result<int> r = Status();
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::Internal);
  EXPECT_NE(r.status().message(), "");
}

TEST(SteDamping, NamesReadBackAndUnknownNamesAreRefused) {
  for (auto d : {gear_sim::SteDamping::Relative, gear_sim::SteDamping::Dte}) {
    const Result<gear_sim::SteDamping> back =
        gear_sim::parseSteDamping(gear_sim::steDampingName(d));
    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_EQ(*back, d);
  }
  EXPECT_STREQ(gear_sim::steDampingName(gear_sim::SteDamping::Relative), "relative");
  EXPECT_STREQ(gear_sim::steDampingName(gear_sim::SteDamping::Dte), "dte");
  const Result<gear_sim::SteDamping> bad = gear_sim::parseSteDamping("viscous");
  EXPECT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::InvalidArgument);
  EXPECT_EQ(bad.status().message(), "unknown name 'viscous' (one of: relative, dte)");
}

// The field each kind of failure names: a YAML key, an options field, a CSV column, a channel.
TEST(StatusField, AMisspeltYamlKeyIsInvalidInputNamingTheKey) {
  gear_sim::SimConfig c;
  const Status s = gear_sim::loadSimConfig(YAML::Load("load: {amplitud: 1}"), &c);
  EXPECT_EQ(s.code(), StatusCode::InvalidInput);
  EXPECT_EQ(s.field(), "load.amplitud");
  EXPECT_EQ(s.message().rfind("load.amplitud: unknown key", 0), 0u) << s;
}

TEST(StatusField, ABrokenOptionRuleIsInvalidArgumentNamingTheOptionsField) {
  gear_sim::SimConfig c;
  const Status s = gear_sim::loadSimConfig(YAML::Load("mesh: {k_min: -1}"), &c);
  EXPECT_EQ(s.code(), StatusCode::InvalidArgument);
  EXPECT_EQ(s.field(), "mesh.k_min");
  EXPECT_NE(s.message().find("violated `must be finite and > 0 [N/m]`"), std::string::npos) << s;
}

TEST(StatusField, AMissingCsvColumnIsNamedAndAMissingFileIsAnIoError) {
  const std::string path =
      (std::filesystem::temp_directory_path() / "status_test_no_dte.csv").string();
  std::ofstream(path) << "time,torque\n0,1\n1e-6,1\n";
  gear_sim::SignalTable t;
  const Status missing = gear_sim::readSignalCsv(path, &t);
  EXPECT_EQ(missing.code(), StatusCode::InvalidInput);
  EXPECT_EQ(missing.field(), "dte");
  EXPECT_EQ(missing.message(), path + ": missing required column 'dte'");
  std::filesystem::remove(path);
  EXPECT_EQ(gear_sim::readSignalCsv(path, &t).code(), StatusCode::IoError);
}

TEST(StatusField, AMissingChannelNamesTheChannelAndWhatNeedsIt) {
  gear_damping_id::ChannelSet present;  // dte only
  const Status s = gear_damping_id::checkChannels(present, gear_damping_id::Formulation::Known,
                                                  gear_damping_id::DampingModel::Piecewise);
  EXPECT_EQ(s.code(), StatusCode::InvalidInput);
  EXPECT_EQ(s.field(), "stiffness");
  EXPECT_EQ(s.message(), "column 'stiffness' is required by formulation 'known' but missing");
  present.stiffness = present.torque = true;
  EXPECT_TRUE(gear_damping_id::checkChannels(present, gear_damping_id::Formulation::Known,
                                             gear_damping_id::DampingModel::Piecewise)
                  .ok());
}

// The STE spec's message carries no option prefix: the CLI adds "--ste: ", the node "~ste".
TEST(StatusField, AnSteSpecErrorNamesTheItemWithoutTheCliPrefix) {
  gear_damping_id::SteModelOptions o;
  const Status s = gear_damping_id::parseSteSpec("mesh:x", &o);
  EXPECT_EQ(s.code(), StatusCode::InvalidArgument);
  EXPECT_EQ(s.message().rfind("'mesh:x' is not one of", 0), 0u) << s;
  EXPECT_TRUE(gear_damping_id::parseSteSpec("mesh:3,shaft:1", &o).ok());
  EXPECT_EQ(o.mesh_orders, 3);
}

}  // namespace
