// BoW place recognition on rendered revisits: the keyframes two robots make in
// the same rendered hall (real front end, shipped vocabulary). For every
// keyframe of robot B that truly sees a place robot A mapped, the best
// candidate from A's keyframes must be that place.
#include <gtest/gtest.h>

#include "hermes/agent/agent_pipeline.h"
#include "hermes/agent/dataset_feed.h"
#include "hermes/core/evaluation.h"
#include "hermes/server/place_recognition.h"
#include "support/rendered_hall.h"

using namespace hermes;

namespace {

struct Mapped {
  std::vector<Keyframe> keyframes;
  std::vector<SE3> T_W_C_gt;  ///< ground-truth camera pose per keyframe
};

Mapped mapSequence(const std::string& dir, const std::string& name) {
  Mapped m;
  auto ds = Dataset::open(dir, DatasetParams{});
  EXPECT_TRUE(ds.ok()) << ds.error();
  if (!ds.ok()) return m;
  const DatasetInfo& info = (*ds)->info();
  agent::AgentPipelineParams p;
  auto pipeline = agent::AgentPipeline::create(p, name, {info.K, info.baseline, info.T_B_C});
  EXPECT_TRUE(pipeline.ok()) << pipeline.error();
  if (!pipeline.ok()) return m;
  for (std::size_t i = 0; i < info.frame_count; ++i) {
    auto f = loadCameraFrame(**ds, i);
    EXPECT_TRUE(f.ok()) << f.error();
    if (!f.ok() || !(*pipeline)->feed(*f).ok()) return m;
  }
  for (const Keyframe& kf : (*pipeline)->tracker().keyframes()) {
    SE3 T_W_B;
    if (!interpolatePose(info.groundtruth, kf.stamp, &T_W_B)) continue;
    m.keyframes.push_back(kf);
    m.T_W_C_gt.push_back(T_W_B * info.T_B_C);
  }
  return m;
}

}  // namespace

TEST(PlaceRecognitionRendered, RevisitsAcrossRobotsFindTheRightPlace) {
  const std::string hall = test_support::renderedHall();
  ASSERT_FALSE(hall.empty()) << "rendering failed";
  const Mapped a = mapSequence(hall + "/MH_01_easy", "a");
  const Mapped b = mapSequence(hall + "/MH_02_easy", "b");
  ASSERT_GT(a.keyframes.size(), 5u);
  ASSERT_GT(b.keyframes.size(), 5u);
  PlaceRecognitionParams pp;
  auto vocabulary = loadVocabulary(pp, HERMES_SOURCE_DIR);
  ASSERT_TRUE(vocabulary.ok()) << vocabulary.error();
  PlaceRecognizer recognizer(*vocabulary, pp);
  for (const Keyframe& kf : a.keyframes)
    ASSERT_TRUE(recognizer.add(KeyframeKey{0, 1, kf.id}, kf.stamp, kf.descriptors));
  int revisits = 0, right = 0, answered = 0;
  for (std::size_t i = 0; i < b.keyframes.size(); ++i) {
    // Ground truth: the closest of A's keyframes by viewpoint.
    const SE3& q = b.T_W_C_gt[i];
    double best_d = 1e9;
    for (const SE3& t : a.T_W_C_gt) {
      const double d = (t.translation() - q.translation()).norm() +
                       eval::relativeAngle(t.quat(), q.quat());  // [m] + [rad]
      best_d = std::min(best_d, d);
    }
    const bool revisit = best_d < 0.6;
    const PlaceQueryResult r = recognizer.query(KeyframeKey{1, 1, b.keyframes[i].id},
                                                b.keyframes[i].stamp, b.keyframes[i].descriptors);
    if (!revisit || r.candidates.empty()) {
      revisits += revisit;
      continue;
    }
    ++revisits;
    ++answered;
    const KeyframeKey& c = r.candidates.front().key;
    for (std::size_t j = 0; j < a.keyframes.size(); ++j)
      if (a.keyframes[j].id == c.id) {
        const SE3& t = a.T_W_C_gt[j];
        const double d = (t.translation() - q.translation()).norm() +
                         eval::relativeAngle(t.quat(), q.quat());
        right += d < 1.2;  // a view of the same place (allowing a neighbouring keyframe)
      }
  }
  std::printf("revisits %d, answered %d, right place %d\n", revisits, answered, right);
  ASSERT_GT(revisits, 3);
  EXPECT_GE(answered, revisits / 2);            // most revisits are recognised
  EXPECT_GE(right * 10, answered * 9);          // >= 90 % of the answers are the right place
}
