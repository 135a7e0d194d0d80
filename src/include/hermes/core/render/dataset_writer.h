// Writes rendered sequences in the EuRoC ASL and TUM RGB-D folder layouts.
//
// EuRoC: DIR/mav0/cam{0,1}/data/<ns>.png, data.csv, sensor.yaml;
//        DIR/mav0/state_groundtruth_estimate0/data.csv (body pose, EuRoC columns);
//        DIR/mav0/body.yaml.
// TUM:   DIR/rgb/<t>.png (8-bit grey), DIR/depth/<t>.png (16-bit, z * depth_scale),
//        rgb.txt, depth.txt, groundtruth.txt (pose of the CAMERA frame, TUM format),
//        camera.yaml (fx fy cx cy width height depth_scale).
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "hermes/core/camera.h"
#include "hermes/core/render/scene.h"
#include "hermes/core/render/sensor.h"
#include "hermes/core/status.h"
#include "hermes/core/trajectory.h"

namespace hermes {
namespace render {

struct SequenceSpec {
  double start_s = 0;        ///< from the trajectory's first pose [s]
  double duration_s = -1;    ///< < 0: until the trajectory ends [s]
  double rate_hz = 20;       ///< frame rate [Hz]
  int png_compression = 1;   ///< cv::IMWRITE_PNG_COMPRESSION
  std::uint64_t seed = 1;    ///< sensor seed
  SensorParams sensor;
};

/// Frame times in ns (trajectory time base): first pose + start + k / rate.
std::vector<std::int64_t> frameTimesNs(const Trajectory& traj_W_B, const SequenceSpec& spec);

struct WriteStats {
  int frames = 0;
  double render_s = 0;  ///< time spent rendering + sensor model
  double write_s = 0;   ///< time spent encoding / writing files
};

/// Progress callback: (frames done, frames total, elapsed render + write time).
using Progress = std::function<void(int, int, double)>;

Expected<WriteStats> writeEurocSequence(const std::string& dir, const Scene& scene,
                                        const Trajectory& traj_W_B, const PinholeRadtan& cam0,
                                        const PinholeRadtan& cam1, const SequenceSpec& spec,
                                        const Progress& progress = nullptr);

Expected<WriteStats> writeTumSequence(const std::string& dir, const Scene& scene,
                                      const Trajectory& traj_W_B, const RgbdCamera& cam,
                                      const SequenceSpec& spec, const Progress& progress = nullptr);

/// sensor.yaml text for a camera, EuRoC format (first line "%YAML:1.0").
std::string eurocSensorYaml(const PinholeRadtan& cam, const std::string& comment);

}  // namespace render
}  // namespace hermes
