// Inverted index of keyframe bag-of-words vectors (word -> (keyframe, weight)).
// Scores are the L1 similarity of bowScore(): for L1-normalised vectors
//   1 - 1/2 |q - v|_1 = sum over shared words of min(q_w, v_w),
// so only the posting lists of the query's words are visited.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <utility>
#include <vector>

#include "hermes/core/map_types.h"
#include "hermes/server/vocabulary.h"

namespace hermes {

struct BowEntry {
  KeyframeKey key;
  double stamp = 0;  ///< keyframe time [s]
  BowVector bow;     ///< L1-normalised
};

class BowDatabase {
 public:
  /// word_count: size of the vocabulary the vectors come from.
  explicit BowDatabase(std::size_t word_count = 0) : postings_(word_count) {}

  /// Adds (or replaces) a keyframe. The vector is L1-normalised on insertion.
  /// Returns an error if a word id is outside the vocabulary.
  Status add(const KeyframeKey& key, double stamp, BowVector bow);
  bool remove(const KeyframeKey& key);
  bool contains(const KeyframeKey& key) const { return entries_.count(key) != 0; }
  const BowEntry* find(const KeyframeKey& key) const;
  std::size_t size() const { return entries_.size(); }
  std::size_t wordCount() const { return postings_.size(); }

  /// L1 scores of every stored keyframe sharing at least one word with `query`
  /// (normalised internally) that passes `accept` (nullptr = all).
  std::vector<std::pair<KeyframeKey, double>> score(
      const BowVector& query, const std::function<bool(const KeyframeKey&)>& accept = nullptr) const;

  /// The stored keys in insertion-slot order (the order score() reports them in):
  /// adding them again in this order reproduces the database's answers.
  std::vector<KeyframeKey> keysInSlotOrder() const;

  /// All entries, ordered by key (agent, session, id).
  const std::map<KeyframeKey, BowEntry>& entries() const { return entries_; }

 private:
  struct Posting {
    std::uint32_t slot;  ///< index into slots_
    float weight;
  };
  std::vector<std::vector<Posting>> postings_;
  std::map<KeyframeKey, BowEntry> entries_;
  std::map<KeyframeKey, std::uint32_t> slot_of_;
  std::vector<KeyframeKey> slots_;          ///< slot -> key (free slots hold kInvalidId)
  std::vector<std::uint32_t> free_slots_;
};

}  // namespace hermes
