// A rendered EuRoC-like stereo clip held in memory: real V1_01 ground truth,
// EuRoC calibration, the procedural scene (seed 7), written once by the
// renderer into a temp folder and read back through the dataset reader.
#pragma once

#include <string>
#include <vector>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/core/trajectory.h"

namespace hermes::test {

struct RenderedClip {
  std::vector<CameraFrame> frames;  ///< rectified stereo, in time order
  agent::AgentCamera camera;        ///< intrinsics, baseline, T_B_C
  Trajectory groundtruth;           ///< body poses (dataset ground truth)
};

/// `duration_s` of V1_01 from `start_s` at 20 Hz, rendered into
/// TempDir()/`name`_<pid> (ctest runs test cases as parallel processes).
/// Errors when the shared data or the renderer fail.
Expected<RenderedClip> renderV101Clip(const std::string& name, double start_s, double duration_s);

}  // namespace hermes::test
