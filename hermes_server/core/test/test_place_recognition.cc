#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <set>
#include <random>
#include <regex>

#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hermes/server/place_recognition.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const char* kPhotoDir = "/usr/share/doc/opencv-doc/examples/data";

std::shared_ptr<const Vocabulary> shippedVocabulary() {
  static std::shared_ptr<const Vocabulary> voc = [] {
    auto v = Vocabulary::load(std::string(HERMES_SOURCE_DIR) +
                              "/config/vocabulary/hermes_orb_k10L4.bin");
    return v.ok() ? std::make_shared<const Vocabulary>(std::move(*v)) : nullptr;
  }();
  return voc;
}

/// Distinct scenes: the stereo-calibration chessboard series (left01..right14)
/// and the second image of each stereo / sequence pair show the same scene as
/// another photo, so they are left out (a "wrong" match there would be right).
bool distinctScene(const std::string& name) {
  static const std::regex calib("(left|right)[0-9][0-9]\\..*");
  if (std::regex_match(name, calib)) return false;
  static const std::set<std::string> seconds = {
      "aloeR.jpg",        "right.jpg",          "basketball2.png", "rubberwhale2.png",
      "graf3.png",        "leuvenB.jpg",        "aero3.jpg",       "Blender_Suzanne2.jpg",
      "box_in_scene.png", "ela_modified.jpg",   "aloeGT.png",      "opencv-logo-white.png",
      "imageTextR.png",   "WindowsLogo.jpg"};
  return !seconds.count(name);
}

cv::Mat loadGray(const fs::path& p) {
  cv::Mat img = cv::imread(p.string(), cv::IMREAD_GRAYSCALE);
  if (img.empty()) return img;
  const double scale = 640.0 / std::max(img.cols, img.rows);
  if (scale < 1.0) cv::resize(img, img, cv::Size(), scale, scale, cv::INTER_AREA);
  return img;
}

/// A revisit: random homography (corners moved by up to 20 % of the size,
/// plus a rotation of up to 25 deg), brightness/contrast change and noise.
cv::Mat revisit(const cv::Mat& img, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const float w = static_cast<float>(img.cols), h = static_cast<float>(img.rows);
  std::vector<cv::Point2f> src = {{0, 0}, {w, 0}, {w, h}, {0, h}}, dst;
  const double angle = u(rng) * 25.0 * CV_PI / 180.0;
  const cv::Point2f c(w / 2, h / 2);
  for (const auto& p : src) {
    const cv::Point2f d = p - c;
    cv::Point2f r(static_cast<float>(std::cos(angle) * d.x - std::sin(angle) * d.y),
                  static_cast<float>(std::sin(angle) * d.x + std::cos(angle) * d.y));
    dst.push_back(c + r +
                  cv::Point2f(static_cast<float>(u(rng) * 0.2 * w), static_cast<float>(u(rng) * 0.2 * h)));
  }
  cv::Mat H = cv::getPerspectiveTransform(src, dst), warped;
  cv::warpPerspective(img, warped, H, img.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  cv::Mat f;
  warped.convertTo(f, CV_32F, 1.0 + 0.3 * u(rng), 25.0 * u(rng));
  cv::Mat noise(f.size(), CV_32F);
  cv::randn(noise, 0.0, 4.0);
  f += noise;
  cv::Mat out;
  f.convertTo(out, CV_8U);  // saturates
  return out;
}

std::vector<Descriptor> orb(const cv::Mat& img) {
  static cv::Ptr<cv::ORB> detector = cv::ORB::create(1000);
  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
  detector->detectAndCompute(img, cv::noArray(), kps, desc);
  return descriptorsFromMat(desc);
}

BowVector bowOf(std::initializer_list<std::pair<WordId, float>> e) {
  BowVector v;
  v.entries.assign(e.begin(), e.end());
  return v;
}

struct RecallResult {
  std::size_t places = 0;
  int top1 = 0, top5 = 0;
  double ms_per_query = 0;
};

/// Adds the distinct-scene photos selected by `use` as agent 0's keyframes,
/// then queries a warped revisit of each as agent 1.
RecallResult measureRecall(std::shared_ptr<const Vocabulary> voc,
                           const std::function<bool(std::size_t)>& use) {
  RecallResult res;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(kPhotoDir)) {
    const std::string ext = e.path().extension().string();
    if ((ext == ".jpg" || ext == ".png") && distinctScene(e.path().filename().string()))
      files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  PlaceRecognitionParams params;
  params.max_candidates = 5;
  PlaceRecognizer pr(voc, params);
  std::mt19937_64 rng(42);
  cv::setRNGSeed(42);
  std::vector<cv::Mat> places;
  std::vector<std::string> names;
  for (std::size_t fi = 0; fi < files.size(); ++fi) {
    if (!use(fi)) continue;
    cv::Mat img = loadGray(files[fi]);
    if (img.empty()) continue;
    auto d = orb(img);
    if (d.size() < 150) continue;  // too little texture to be a place (logos, blank shapes)
    const KeyframeKey key{0, 0, places.size() * 100};
    EXPECT_TRUE(pr.add(key, static_cast<double>(places.size()) * 100.0, d).ok());
    places.push_back(img);
    names.push_back(files[fi].filename().string());
  }
  res.places = places.size();
  const auto t0 = std::chrono::steady_clock::now();
  for (std::size_t i = 0; i < places.size(); ++i) {
    const BowVector q = pr.bow(orb(revisit(places[i], rng)));
    // A revisit by another agent (inter-agent query).
    PlaceQueryResult r = pr.query(KeyframeKey{1, 0, i}, 1000.0 + i, q);
    const KeyframeKey truth{0, 0, i * 100};
    if (!r.candidates.empty() && r.candidates[0].key == truth) {
      ++res.top1;
    } else {
      std::printf("  miss: %s -> %s (score %.3f)\n", names[i].c_str(),
                  r.candidates.empty() ? "none" : names[r.candidates[0].key.id / 100].c_str(),
                  r.candidates.empty() ? 0.0 : r.candidates[0].score);
    }
    for (const auto& c : r.candidates) res.top5 += c.key == truth ? 1 : 0;
    // The inverted-index score equals the explicit L1 score.
    if (!r.candidates.empty()) {
      const BowEntry* e = pr.database().find(r.candidates[0].key);
      EXPECT_NE(e, nullptr);
      if (e) {
        EXPECT_NEAR(r.candidates[0].score, bowScore(q, e->bow), 1e-5);
      }
    }
  }
  res.ms_per_query = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() /
                     std::max<std::size_t>(1, places.size());
  return res;
}

}  // namespace

TEST(PlaceRecognition, WarpedRevisitsOfRealPhotosRankTheRightPlaceFirst) {
  auto voc = shippedVocabulary();
  ASSERT_TRUE(voc) << "shipped vocabulary missing";
  if (!fs::is_directory(kPhotoDir)) GTEST_SKIP() << kPhotoDir << " not installed (opencv-doc)";
  RecallResult r = measureRecall(voc, [](std::size_t) { return true; });
  ASSERT_GE(r.places, 40u);
  const double recall1 = static_cast<double>(r.top1) / r.places;
  std::printf("place recognition (shipped vocabulary): %zu places, recall@1 %d/%zu = %.3f, "
              "recall@5 %.3f, %.1f ms per revisit (ORB + BoW + query)\n",
              r.places, r.top1, r.places, recall1, static_cast<double>(r.top5) / r.places,
              r.ms_per_query);
  RecordProperty("recall_at_1", std::to_string(recall1));
  EXPECT_GE(recall1, 0.9);
}

TEST(PlaceRecognition, HeldOutVocabularyStillRecognisesPlaces) {
  // The shipped vocabulary saw these photos in training; here a vocabulary is
  // trained on the odd-numbered files only and queried with the even-numbered ones.
  if (!fs::is_directory(kPhotoDir)) GTEST_SKIP() << kPhotoDir << " not installed (opencv-doc)";
  std::vector<fs::path> all;
  for (const auto& e : fs::directory_iterator(kPhotoDir)) {
    const std::string ext = e.path().extension().string();
    if (ext == ".jpg" || ext == ".png") all.push_back(e.path());
  }
  std::sort(all.begin(), all.end());
  std::vector<fs::path> distinct;
  for (const auto& p : all)
    if (distinctScene(p.filename().string())) distinct.push_back(p);
  std::set<std::string> test_names;
  for (std::size_t i = 0; i < distinct.size(); i += 2) test_names.insert(distinct[i].filename().string());
  std::vector<std::vector<Descriptor>> training;
  for (const auto& p : all) {
    if (test_names.count(p.filename().string())) continue;
    // Same-scene partners of test photos are left out of training as well.
    const std::string n = p.filename().string();
    if (!distinctScene(n) && !std::regex_match(n, std::regex("(left|right)[0-9][0-9]\\..*"))) continue;
    cv::Mat img = loadGray(p);
    if (!img.empty()) training.push_back(orb(img));
  }
  VocabularyParams vp;
  vp.k = 10;
  vp.levels = 3;
  auto voc = Vocabulary::train(training, vp);
  ASSERT_TRUE(voc.ok()) << voc.error();
  auto shared = std::make_shared<const Vocabulary>(std::move(*voc));
  RecallResult r = measureRecall(shared, [](std::size_t i) { return i % 2 == 0; });
  ASSERT_GE(r.places, 15u);
  const double recall1 = static_cast<double>(r.top1) / r.places;
  std::printf("place recognition (held-out vocabulary, %zu training images, %zu words): "
              "recall@1 %d/%zu = %.3f, recall@5 %.3f\n",
              training.size(), shared->wordCount(), r.top1, r.places, recall1,
              static_cast<double>(r.top5) / r.places);
  EXPECT_GE(recall1, 0.85);
}

TEST(PlaceRecognition, OwnRecentKeyframesAreExcluded) {
  auto voc = shippedVocabulary();
  ASSERT_TRUE(voc);
  PlaceRecognitionParams params;
  params.exclude_id_distance = 5;
  params.exclude_time_s = 10;
  params.min_score = 0.0;
  params.min_normalized_score = 0.0;
  params.max_candidates = 50;
  params.island_id_gap = 0;  // every keyframe its own island here
  PlaceRecognizer pr(voc, params);
  const BowVector same = bowOf({{1, 1.f}, {2, 1.f}, {3, 1.f}});
  // Agent 0 session 0: ids 0..9 at 1 s spacing, then id 40 at t = 100 s.
  for (KeyframeId id = 0; id < 10; ++id) ASSERT_TRUE(pr.addBow({0, 0, id}, double(id), same).ok());
  ASSERT_TRUE(pr.addBow({0, 0, 40}, 100.0, same).ok());
  ASSERT_TRUE(pr.addBow({0, 1, 9}, 9.0, same).ok());  // new session, reused id
  ASSERT_TRUE(pr.addBow({1, 0, 9}, 9.0, same).ok());  // another agent

  // Query from (0, 0, 10) at t = 10 s: ids 5..9 are within 5 ids, 1..9 within 10 s.
  PlaceQueryResult r = pr.query(KeyframeKey{0, 0, 10}, 10.0, same);
  std::set<KeyframeKey> got;
  for (const auto& c : r.candidates) got.insert(c.key);
  const std::set<KeyframeKey> expected = {{0, 0, 0}, {0, 0, 40}, {0, 1, 9}, {1, 0, 9}};
  EXPECT_EQ(got, expected);

  // Inter-agent only.
  params.intra_agent = false;
  PlaceRecognizer inter(voc, params);
  for (const auto& [k, e] : pr.database().entries()) ASSERT_TRUE(inter.addBow(k, e.stamp, e.bow).ok());
  r = inter.query(KeyframeKey{0, 0, 10}, 10.0, same);
  ASSERT_EQ(r.candidates.size(), 1u);
  EXPECT_EQ(r.candidates[0].key, (KeyframeKey{1, 0, 9}));

  // A keyframe is never its own candidate even when it is in the database.
  params.intra_agent = true;
  params.exclude_id_distance = 0;
  params.exclude_time_s = 0;
  PlaceRecognizer self(voc, params);
  ASSERT_TRUE(self.addBow({2, 0, 1}, 0.0, same).ok());
  EXPECT_TRUE(self.query(KeyframeKey{2, 0, 1}, 0.0, same).candidates.empty());
}

TEST(PlaceRecognition, NormalisedScoreAndIslands) {
  auto voc = shippedVocabulary();
  ASSERT_TRUE(voc);
  PlaceRecognitionParams params;
  params.min_score = 0.05;
  params.min_normalized_score = 0.5;
  params.neighbour_id_distance = 2;
  params.exclude_id_distance = 2;
  params.exclude_time_s = 0;
  params.island_id_gap = 3;
  params.max_candidates = 5;
  PlaceRecognizer pr(voc, params);
  // Query: words 0..9 equally. Neighbour (0,0,99) shares words 0..5 -> score 0.6.
  BowVector q;
  for (WordId w = 0; w < 10; ++w) q.entries.emplace_back(w, 0.1f);
  auto share = [](WordId first, WordId n) {
    BowVector v;
    for (WordId w = first; w < first + n; ++w) v.entries.emplace_back(w, 1.f);
    return v;
  };
  ASSERT_TRUE(pr.addBow({0, 0, 99}, 0, share(0, 6)).ok());
  // Agent 1: an island 10, 12, 14 each sharing 4 words (0.4 -> normalised 0.67),
  // a lone keyframe 50 sharing 5 words (0.5 -> 0.83), keyframe 80 sharing 2 (0.2 -> 0.33, rejected).
  ASSERT_TRUE(pr.addBow({1, 0, 10}, 0, share(0, 4)).ok());
  ASSERT_TRUE(pr.addBow({1, 0, 12}, 0, share(2, 4)).ok());
  ASSERT_TRUE(pr.addBow({1, 0, 14}, 0, share(4, 4)).ok());
  ASSERT_TRUE(pr.addBow({1, 0, 50}, 0, share(5, 5)).ok());
  ASSERT_TRUE(pr.addBow({1, 0, 80}, 0, share(8, 2)).ok());
  PlaceQueryResult r = pr.query(KeyframeKey{0, 0, 100}, 0, q);
  EXPECT_NEAR(r.neighbour_score, 0.6, 1e-5);
  ASSERT_EQ(r.candidates.size(), 2u);
  EXPECT_EQ(r.candidates[0].island_first, 10u);
  EXPECT_EQ(r.candidates[0].island_last, 14u);
  EXPECT_EQ(r.candidates[0].island_size, 3);
  EXPECT_NEAR(r.candidates[0].island_score, 1.2, 1e-5);
  EXPECT_NEAR(r.candidates[0].score, 0.4, 1e-5);
  EXPECT_EQ(r.candidates[1].key, (KeyframeKey{1, 0, 50}));
  EXPECT_NEAR(r.candidates[1].normalized_score, 0.5 / 0.6, 1e-5);

  // Without a neighbour only the absolute floor applies: keyframe 80 (0.2) passes.
  r = pr.query(KeyframeKey{3, 0, 0}, 0, q);
  EXPECT_EQ(r.neighbour_score, 0.0);
  bool has80 = false;
  for (const auto& c : r.candidates) has80 |= c.key == KeyframeKey{1, 0, 80};
  EXPECT_TRUE(has80);
}

TEST(PlaceRecognition, BadInputIsAnError) {
  auto voc = shippedVocabulary();
  ASSERT_TRUE(voc);
  PlaceRecognizer pr(voc, PlaceRecognitionParams{});
  Status s = pr.addBow({4, 2, 7}, 0, bowOf({{static_cast<WordId>(voc->wordCount() + 5), 1.f}}));
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("agent 4"), std::string::npos) << s.error();
  EXPECT_FALSE(pr.database().contains({4, 2, 7}));
  PlaceRecognitionParams bad;
  bad.intra_agent = bad.inter_agent = false;
  EXPECT_FALSE(bad.validate().ok());
  auto cfg = Config::fromString("server:\n  place_recognition:\n    min_score: 2.0\n", "pr.yaml");
  ASSERT_TRUE(cfg.ok());
  PlaceRecognitionParams p;
  EXPECT_FALSE(p.read(*cfg).ok());
}

TEST(PlaceRecognition, ParamsRoundTripAndVocabularyLoading) {
  PlaceRecognitionParams p;
  p.max_candidates = 7;
  p.min_score = 0.125;
  p.intra_agent = false;
  ConfigWriter w;
  p.write(w);
  auto cfg = Config::fromString(w.yaml(), "written.yaml");
  ASSERT_TRUE(cfg.ok()) << cfg.error();
  PlaceRecognitionParams q;
  ASSERT_TRUE(q.read(*cfg).ok());
  EXPECT_EQ(q.max_candidates, 7);
  EXPECT_DOUBLE_EQ(q.min_score, 0.125);
  EXPECT_FALSE(q.intra_agent);
  EXPECT_EQ(q.vocabulary_file, p.vocabulary_file);
  auto voc = loadVocabulary(q, HERMES_SOURCE_DIR);
  ASSERT_TRUE(voc.ok()) << voc.error();
  EXPECT_GT((*voc)->wordCount(), 5000u);
  q.vocabulary_file = "config/vocabulary/missing.bin";
  auto missing = loadVocabulary(q, HERMES_SOURCE_DIR);
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("missing.bin"), std::string::npos);
}

TEST(PlaceRecognition, QueryTimeWithThousandsOfKeyframes) {
  auto voc = shippedVocabulary();
  ASSERT_TRUE(voc);
  PlaceRecognitionParams params;
  PlaceRecognizer pr(voc, params);
  // Realistic word statistics: descriptors of the real photos, 300 per keyframe,
  // drawn at random, for 3000 keyframes of 3 agents.
  std::vector<Descriptor> pool;
  for (const char* name : {"building.jpg", "home.jpg", "graf1.png", "leuvenA.jpg", "fruits.jpg"}) {
    cv::Mat img = loadGray(fs::path(kPhotoDir) / name);
    if (img.empty()) GTEST_SKIP() << "opencv-doc photos not installed";
    auto d = orb(img);
    pool.insert(pool.end(), d.begin(), d.end());
  }
  std::mt19937_64 rng(3);
  auto sample = [&] {
    std::vector<Descriptor> d(300);
    for (auto& x : d) x = pool[rng() % pool.size()];
    return d;
  };
  const auto t0 = std::chrono::steady_clock::now();
  for (std::uint32_t i = 0; i < 3000; ++i)
    ASSERT_TRUE(pr.add(KeyframeKey{i % 3, 0, i / 3}, i * 0.1, sample()).ok());
  const auto t1 = std::chrono::steady_clock::now();
  double worst = 0;
  for (int q = 0; q < 20; ++q) {
    const BowVector v = pr.bow(sample());
    const auto a = std::chrono::steady_clock::now();
    PlaceQueryResult r = pr.query(KeyframeKey{0, 0, 5000}, 1000.0, v);
    worst = std::max(worst, std::chrono::duration<double, std::milli>(
                                std::chrono::steady_clock::now() - a).count());
    EXPECT_EQ(r.scored, 3000);  // every keyframe shares words with a sample of the same pool
  }
  const double add_ms = std::chrono::duration<double, std::milli>(t1 - t0).count() / 3000;
  std::printf("database of 3000 keyframes: %.3f ms per add (BoW transform + insert), "
              "worst query %.2f ms\n", add_ms, worst);
  EXPECT_LT(worst, 100.0);
}
