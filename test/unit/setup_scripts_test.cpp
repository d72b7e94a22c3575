// The set-up scripts never delete or overwrite what they did not create: scripts/common.sh's
// gear_link_checkout (workspace src/gear_damping) and gear_prepare_out_dir (the demo's output
// directory), run by bash on scratch directories (no build, no apt), and the package.xml rosdep
// key check (scripts/check_rosdep_keys.py).
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "tool_runner.hpp"

namespace fs = std::filesystem;

namespace {

using gear_test::readText;
using gear_test::ScratchDir;
using gear_test::writeText;

// Runs `body` in bash after sourcing `common` (a copy of scripts/common.sh: GEAR_REPO is the
// directory above the copy's scripts/) with GEAR_DAMPING_WS = `ws`.
gear_test::ToolRun runBash(const fs::path& common, const fs::path& ws, const std::string& body,
                           const fs::path& scratch) {
  const fs::path script = scratch / "run.sh";
  writeText(script, "export GEAR_DAMPING_WS='" + ws.string() + "'\nsource '" + common.string() +
                        "'\n" + body + "\n");
  return gear_test::runShell("bash '" + script.string() + "'", scratch, "bash");
}

// A fake checkout at `repo`: scripts/common.sh copied from the source tree, plus a marker file.
fs::path makeCheckout(const fs::path& repo) {
  fs::create_directories(repo / "scripts");
  fs::copy_file(fs::path(GEAR_SOURCE_DIR) / "scripts/common.sh", repo / "scripts/common.sh",
                fs::copy_options::overwrite_existing);
  writeText(repo / "package.xml", "<package><name>gear_damping</name></package>\n");
  return repo / "scripts/common.sh";
}

class SetupScripts : public ::testing::Test {
 protected:
  ScratchDir dir_{"gear_setup_scripts"};
  fs::path root() const { return dir_.path(); }
};

TEST_F(SetupScripts, FreshWorkspaceGetsASymlinkToTheCheckout) {
  const fs::path common = makeCheckout(root() / "clone");
  const fs::path ws = root() / "ws";
  const gear_test::ToolRun r = runBash(common, ws, "gear_link_checkout", root());
  ASSERT_EQ(r.code, 0) << r.err;
  const fs::path target = ws / "src/gear_damping";
  ASSERT_TRUE(fs::is_symlink(target));
  EXPECT_EQ(fs::canonical(target), fs::canonical(root() / "clone"));
}

TEST_F(SetupScripts, ForeignDirectoryIsRefusedAndKept) {
  const fs::path common = makeCheckout(root() / "clone");
  const fs::path ws = root() / "ws";
  const fs::path other = ws / "src/gear_damping";
  fs::create_directories(other);
  writeText(other / "uncommitted_work.cpp", "precious\n");
  const gear_test::ToolRun r = runBash(common, ws, "gear_link_checkout", root());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("refusing"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find(other.string()), std::string::npos) << "message names the path: " << r.err;
  EXPECT_FALSE(fs::is_symlink(other));
  EXPECT_EQ(readText(other / "uncommitted_work.cpp"), "precious\n");
}

TEST_F(SetupScripts, ForeignFileIsRefusedAndKept) {
  const fs::path common = makeCheckout(root() / "clone");
  const fs::path ws = root() / "ws";
  fs::create_directories(ws / "src");
  writeText(ws / "src/gear_damping", "a file\n");
  const gear_test::ToolRun r = runBash(common, ws, "gear_link_checkout", root());
  EXPECT_NE(r.code, 0);
  EXPECT_EQ(readText(ws / "src/gear_damping"), "a file\n");
}

// The data-loss case: the clone sits at WS/src/gear_damping and GEAR_DAMPING_WS=WS.
TEST_F(SetupScripts, CloneInsideTheWorkspaceIsUsedInPlace) {
  const fs::path ws = root() / "catkin_ws";
  const fs::path clone = ws / "src/gear_damping";
  const fs::path common = makeCheckout(clone);
  writeText(clone / "uncommitted_work.cpp", "precious\n");
  const gear_test::ToolRun r =
      runBash(common, ws, "gear_link_checkout && gear_link_checkout", root());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_FALSE(fs::is_symlink(clone));
  EXPECT_EQ(readText(clone / "uncommitted_work.cpp"), "precious\n");
  EXPECT_TRUE(fs::exists(clone / "scripts/common.sh"));
}

// A clone elsewhere under WS/src (e.g. WS/src/vendor/gear_damping): catkin finds it there, so no
// second copy is linked.
TEST_F(SetupScripts, CloneElsewhereUnderSrcIsNotLinkedTwice) {
  const fs::path ws = root() / "catkin_ws";
  const fs::path common = makeCheckout(ws / "src/vendor/gear_damping");
  const gear_test::ToolRun r = runBash(common, ws, "gear_link_checkout", root());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_FALSE(fs::exists(ws / "src/gear_damping"));
}

TEST_F(SetupScripts, OldSymlinkIsRepointedAndItsTargetKept) {
  const fs::path common = makeCheckout(root() / "clone");
  const fs::path old_clone = root() / "old_clone";
  fs::create_directories(old_clone);
  writeText(old_clone / "file.txt", "kept\n");
  const fs::path ws = root() / "ws";
  fs::create_directories(ws / "src");
  fs::create_directory_symlink(old_clone, ws / "src/gear_damping");
  const gear_test::ToolRun r = runBash(common, ws, "gear_link_checkout", root());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(fs::canonical(ws / "src/gear_damping"), fs::canonical(root() / "clone"));
  EXPECT_EQ(readText(old_clone / "file.txt"), "kept\n");
}

TEST_F(SetupScripts, DemoOutputDirectoryWithForeignFilesIsRefused) {
  const fs::path common = makeCheckout(root() / "clone");
  const fs::path out = root() / "my_data";
  fs::create_directories(out);
  writeText(out / "signal.csv", "my measurement\n");
  const gear_test::ToolRun r =
      runBash(common, root() / "ws", "gear_prepare_out_dir '" + out.string() + "'", root());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.err.find("refusing"), std::string::npos) << r.err;
  EXPECT_EQ(readText(out / "signal.csv"), "my measurement\n");
  EXPECT_FALSE(fs::exists(out / ".gear_damping_demo"));
}

TEST_F(SetupScripts, DemoOutputDirectoryNewOrOwnIsAccepted) {
  const fs::path common = makeCheckout(root() / "clone");
  const fs::path out = root() / "results";
  gear_test::ToolRun r =
      runBash(common, root() / "ws", "gear_prepare_out_dir '" + out.string() + "'", root());
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.out, fs::canonical(out).string() + "\n");
  EXPECT_TRUE(fs::exists(out / ".gear_damping_demo"));
  writeText(out / "signal.csv", "from the demo\n");  // a second run reuses its own directory
  r = runBash(common, root() / "ws", "gear_prepare_out_dir '" + out.string() + "'", root());
  EXPECT_EQ(r.code, 0) << r.err;
}

// Every package.xml key is one the script verified against the rosdistro rosdep database, and
// every system key's Debian package is in the scripts' apt list (scripts/check_rosdep_keys.py).
TEST(PackageManifest, EveryRosdepKeyIsVerified) {
  ScratchDir dir("gear_rosdep_keys");
  const std::string cmd = "/usr/bin/python3 '" + std::string(GEAR_SOURCE_DIR) +
                          "/scripts/check_rosdep_keys.py' >'" + (dir.path() / "out").string() +
                          "' 2>&1";
  const int status = std::system(cmd.c_str());
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << readText(dir.path() / "out");
}

}  // namespace
