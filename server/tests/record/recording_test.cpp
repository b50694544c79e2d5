// Where a controller's recording goes and what starting one refuses
// (record/recording.hpp): one test per rule, in a fresh folder.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "record/recording.hpp"
#include "temp_dir.hpp"

namespace tactile {
namespace {

using Clock = std::chrono::system_clock;
// 2026-12-06 07:08:28.042 UTC
const Clock::time_point at = Clock::time_point(std::chrono::milliseconds(1796540908042));

TEST(RecordingPath, NoFolderNoRecording) {
  std::string error;
  EXPECT_EQ(Recording::path_in("", "a.mcap", at, &error), "");
  EXPECT_EQ(error, "StartRecording: this server has no recordings folder (start it with --recordings DIR)");
}

TEST(RecordingPath, APlainNameInTheFolderWithMcapAdded) {
  test::TempDir dir;
  std::string error;
  EXPECT_EQ(Recording::path_in(dir.path(), "press_1", at, &error), dir.file("press_1.mcap")) << error;
  EXPECT_EQ(Recording::path_in(dir.path(), "press-2.mcap", at, &error), dir.file("press-2.mcap")) << error;
}

TEST(RecordingPath, ANameThatIsNotPlainIsRefusedAndShownSafely) {
  test::TempDir dir;
  for (const std::string& bad :
       std::vector<std::string>{"../up.mcap", ".hidden", "a/b.mcap", std::string(129, 'a'), "x\ny"}) {
    std::string error;
    EXPECT_EQ(Recording::path_in(dir.path(), bad, at, &error), "") << bad;
    EXPECT_NE(error.find("is not a plain file name"), std::string::npos) << error;
    EXPECT_EQ(error.find('\n'), std::string::npos) << "a control character reaches the log: " << error;
  }
}

TEST(RecordingPath, AFileAlreadyThereIsNeverOverwritten) {
  test::TempDir dir;
  dir.write("take.mcap", "kept");
  std::string error;
  EXPECT_EQ(Recording::path_in(dir.path(), "take", at, &error), "");
  EXPECT_EQ(error, "StartRecording: 'take.mcap' is already in the recordings folder: pick another name");
}

TEST(RecordingPath, NoNamePicksTheTimeToTheMillisecondAndCountsPastTakenOnes) {
  test::TempDir dir;
  std::string error;
  const std::string first = Recording::path_in(dir.path(), "", at, &error);
  EXPECT_EQ(first, dir.file("session-20261206-070828-042.mcap")) << error;
  dir.write("session-20261206-070828-042.mcap", "");
  EXPECT_EQ(Recording::path_in(dir.path(), "", at, &error), dir.file("session-20261206-070828-042-2.mcap"));
  dir.write("session-20261206-070828-042-2.mcap", "");
  EXPECT_EQ(Recording::path_in(dir.path(), "", at, &error), dir.file("session-20261206-070828-042-3.mcap"));
}

TEST(Recording, OneAtATimeAndAFileThatCannotBeMadeLeavesNothing) {
  test::TempDir dir;
  Recording r;
  EXPECT_EQ(
      r.start(dir.file("no/such/folder/a.mcap"), {}),
      "StartRecording: cannot write recording '" + dir.file("no/such/folder/a.mcap") + "': No such file or directory");
  EXPECT_FALSE(r.active());
  ASSERT_EQ(r.start(dir.file("a.mcap"), {}), "");
  EXPECT_TRUE(r.active());
  EXPECT_EQ(r.path(), dir.file("a.mcap"));
  EXPECT_EQ(r.start(dir.file("b.mcap"), {}), "a recording is under way ('" + dir.file("a.mcap") + "'): stop it first");
  EXPECT_FALSE(std::filesystem::exists(dir.file("b.mcap")));
  r.finish();
  EXPECT_FALSE(r.active());
  EXPECT_GT(std::filesystem::file_size(dir.file("a.mcap")), 0u) << "closed, with its summary";
}

TEST(Recording, AFaultStopsItAndIsToldOnce) {
  test::TempDir dir;
  Recording r;
  ASSERT_EQ(r.start(dir.file("a.mcap"), {}), "");
  r.fail("the disk is full");
  EXPECT_EQ(r.check(), "recording: the disk is full");
  EXPECT_FALSE(r.active());
  EXPECT_EQ(r.check(), "");
  r.finish();
}

}  // namespace
}  // namespace tactile
