#include "rendered_clip.h"

#include <unistd.h>

#include <filesystem>

#include <gtest/gtest.h>

#include "hermes/agent/dataset_feed.h"
#include "hermes/core/dataset.h"
#include "hermes/core/render/dataset_writer.h"
#include "hermes/core/render/rig.h"
#include "hermes/core/render/scene.h"

namespace hermes::test {

Expected<RenderedClip> renderV101Clip(const std::string& name, double start_s, double duration_s) {
  const std::string gt_path = std::string(HERMES_TRAJECTORY_DIR) + "/V1_01_easy.txt";
  auto gt = readTumTrajectory(gt_path);
  if (!gt.ok()) return Error{gt.error()};
  const PinholeRadtan cam0 = render::eurocCam0(), cam1 = render::eurocCam1();
  std::vector<Vec3> positions;
  render::appendRigPositions(*gt, {cam0.T_B_C, cam1.T_B_C}, &positions);
  render::SceneParams sp;
  sp.seed = 7;
  auto scene = render::buildScene(positions, sp);
  if (!scene.ok()) return Error{scene.error()};
  render::SequenceSpec spec;
  spec.start_s = start_s;
  spec.duration_s = duration_s;
  spec.rate_hz = 20;
  spec.seed = 7;
  const std::string dir = ::testing::TempDir() + "/" + name + "_" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  auto written = render::writeEurocSequence(dir, *scene, *gt, cam0, cam1, spec);
  if (!written.ok()) return Error{written.error()};
  auto dataset = Dataset::open(dir);
  if (!dataset.ok()) return Error{dataset.error()};
  const DatasetInfo& info = (*dataset)->info();
  RenderedClip clip;
  clip.camera = agent::AgentCamera{info.K, info.baseline, info.T_B_C};
  clip.groundtruth = info.groundtruth;
  for (std::size_t i = 0; i < (*dataset)->size(); ++i) {
    auto frame = loadCameraFrame(**dataset, i);
    if (!frame.ok()) return Error{frame.error()};
    clip.frames.push_back(std::move(*frame));
  }
  dataset->reset();
  std::filesystem::remove_all(dir);  // the clip lives in memory: leave no 30 MB behind per process
  return clip;
}

}  // namespace hermes::test
