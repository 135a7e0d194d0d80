// Bag-of-words vocabulary over binary 256-bit ORB descriptors.
//
// A tree built by hierarchical k-medians (Hamming distance, cluster centre =
// bitwise majority, k-means++-style seeding, deterministic for a seed) with
// branching factor k and depth L; its leaves are the words, each weighted by
// idf = log(N / n_i) over the N training images (n_i = images containing the
// word). An image becomes a sparse tf-idf vector, L1-normalised.
//
// File format (little-endian, all fields fixed width):
//   "HRMSVOC\0" (8 bytes) | u32 version (=1) | u32 k | u32 levels | u32 node_count
//   | u32 word_count | u32 training_images | node_count x {u8 centre[32],
//   u32 first_child, u32 child_count, u32 word (0xffffffff = inner node)}
//   | word_count x {f32 idf, u32 node} | u32 CRC-32 (IEEE) of all preceding bytes.
// Node 0 is the root (its centre is unused); children of a node are contiguous
// and have larger indices than their parent.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace cv {
class Mat;
}

namespace hermes {

using WordId = std::uint32_t;
constexpr WordId kInvalidWord = 0xffffffffu;

/// Sparse bag-of-words vector: (word, weight) sorted by word, weights >= 0.
struct BowVector {
  std::vector<std::pair<WordId, float>> entries;
  bool empty() const { return entries.empty(); }
  double l1Norm() const;
};

/// L1 similarity in [0, 1]: 1 - 1/2 * | a/|a|_1 - b/|b|_1 |_1 (0 if either is empty).
double bowScore(const BowVector& a, const BowVector& b);

struct VocabularyParams {
  int k = 10;               ///< branching factor
  int levels = 4;           ///< tree depth (leaves at most at this depth)
  int max_iterations = 10;  ///< k-medians iterations per node
  std::uint64_t seed = 1;   ///< seeding RNG
  Status read(const Config& config, const std::string& prefix = "vocabulary.");
  void write(ConfigWriter& out, const std::string& prefix = "vocabulary.") const;
  Status validate() const;
};

class Vocabulary {
 public:
  using Progress = std::function<void(const std::string&)>;

  /// Trains on the descriptors of a set of images (one vector per image).
  static Expected<Vocabulary> train(const std::vector<std::vector<Descriptor>>& images,
                                    const VocabularyParams& params,
                                    const Progress& progress = nullptr);
  /// Loads the binary format above; errors name the file and the problem.
  static Expected<Vocabulary> load(const std::string& path);
  static Expected<Vocabulary> fromBytes(const std::vector<std::uint8_t>& bytes,
                                        const std::string& origin);
  Status save(const std::string& path) const;
  std::vector<std::uint8_t> toBytes() const;

  /// Word of one descriptor (descends the tree to a leaf).
  WordId word(const Descriptor& d) const;
  /// tf-idf vector of an image, L1-normalised. If words_out is given it gets
  /// the word of each descriptor.
  BowVector transform(const std::vector<Descriptor>& descriptors,
                      std::vector<WordId>* words_out = nullptr) const;

  std::size_t wordCount() const { return words_.size(); }
  std::size_t nodeCount() const { return nodes_.size(); }
  int branching() const { return k_; }
  int levels() const { return levels_; }
  int trainingImages() const { return training_images_; }
  float idf(WordId w) const { return words_[w].idf; }
  bool empty() const { return nodes_.empty(); }
  bool operator==(const Vocabulary& o) const;

  struct Node {
    Descriptor centre{};
    std::uint32_t first_child = 0;
    std::uint32_t child_count = 0;
    WordId word = kInvalidWord;
  };
  struct Word {
    float idf = 0.f;
    std::uint32_t node = 0;
  };

 private:
  int k_ = 0;
  int levels_ = 0;
  int training_images_ = 0;
  std::vector<Node> nodes_;
  std::vector<Word> words_;
  friend class VocabularyTrainer;
};

/// Rows of a CV_8U Nx32 descriptor matrix (as cv::ORB returns) as Descriptors.
std::vector<Descriptor> descriptorsFromMat(const cv::Mat& m);

}  // namespace hermes
