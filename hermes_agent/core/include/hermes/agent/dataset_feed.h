// Frames of a dataset folder as the agent's one door takes them.
#pragma once

#include <cstddef>

#include "hermes/agent/tracker.h"
#include "hermes/core/dataset.h"

namespace hermes {

/// Frame i of `dataset` as a CameraFrame: stereo (left+right, rectified when the
/// dataset rectifies) for EuRoC, grey + depth [m] for TUM. Errors name the frame.
Expected<CameraFrame> loadCameraFrame(const Dataset& dataset, std::size_t i);

}  // namespace hermes
