// Hierarchical k-medians training of the binary-descriptor vocabulary.
#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <set>

#include "hermes/server/vocabulary.h"

namespace hermes {

namespace {

/// Bitwise majority of a set of descriptors (ties -> 0).
Descriptor majority(const std::vector<Descriptor>& all, const std::vector<std::uint32_t>& members) {
  std::array<std::uint32_t, 256> ones{};
  for (std::uint32_t m : members) {
    const Descriptor& d = all[m];
    for (int byte = 0; byte < 32; ++byte) {
      std::uint8_t v = d[byte];
      if (!v) continue;
      for (int bit = 0; bit < 8; ++bit) ones[byte * 8 + bit] += (v >> bit) & 1u;
    }
  }
  Descriptor c{};
  const std::size_t n = members.size();
  for (int i = 0; i < 256; ++i)
    if (2 * static_cast<std::size_t>(ones[i]) > n) c[i / 8] |= static_cast<std::uint8_t>(1u << (i % 8));
  return c;
}

double uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

}  // namespace

/// Builds the tree depth-first; children of a node are allocated together so
/// they stay contiguous and after their parent.
class VocabularyTrainer {
 public:
  VocabularyTrainer(const std::vector<Descriptor>& all, const VocabularyParams& p,
                    Vocabulary* voc, const Vocabulary::Progress& progress)
      : all_(all), p_(p), voc_(voc), rng_(p.seed), progress_(progress) {}

  void build(std::uint32_t node, const std::vector<std::uint32_t>& members, int depth) {
    if (depth >= p_.levels || members.size() <= 1) return makeLeaf(node);
    std::vector<std::vector<std::uint32_t>> clusters = cluster(members);
    if (clusters.size() <= 1) return makeLeaf(node);
    const auto first = static_cast<std::uint32_t>(voc_->nodes_.size());
    voc_->nodes_[node].first_child = first;
    voc_->nodes_[node].child_count = static_cast<std::uint32_t>(clusters.size());
    for (const auto& c : clusters) {
      Vocabulary::Node child;
      child.centre = majority(all_, c);
      voc_->nodes_.push_back(child);
    }
    for (std::size_t i = 0; i < clusters.size(); ++i) {
      if (depth == 0 && progress_)
        progress_("vocabulary: branch " + std::to_string(i + 1) + "/" +
                  std::to_string(clusters.size()) + " (" + std::to_string(clusters[i].size()) +
                  " descriptors)");
      build(first + static_cast<std::uint32_t>(i), clusters[i], depth + 1);
    }
  }

 private:
  void makeLeaf(std::uint32_t node) {
    voc_->nodes_[node].word = static_cast<WordId>(voc_->words_.size());
    Vocabulary::Word w;
    w.node = node;
    voc_->words_.push_back(w);
  }

  /// k-medians with k-means++ seeding; returns the non-empty clusters.
  std::vector<std::vector<std::uint32_t>> cluster(const std::vector<std::uint32_t>& members) {
    const std::size_t n = members.size();
    const std::size_t k = static_cast<std::size_t>(p_.k);
    std::vector<Descriptor> centres;
    if (n <= k) {  // every distinct descriptor its own cluster
      std::set<Descriptor> distinct;
      for (auto m : members) distinct.insert(all_[m]);
      centres.assign(distinct.begin(), distinct.end());
    } else {
      // Greedy k-means++ seeding: draw a few candidates with probability ~ D^2 and
      // keep the one that lowers the total potential most.
      const int trials = 2 + static_cast<int>(std::log(static_cast<double>(k)));
      centres.push_back(all_[members[rng_() % n]]);
      std::vector<double> d2(n), cand_d2(n), best_d2(n);
      for (std::size_t i = 0; i < n; ++i) {
        const double d = hammingDistance(all_[members[i]], centres.back());
        d2[i] = d * d;
      }
      while (centres.size() < k) {
        double total = 0;
        for (double v : d2) total += v;
        if (total <= 0) break;  // all remaining descriptors coincide with a centre
        double best_potential = -1;
        std::size_t best_pick = 0;
        for (int t = 0; t < trials; ++t) {
          double r = uniform01(rng_) * total;
          std::size_t pick = n - 1;
          for (std::size_t i = 0; i < n; ++i) {
            r -= d2[i];
            if (r < 0 && d2[i] > 0) {
              pick = i;
              break;
            }
          }
          double potential = 0;
          for (std::size_t i = 0; i < n; ++i) {
            const double d = hammingDistance(all_[members[i]], all_[members[pick]]);
            cand_d2[i] = std::min(d2[i], d * d);
            potential += cand_d2[i];
          }
          if (best_potential < 0 || potential < best_potential) {
            best_potential = potential;
            best_pick = pick;
            best_d2.swap(cand_d2);
          }
        }
        centres.push_back(all_[members[best_pick]]);
        d2.swap(best_d2);
      }
    }
    std::vector<std::uint32_t> assign(n, 0xffffffffu);
    std::vector<std::vector<std::uint32_t>> clusters;
    for (int it = 0; it < std::max(1, p_.max_iterations); ++it) {
      bool changed = false;
      for (std::size_t i = 0; i < n; ++i) {
        int best = 257;
        std::uint32_t bi = 0;
        for (std::size_t c = 0; c < centres.size(); ++c) {
          const int d = hammingDistance(all_[members[i]], centres[c]);
          if (d < best) {
            best = d;
            bi = static_cast<std::uint32_t>(c);
          }
        }
        if (assign[i] != bi) changed = true;
        assign[i] = bi;
      }
      clusters.assign(centres.size(), {});
      for (std::size_t i = 0; i < n; ++i) clusters[assign[i]].push_back(members[i]);
      if (!changed && it > 0) break;
      // Update centres; drop empty clusters (re-index assignments).
      std::vector<Descriptor> next;
      std::vector<std::uint32_t> remap(centres.size(), 0xffffffffu);
      for (std::size_t c = 0; c < centres.size(); ++c) {
        if (clusters[c].empty()) continue;
        remap[c] = static_cast<std::uint32_t>(next.size());
        next.push_back(majority(all_, clusters[c]));
      }
      for (auto& a : assign) a = remap[a];
      centres.swap(next);
    }
    clusters.erase(std::remove_if(clusters.begin(), clusters.end(),
                                  [](const auto& c) { return c.empty(); }),
                   clusters.end());
    return clusters;
  }

  const std::vector<Descriptor>& all_;
  const VocabularyParams& p_;
  Vocabulary* voc_;
  std::mt19937_64 rng_;
  Vocabulary::Progress progress_;
};

Expected<Vocabulary> Vocabulary::train(const std::vector<std::vector<Descriptor>>& images,
                                       const VocabularyParams& params,
                                       const Progress& progress) {
  Status valid = params.validate();
  if (!valid) return Error{valid.error()};
  std::vector<Descriptor> all;
  for (const auto& im : images) all.insert(all.end(), im.begin(), im.end());
  int non_empty = 0;
  for (const auto& im : images) non_empty += im.empty() ? 0 : 1;
  if (all.empty() || non_empty == 0)
    return Error{"vocabulary training: no descriptors in " + std::to_string(images.size()) +
                 " images"};
  if (all.size() >= 0xffffffffu) return Error{"vocabulary training: too many descriptors"};
  Vocabulary voc;
  voc.k_ = params.k;
  voc.levels_ = params.levels;
  voc.training_images_ = non_empty;
  voc.nodes_.emplace_back();  // root
  std::vector<std::uint32_t> members(all.size());
  for (std::size_t i = 0; i < all.size(); ++i) members[i] = static_cast<std::uint32_t>(i);
  if (progress)
    progress("vocabulary: clustering " + std::to_string(all.size()) + " descriptors of " +
             std::to_string(non_empty) + " images, k=" + std::to_string(params.k) +
             " L=" + std::to_string(params.levels));
  VocabularyTrainer(all, params, &voc, progress).build(0, members, 0);

  // idf = log(N / n_i) with n_i = training images containing word i.
  std::vector<int> images_with(voc.words_.size(), 0);
  std::vector<int> last_image(voc.words_.size(), -1);
  for (std::size_t im = 0; im < images.size(); ++im) {
    for (const auto& d : images[im]) {
      const WordId w = voc.word(d);
      if (last_image[w] != static_cast<int>(im)) {
        last_image[w] = static_cast<int>(im);
        ++images_with[w];
      }
    }
  }
  for (std::size_t w = 0; w < voc.words_.size(); ++w)
    voc.words_[w].idf = static_cast<float>(
        std::log(static_cast<double>(non_empty) / std::max(1, images_with[w])));
  if (progress)
    progress("vocabulary: " + std::to_string(voc.words_.size()) + " words, " +
             std::to_string(voc.nodes_.size()) + " nodes");
  return voc;
}

}  // namespace hermes
