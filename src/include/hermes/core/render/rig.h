// Built-in camera rigs of the synthetic renderer: the real EuRoC VI-Sensor
// stereo calibration (cam0/cam1 of every EuRoC sequence) and a TUM-like RGB-D
// camera mounted where EuRoC's cam0 is.
#pragma once

#include "hermes/core/camera.h"

namespace hermes {
namespace render {

PinholeRadtan eurocCam0();
PinholeRadtan eurocCam1();
/// TUM-like RGB-D: 640x480, f = 525, 30 Hz, depth scale 5000, T_B_C = EuRoC cam0.
RgbdCamera defaultRgbd();

/// Same camera at another resolution (intrinsics scaled, pixel-centre convention).
PinholeIntrinsics scaleIntrinsics(const PinholeIntrinsics& K, int width, int height);

}  // namespace render
}  // namespace hermes
