// The offline runner over the rendered hall (rendered_hall.h): one agent per
// hall (or meeting) sequence, spools under the test temp dir.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "hermes/system/offline_run.h"

namespace hermes::test_support {

/// Spools in <test temp dir>/hermes_offline_<tag>/spool. Null (with a gtest
/// failure) when rendering or opening a dataset failed. `max_frames[i]` (0 = all)
/// cuts robot i's sequence short.
std::unique_ptr<system::OfflineRun> makeHallRun(const system::SystemParams& params,
                                                const std::string& tag,
                                                const std::vector<std::size_t>& max_frames = {});

/// The two robots of renderedMeeting() (30 s each), spools in <test temp
/// dir>/hermes_meeting_<tag>. Null (with a gtest failure) as makeHallRun.
std::unique_ptr<system::OfflineRun> makeMeetingRun(const system::SystemParams& params,
                                                   const std::string& tag);

/// One agent per `sequences` folder under `dir` (rendered in EuRoC layout), spools in
/// <test temp dir>/hermes_run_<tag>. Null (with a gtest failure) as makeHallRun.
std::unique_ptr<system::OfflineRun> makeRunOn(const system::SystemParams& params, const std::string& dir,
                                              const std::vector<std::string>& sequences,
                                              const std::string& tag);

/// Default system params for tests: the spools do not fsync.
system::SystemParams testRunParams();

}  // namespace hermes::test_support
