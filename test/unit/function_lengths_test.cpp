// scripts/function_lengths.py (the issue-17 bar "no function over ~120 lines", run by .ci/run):
// on a fixture with the constructs that trip a brace count (braces in comments, strings, raw
// strings, character literals and macros; lambdas; in-class members; operators; templates; a
// constructor's brace-initialised members) it reports every definition with its line count
// and nothing else, lists only those over --limit, and fails with --fail only when one is.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <sstream>
#include <string>

#include "tool_runner.hpp"

namespace {

using gear_test::ScratchDir;
using gear_test::ToolRun;

// Line 1 is the comment; each definition's expected length is in FunctionLengths.* below.
const char* const kFixture = R"fixture(// A comment with an opening brace { that is no scope.
#include <string>
#define BRACES() { }
namespace a {
int small() { return 1; }
struct S {
  S() : x_(0) {}
  int get() const {
    return x_;
  }
  bool operator()(int k) const { return k == x_; }
  int x_;
};
const char* text = "}{ not a scope";
const int table[] = {1, 2, 3};
int S2::big(int n) {
  auto f = [&](int k) {
    return k + n;
  };
  const char* raw = R"(}}}{)";
  /* } */
  if (n > 0) {
    return f(n);
  }
  // }
  return table[0] + '}';
}
}  // namespace a
bool operator==(const a::S& x, const a::S& y) {
  return x.x_ == y.x_;
}
template <class T, int N = 2>
T twice(T x) {
  return N * x;
}
struct Init {
  Init(int a, int b)
      : a_{a},
        b_{b} {
    a_ += b_;
    b_ = 0;
  }
  explicit operator bool() const { return a_ != 0; }
  int a_, b_;
};
)fixture";

class FunctionLengths : public ::testing::Test {
 protected:
  void SetUp() override { gear_test::writeText(fixture(), kFixture); }
  std::filesystem::path fixture() const { return dir_.path() / "fixture.cpp"; }
  ToolRun run(const std::string& args) {
    return gear_test::runShell("/usr/bin/python3 '" + std::string(GEAR_SOURCE_DIR) +
                                   "/scripts/function_lengths.py' " + args + " '" +
                                   fixture().string() + "'",
                               dir_.path(), "function_lengths");
  }
  // name -> length of the rows "LENGTH  FILE:LINE  NAME".
  static std::map<std::string, int> rows(const std::string& out) {
    std::map<std::string, int> r;
    std::istringstream in(out);
    std::string line;
    while (std::getline(in, line)) {
      std::istringstream fields(line);
      int length = 0;
      std::string where, name;
      fields >> length >> where;
      std::getline(fields >> std::ws, name);
      r[name] = length;
    }
    return r;
  }
  ScratchDir dir_{"gear_function_lengths"};
};

TEST_F(FunctionLengths, EveryDefinitionIsFoundWithItsLinesAndNothingElse) {
  const ToolRun r = run("--top 50");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::map<std::string, int> expected = {
      {"S2::big", 12}, {"Init", 6},  {"twice", 4},      {"operator==", 3},    {"get", 3},
      {"S", 1},        {"small", 1}, {"operator()", 1}, {"operator bool", 1},
  };
  EXPECT_EQ(rows(r.out), expected) << r.out;
}

TEST_F(FunctionLengths, OnlyFunctionsOverTheLimitAreListedAndFailOnlyWhenAsked) {
  ToolRun r = run("--limit 11");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(rows(r.out), (std::map<std::string, int>{{"S2::big", 12}})) << r.out;
  r = run("--limit 11 --fail");
  EXPECT_EQ(r.code, 1) << r.out << r.err;
  r = run("--limit 12 --fail");
  EXPECT_EQ(r.code, 0) << r.out << r.err;
  EXPECT_TRUE(r.out.empty()) << r.out;
}

}  // namespace
