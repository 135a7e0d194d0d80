// Frames of a dataset folder as the agent's one door takes them.
#pragma once

#include <cstddef>

#include "hermes/agent/tracker.h"
#include "hermes/core/camera_calibration.h"
#include "hermes/core/dataset.h"

namespace hermes {

/// Frame i of `dataset` as a CameraFrame: stereo (left+right, rectified when the
/// dataset rectifies or comes rectified) for EuRoC and KITTI, grey + depth [m] for
/// TUM / ICL-NUIM. Errors name the image.
Expected<CameraFrame> loadCameraFrame(const Dataset& dataset, std::size_t i);

/// The calibration of the images loadCameraFrame() hands out (and the
/// DatasetPlayer publishes): EuRoC rectified by the dataset -> a rectified
/// pinhole pair (K, baseline, T_B_C of the rectified left camera); EuRoC not
/// rectified -> the raw rig; TUM -> the colour camera with its distortion.
/// format "dataset", source = the dataset folder.
CameraCalibration datasetCalibration(const Dataset& dataset);

}  // namespace hermes
