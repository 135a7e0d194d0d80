// A long mission on the simulated clock (issue 20's soak, `hermes bench soak`):
// a swarm whose robots fly their sequence again and again, each sortie a new
// session of the same robot (it lands, its map is gone, it takes off again and
// must be re-localised by the server's map), in waves spread over the mission.
//
// The data is the whole-sequence renders, time-shifted: each robot gets one
// EuRoC folder (writeMissionView) whose cameras and ground truth hold its
// sequence once per sortie, stamped on the mission's clock; images are linked,
// not copied. The offline runner flies it as AgentSource::sorties (offline_run.h),
// each sortie replaying the sequence's tracking recording moved onto that clock.
#pragma once

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "hermes/core/status.h"

namespace hermes::system {

struct MissionPlan {
  int robots = 10;
  double duration_s = 3600;  ///< [s] the waves start over this span
  int waves = 3;             ///< wave w starts at w * duration / waves
  int sorties = 1;           ///< per robot (<= waves): robot k flies waves (k + j) mod waves, j < sorties
  double stagger_s = 15;     ///< [s] the i-th robot of a wave takes off i * stagger_s after it starts
  std::vector<std::string> sequences;  ///< robot k flies sequences[k % size]
};

struct MissionRobot {
  std::string name;      ///< r01, r02, ...
  std::string sequence;  ///< the one it flies every sortie
  std::vector<double> takeoffs_s;  ///< [s] mission time of each take-off
};

/// The robots and their take-offs. `length_s(sequence)`: how long a sortie of
/// it lasts. Errors: no robot / sortie / sequence, or a sortie that would not
/// have landed (plus 2 s) before the robot's next take-off.
Expected<std::vector<MissionRobot>> planMission(const MissionPlan& plan,
                                                const std::function<double(const std::string&)>& length_s);

struct MissionView {
  std::size_t frames = 0;                ///< cam0 frames over all sorties
  std::vector<std::size_t> first_frames; ///< per sortie: its first cam0 frame
  std::vector<double> shifts_s;          ///< per sortie: mission stamp - source stamp [s]
};

/// Writes the EuRoC folder `out` (emptied first): every `mav0/<sensor>/data.csv`
/// of `source` (cameras, ground truth) once per take-off, each row's stamp
/// moved to epoch_s + takeoff + (stamp - first cam0 stamp); everything else
/// linked. Errors name the file and row.
Expected<MissionView> writeMissionView(const std::string& source, const std::vector<double>& takeoffs_s,
                                       double epoch_s, const std::string& out);

}  // namespace hermes::system
