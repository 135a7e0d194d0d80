// Rendered test data shared by the whole-system tests: three robots (EuRoC
// MH_01..03 trajectories) in one hall, rendered once per machine and cached.
#pragma once

#include <string>
#include <vector>

namespace hermes::test_support {

/// The three sequence names, in agent order.
const std::vector<std::string>& hallSequences();
/// Folder with <sequence>/mav0/... for each of hallSequences(), 10 s at 10 Hz;
/// rendered on first use under the temp dir. Empty when rendering failed.
std::string renderedHall();

/// Two robots (MH_01_easy, MH_02_easy) flying the same route through the hall,
/// 40..70 s of their trajectories at 10 Hz: they meet all along (loops before
/// and after any point). Rendered on first use; empty when rendering failed.
std::string renderedMeeting();
const std::vector<std::string>& meetingSequences();

}  // namespace hermes::test_support
