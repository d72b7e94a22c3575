// The report script on a small real result (simulate -> analyze with every model and the
// wavelet on the free decay -> report): every figure exists, is a PNG of the documented size,
// and index.html shows it; a missing result gives exit code 2 with a message.
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>

#include "tool_runner.hpp"

namespace fs = std::filesystem;

namespace {

const std::string kParams = std::string(GEAR_SOURCE_DIR) + "/config/table1.yaml";
const std::string kReport =
    "/usr/bin/python3 " + std::string(GEAR_SOURCE_DIR) + "/gear_damping_id/scripts/report ";

// Width and height from a PNG's IHDR chunk (0 x 0 if not a PNG).
std::array<std::uint32_t, 2> pngSize(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  unsigned char b[24] = {};
  f.read(reinterpret_cast<char*>(b), sizeof b);
  const unsigned char sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (!f || !std::equal(sig, sig + 8, b)) return {0, 0};
  auto be = [&](int o) {
    return (std::uint32_t(b[o]) << 24) | (std::uint32_t(b[o + 1]) << 16) |
           (std::uint32_t(b[o + 2]) << 8) | std::uint32_t(b[o + 3]);
  };
  return {be(16), be(20)};
}

int shell(const std::string& cmd) {
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(Report, DrawsEveryFigureOfASmallResult) {
  gear_test::ScratchDir scratch("report_test");
  const fs::path dir = scratch.path(), res = dir / "result";
  fs::create_directories(res);
  const std::string sim = " --config " + kParams + " --duration 0.004";
  ASSERT_EQ(gear_test::runTool("simulate", sim + " --output " + (res / "signal.csv").string(), dir).code, 0);
  ASSERT_EQ(gear_test::runTool("simulate", sim + " --free-response --output " +
                                               (res / "free_response.csv").string(), dir).code, 0);
  const gear_test::ToolRun a = gear_test::runTool(
      "analyze", "--input " + (res / "signal.csv").string() + " --params " + kParams +
                     " --formulation known --formulation legacy --model piecewise --model constant"
                     " --model load_law --wavelet-input " + (res / "free_response.csv").string() +
                     " --output " + (res / "result.json").string() + " --csv-out " +
                     (res / "tables").string(),
      dir);
  ASSERT_EQ(a.code, 0) << a.err;
  ASSERT_EQ(shell(kReport + res.string() + " >" + (dir / "out.txt").string() + " 2>&1"), 0)
      << gear_test::readText(dir / "out.txt");
  const std::string index = gear_test::readText(res / "report" / "index.html");
  for (const char* fig : {"fig04_load_stiffness.png", "fig05_dte.png", "fig06_response_legacy.png",
                          "fig07_response_constant.png", "fig08_damping.png",
                          "fig09_response_piecewise.png", "fig09b_response_load_law.png",
                          "fig10_scalogram.png", "fig11_spectrum.png", "fig12_envelopes.png"}) {
    const fs::path p = res / "report" / fig;
    ASSERT_TRUE(fs::is_regular_file(p)) << fig;
    EXPECT_GT(fs::file_size(p), 10000u) << fig;  // a drawn figure, not an empty canvas
    const auto size = pngSize(p);
    EXPECT_EQ(size[0], 1200u) << fig;
    EXPECT_EQ(size[1], 750u) << fig;
    EXPECT_NE(index.find(fig), std::string::npos) << fig;
  }
  EXPECT_NE(index.find("Wavelet modes"), std::string::npos);
  EXPECT_EQ(index.find("not drawn"), std::string::npos) << index;
}

TEST(Report, ExitsWithTwoWithoutAResult) {
  gear_test::ScratchDir scratch("report_missing_test");
  const fs::path out = scratch.path() / "out.txt";
  EXPECT_EQ(shell(kReport + scratch.path().string() + " 2>" + out.string()), 2);
  EXPECT_NE(gear_test::readText(out).find("no result.json"), std::string::npos);
  EXPECT_EQ(shell(kReport + (scratch.path() / "nope").string() + " 2>" + out.string()), 2);
  EXPECT_NE(gear_test::readText(out).find("no such directory"), std::string::npos);
}

}  // namespace
