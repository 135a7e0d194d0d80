// Trajectory input for evaluation: TUM files and EuRoC ground truth
// (state_groundtruth_estimate0/data.csv or a dataset folder), detected by content.
// Deliberately minimal: only what hermes_eval needs (the full EuRoC dataset
// reader lives elsewhere).
#pragma once

#include <string>

#include "hermes/core/trajectory.h"

namespace hermes {
namespace eval {

enum class TrajectoryFormat { kTum, kEurocCsv };

/// EuRoC ground-truth csv: `ns, px, py, pz, qw, qx, qy, qz, ...` ('#' header).
/// Errors name path and line.
Expected<Trajectory> readEurocGroundTruthCsv(const std::string& path);

/// Resolves a dataset folder (containing mav0/, or mav0 itself) to its
/// state_groundtruth_estimate0/data.csv; a file path is returned unchanged.
Expected<std::string> resolveTrajectoryPath(const std::string& path);

/// EuRoC when the header names p_RS_R_x or the first stamp is an integer >= 1e12
/// (nanoseconds); TUM otherwise.
Expected<TrajectoryFormat> detectTrajectoryFormat(const std::string& file);

/// T_BS (body <- sensor) of a EuRoC sensor.yaml (`T_BS: {data: [16 numbers]}`;
/// OpenCV's `%YAML:1.0` line is accepted). Errors name the file and the problem.
Expected<SE3> readEurocSensorExtrinsic(const std::string& path);

/// resolve + detect + read. An ICL-NUIM `*.gt.freiburg` file is read as
/// readIclNuimGroundTruth() gives it (frame-index stamps at 30 Hz, y mirrored to the
/// images' convention); any other dataset folder (TUM, ICL-NUIM, KITTI sequences/NN)
/// yields the ground truth its dataset reader finds.
Expected<Trajectory> readTrajectoryForEval(const std::string& path);

}  // namespace eval
}  // namespace hermes
