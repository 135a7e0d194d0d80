// Place recognition: bag-of-words retrieval of loop-closure candidates.
//
// Each keyframe's ORB descriptors become a tf-idf BoW vector (Vocabulary) kept
// in a BowDatabase. A query returns candidate keyframes ranked by L1 score:
//  * the query's own recent keyframes (same agent and session, within
//    exclude_id_distance ids or exclude_time_s seconds) are never candidates;
//  * intra-agent and inter-agent candidates can be switched separately;
//  * a candidate must reach min_score (absolute) and, when the query has
//    temporal neighbours in the database (same agent and session, within
//    neighbour_id_distance ids), score / best_neighbour_score >= min_normalized_score;
//  * passing candidates are grouped into islands (keyframes of one agent and
//    session whose ids are within island_id_gap), an island scores the sum of
//    its members, and the best keyframe of each of the top islands is returned.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/server/bow_database.h"
#include "hermes/server/vocabulary.h"

namespace hermes {

struct PlaceRecognitionParams {
  std::string vocabulary_file = "config/vocabulary/hermes_orb_k10L4.bin";
  int max_candidates = 3;              ///< top-N islands returned
  double min_score = 0.02;             ///< absolute L1 score floor
  double min_normalized_score = 0.3;   ///< score / best temporal-neighbour score
  double min_neighbour_score = 0.005;  ///< below this the normaliser is not trusted
  int neighbour_id_distance = 3;       ///< temporal neighbours for the normaliser [ids]
  int exclude_id_distance = 20;        ///< own keyframes this close are excluded [ids]
  double exclude_time_s = 10.0;        ///< own keyframes this recent are excluded [s]
  int island_id_gap = 5;               ///< max id step inside an island (trimming leaves gaps)
  bool intra_agent = true;             ///< candidates from the query's own agent
  bool inter_agent = true;             ///< candidates from other agents
  Status read(const Config& config, const std::string& prefix = "server.place_recognition.");
  void write(ConfigWriter& out, const std::string& prefix = "server.place_recognition.") const;
  Status validate() const;
};

/// Loads params.vocabulary_file; a relative path is taken relative to base_dir
/// (normally the repository root). Errors name the file.
Expected<std::shared_ptr<const Vocabulary>> loadVocabulary(const PlaceRecognitionParams& params,
                                                           const std::string& base_dir);

struct PlaceCandidate {
  KeyframeKey key;             ///< best keyframe of the island
  double score = 0;            ///< its L1 score
  double normalized_score = 0; ///< score / neighbour score (= score when no normaliser)
  double island_score = 0;     ///< sum of the island members' scores
  KeyframeId island_first = kInvalidId, island_last = kInvalidId;
  int island_size = 0;
};

struct PlaceQueryResult {
  std::vector<PlaceCandidate> candidates;  ///< best island first
  double neighbour_score = 0;              ///< normaliser used (0 = none)
  int scored = 0;                          ///< keyframes sharing a word with the query
  int excluded = 0;                        ///< dropped as own recent / disabled scope
};

/// Not thread-safe: the server pipeline owns it and calls it from one thread.
class PlaceRecognizer {
 public:
  PlaceRecognizer(std::shared_ptr<const Vocabulary> vocabulary, PlaceRecognitionParams params);

  const Vocabulary& vocabulary() const { return *vocabulary_; }
  const BowDatabase& database() const { return db_; }
  const PlaceRecognitionParams& params() const { return params_; }

  BowVector bow(const std::vector<Descriptor>& descriptors) const {
    return vocabulary_->transform(descriptors);
  }
  /// Adds a keyframe (its descriptors are turned into a BoW vector).
  Status add(const KeyframeKey& key, double stamp, const std::vector<Descriptor>& descriptors);
  Status addBow(const KeyframeKey& key, double stamp, BowVector bow);
  bool remove(const KeyframeKey& key) { return db_.remove(key); }

  /// Candidates for a keyframe (which may or may not already be in the database).
  PlaceQueryResult query(const KeyframeKey& key, double stamp, const BowVector& bow) const;
  PlaceQueryResult query(const KeyframeKey& key, double stamp,
                         const std::vector<Descriptor>& descriptors) const {
    return query(key, stamp, bow(descriptors));
  }

  /// True if `candidate` is excluded for a query from `key` at `stamp`.
  bool excluded(const KeyframeKey& key, double stamp, const KeyframeKey& candidate) const;

 private:
  std::shared_ptr<const Vocabulary> vocabulary_;
  PlaceRecognitionParams params_;
  BowDatabase db_;
};

}  // namespace hermes
