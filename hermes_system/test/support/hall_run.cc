#include "hall_run.h"

#include <gtest/gtest.h>

#include "rendered_hall.h"

namespace hermes::test_support {

namespace {

std::unique_ptr<system::OfflineRun> makeRun(const system::SystemParams& params, const std::string& dir,
                                            const std::vector<std::string>& sequences,
                                            const std::string& root, const std::vector<std::size_t>& max_frames) {
  EXPECT_FALSE(dir.empty()) << "rendering failed";
  std::vector<system::AgentSource> sources;
  for (const std::string& s : sequences) {
    auto ds = Dataset::open(dir + "/" + s, params.run.dataset);
    EXPECT_TRUE(ds.ok()) << ds.error();
    if (!ds.ok()) return nullptr;
    const std::size_t i = sources.size();
    sources.push_back({s, std::move(*ds), i < max_frames.size() ? max_frames[i] : 0});
  }
  auto run = system::OfflineRun::create(params, std::move(sources), root, HERMES_SOURCE_DIR);
  EXPECT_TRUE(run.ok()) << run.error();
  return run.ok() ? std::move(*run) : nullptr;
}

}  // namespace

std::unique_ptr<system::OfflineRun> makeHallRun(const system::SystemParams& params,
                                                const std::string& tag,
                                                const std::vector<std::size_t>& max_frames) {
  return makeRun(params, renderedHall(), hallSequences(),
                 ::testing::TempDir() + "/hermes_offline_" + tag + "/spool", max_frames);
}

std::unique_ptr<system::OfflineRun> makeMeetingRun(const system::SystemParams& params,
                                                   const std::string& tag) {
  return makeRun(params, renderedMeeting(), meetingSequences(),
                 ::testing::TempDir() + "/hermes_meeting_" + tag, {});
}

std::unique_ptr<system::OfflineRun> makeRunOn(const system::SystemParams& params, const std::string& dir,
                                              const std::vector<std::string>& sequences,
                                              const std::string& tag) {
  return makeRun(params, dir, sequences, ::testing::TempDir() + "/hermes_run_" + tag, {});
}

system::SystemParams testRunParams() {
  system::SystemParams p;
  p.run.agent.uplink.buffer.fsync = false;
  return p;
}

}  // namespace hermes::test_support
