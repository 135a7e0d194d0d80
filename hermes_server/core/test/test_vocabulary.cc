#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>

#include "hermes/server/vocabulary.h"

using namespace hermes;

namespace {

Descriptor randomDescriptor(std::mt19937_64& rng) {
  Descriptor d;
  for (auto& b : d) b = static_cast<std::uint8_t>(rng());
  return d;
}

Descriptor flipBits(Descriptor d, int bits, std::mt19937_64& rng) {
  std::set<int> flipped;
  while (static_cast<int>(flipped.size()) < bits) flipped.insert(static_cast<int>(rng() % 256));
  for (int b : flipped) d[b / 8] ^= static_cast<std::uint8_t>(1u << (b % 8));
  return d;
}

/// 10 well separated clusters (centres ~128 bits apart, members <= 8 bits from
/// their centre); image i holds cluster 0 always and cluster c only if i % (c+1) == 0.
struct Synthetic {
  std::vector<Descriptor> centres;
  std::vector<std::vector<Descriptor>> images;
  std::vector<std::vector<int>> labels;
};

Synthetic makeSynthetic(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  Synthetic s;
  for (int c = 0; c < 10; ++c) s.centres.push_back(randomDescriptor(rng));
  for (int i = 0; i < 20; ++i) {
    s.images.emplace_back();
    s.labels.emplace_back();
    for (int c = 0; c < 10; ++c) {
      if (i % (c + 1) != 0) continue;
      for (int m = 0; m < 15; ++m) {
        s.images.back().push_back(flipBits(s.centres[c], 1 + static_cast<int>(rng() % 8), rng));
        s.labels.back().push_back(c);
      }
    }
  }
  return s;
}

std::string tempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("hermes_test_vocab_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

}  // namespace

TEST(Vocabulary, SyntheticClustersMapToOneWordEach) {
  for (std::uint64_t seed = 1; seed <= 10; ++seed) {
    Synthetic s = makeSynthetic(100 + seed);
    VocabularyParams p;
    p.k = 10;
    p.levels = 1;
    p.seed = seed;
    auto voc = Vocabulary::train(s.images, p);
    ASSERT_TRUE(voc.ok()) << voc.error();
    EXPECT_EQ(voc->wordCount(), 10u);
    std::map<int, WordId> word_of_cluster;
    for (std::size_t i = 0; i < s.images.size(); ++i)
      for (std::size_t j = 0; j < s.images[i].size(); ++j) {
        const WordId w = voc->word(s.images[i][j]);
        auto [it, inserted] = word_of_cluster.emplace(s.labels[i][j], w);
        EXPECT_EQ(it->second, w) << "seed " << seed << " cluster " << s.labels[i][j];
      }
    std::set<WordId> distinct;
    for (auto& [c, w] : word_of_cluster) distinct.insert(w);
    EXPECT_EQ(distinct.size(), 10u) << "seed " << seed << ": clusters share words";
    // Unseen descriptors near a centre land in that centre's word.
    std::mt19937_64 rng(seed);
    for (int c = 0; c < 10; ++c)
      EXPECT_EQ(voc->word(flipBits(s.centres[c], 6, rng)), word_of_cluster[c]);
    // idf = log(N / n_i): cluster 0 is in all 20 images, cluster 3 in images 0,4,8,12,16.
    EXPECT_FLOAT_EQ(voc->idf(word_of_cluster[0]), 0.f);
    EXPECT_NEAR(voc->idf(word_of_cluster[3]), std::log(20.0 / 5.0), 1e-6);
  }
}

TEST(Vocabulary, DeeperTreeIsDeterministicAndTransformIsNormalised) {
  Synthetic s = makeSynthetic(7);
  VocabularyParams p;
  p.k = 4;
  p.levels = 3;
  p.seed = 5;
  auto a = Vocabulary::train(s.images, p);
  auto b = Vocabulary::train(s.images, p);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_TRUE(*a == *b);
  EXPECT_GE(a->wordCount(), 10u);
  EXPECT_LE(a->wordCount(), 64u);
  BowVector v = a->transform(s.images[3]);
  ASSERT_FALSE(v.empty());
  EXPECT_NEAR(v.l1Norm(), 1.0, 1e-5);
  for (std::size_t i = 1; i < v.entries.size(); ++i)
    EXPECT_LT(v.entries[i - 1].first, v.entries[i].first);
  EXPECT_NEAR(bowScore(v, v), 1.0, 1e-6);
  EXPECT_NEAR(bowScore(v, a->transform(s.images[5])), bowScore(a->transform(s.images[5]), v), 1e-9);
}

TEST(Vocabulary, BowScoreMatchesDefinition) {
  BowVector a, b;
  a.entries = {{1, 0.5f}, {2, 0.5f}};
  b.entries = {{2, 2.f}, {3, 2.f}};  // not normalised: the score normalises
  // |a - b/4|_1 = 0.5 + 0 + 0.5 = 1 -> 1 - 0.5 = 0.5
  EXPECT_NEAR(bowScore(a, b), 0.5, 1e-9);
  BowVector c;
  c.entries = {{7, 1.f}};
  EXPECT_NEAR(bowScore(a, c), 0.0, 1e-9);
  EXPECT_EQ(bowScore(a, BowVector{}), 0.0);
}

TEST(Vocabulary, SaveLoadRoundTripIsIdentical) {
  Synthetic s = makeSynthetic(11);
  VocabularyParams p;
  p.k = 5;
  p.levels = 2;
  auto voc = Vocabulary::train(s.images, p);
  ASSERT_TRUE(voc.ok());
  const std::string path = tempPath("roundtrip.bin");
  ASSERT_TRUE(voc->save(path).ok());
  auto back = Vocabulary::load(path);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_TRUE(*back == *voc);
  for (const auto& im : s.images)
    for (const auto& d : im) EXPECT_EQ(back->word(d), voc->word(d));
  std::remove(path.c_str());
}

TEST(Vocabulary, CorruptFilesAreRejectedWithTheFileName) {
  Synthetic s = makeSynthetic(13);
  VocabularyParams p;
  p.k = 5;
  p.levels = 2;
  auto voc = Vocabulary::train(s.images, p);
  ASSERT_TRUE(voc.ok());
  std::vector<std::uint8_t> bytes = voc->toBytes();

  auto flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x10;
  auto r1 = Vocabulary::fromBytes(flipped, "flip.bin");
  ASSERT_FALSE(r1.ok());
  EXPECT_NE(r1.error().find("flip.bin"), std::string::npos);
  EXPECT_NE(r1.error().find("CRC"), std::string::npos) << r1.error();

  auto truncated = bytes;
  truncated.resize(bytes.size() - 9);
  auto r2 = Vocabulary::fromBytes(truncated, "short.bin");
  ASSERT_FALSE(r2.ok());
  EXPECT_NE(r2.error().find("short.bin"), std::string::npos);

  auto magic = bytes;
  magic[0] = 'X';
  auto r3 = Vocabulary::fromBytes(magic, "magic.bin");
  ASSERT_FALSE(r3.ok());
  EXPECT_NE(r3.error().find("magic"), std::string::npos);

  const std::string path = tempPath("corrupt.bin");
  {
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(flipped.data()), static_cast<std::streamsize>(flipped.size()));
  }
  auto r4 = Vocabulary::load(path);
  ASSERT_FALSE(r4.ok());
  EXPECT_NE(r4.error().find(path), std::string::npos) << r4.error();
  std::remove(path.c_str());

  auto r5 = Vocabulary::load("/nonexistent/dir/voc.bin");
  ASSERT_FALSE(r5.ok());
  EXPECT_NE(r5.error().find("/nonexistent/dir/voc.bin"), std::string::npos);
}

TEST(Vocabulary, RejectsBadParamsAndEmptyTraining) {
  VocabularyParams p;
  p.k = 1;
  EXPECT_FALSE(p.validate().ok());
  p = VocabularyParams{};
  EXPECT_FALSE(Vocabulary::train({}, p).ok());
  EXPECT_FALSE(Vocabulary::train({{}, {}}, p).ok());
}

TEST(Vocabulary, ShippedVocabularyLoadsFast) {
  const std::string path = std::string(HERMES_SOURCE_DIR) + "/config/vocabulary/hermes_orb_k10L4.bin";
  const auto t0 = std::chrono::steady_clock::now();
  auto voc = Vocabulary::load(path);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(voc.ok()) << voc.error();
  std::printf("shipped vocabulary: %zu words, %zu nodes, k=%d L=%d, %d training images, "
              "loaded in %.2f ms\n",
              voc->wordCount(), voc->nodeCount(), voc->branching(), voc->levels(),
              voc->trainingImages(), ms);
  RecordProperty("load_ms", std::to_string(ms));
  EXPECT_EQ(voc->branching(), 10);
  EXPECT_EQ(voc->levels(), 4);
  EXPECT_GT(voc->wordCount(), 5000u);
  EXPECT_LT(ms, 100.0);
}
