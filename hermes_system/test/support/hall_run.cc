#include "hall_run.h"

#include <gtest/gtest.h>

#include "rendered_hall.h"

namespace hermes::test_support {

std::unique_ptr<system::OfflineRun> makeHallRun(const system::SystemParams& params,
                                                const std::string& tag,
                                                const std::vector<std::size_t>& max_frames) {
  const std::string hall = renderedHall();
  EXPECT_FALSE(hall.empty()) << "rendering failed";
  std::vector<system::AgentSource> sources;
  for (const std::string& s : hallSequences()) {
    auto ds = Dataset::open(hall + "/" + s, params.run.dataset);
    EXPECT_TRUE(ds.ok()) << ds.error();
    if (!ds.ok()) return nullptr;
    const std::size_t i = sources.size();
    sources.push_back({s, std::move(*ds), i < max_frames.size() ? max_frames[i] : 0});
  }
  const std::string root = ::testing::TempDir() + "/hermes_offline_" + tag;
  auto run = system::OfflineRun::create(params, std::move(sources), root + "/spool", HERMES_SOURCE_DIR);
  EXPECT_TRUE(run.ok()) << run.error();
  return run.ok() ? std::move(*run) : nullptr;
}

}  // namespace hermes::test_support
