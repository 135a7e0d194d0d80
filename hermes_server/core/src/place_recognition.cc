// Place recognition: candidate selection, normalised scores, temporal islands.
#include "hermes/server/place_recognition.h"

#include <algorithm>
#include <cmath>

namespace hermes {

namespace {
std::uint64_t idDistance(KeyframeId a, KeyframeId b) { return a > b ? a - b : b - a; }
}  // namespace

Status PlaceRecognitionParams::read(const Config& c, const std::string& p) {
  for (auto s : {c.get(p + "vocabulary", &vocabulary_file),
                 c.get(p + "max_candidates", &max_candidates), c.get(p + "min_score", &min_score),
                 c.get(p + "min_normalized_score", &min_normalized_score),
                 c.get(p + "min_neighbour_score", &min_neighbour_score),
                 c.get(p + "neighbour_id_distance", &neighbour_id_distance),
                 c.get(p + "exclude_id_distance", &exclude_id_distance),
                 c.get(p + "exclude_time_s", &exclude_time_s),
                 c.get(p + "island_id_gap", &island_id_gap), c.get(p + "intra_agent", &intra_agent),
                 c.get(p + "inter_agent", &inter_agent)})
    if (!s) return s;
  return validate();
}

void PlaceRecognitionParams::write(ConfigWriter& w, const std::string& p) const {
  w.set(p + "vocabulary", vocabulary_file);
  w.set(p + "max_candidates", max_candidates);
  w.set(p + "min_score", min_score);
  w.set(p + "min_normalized_score", min_normalized_score);
  w.set(p + "min_neighbour_score", min_neighbour_score);
  w.set(p + "neighbour_id_distance", neighbour_id_distance);
  w.set(p + "exclude_id_distance", exclude_id_distance);
  w.set(p + "exclude_time_s", exclude_time_s);
  w.set(p + "island_id_gap", island_id_gap);
  w.set(p + "intra_agent", intra_agent);
  w.set(p + "inter_agent", inter_agent);
}

Expected<std::shared_ptr<const Vocabulary>> loadVocabulary(const PlaceRecognitionParams& params,
                                                           const std::string& base_dir) {
  std::string path = params.vocabulary_file;
  if (path.empty()) return Error{"server.place_recognition.vocabulary is empty"};
  if (path.front() != '/' && !base_dir.empty()) path = base_dir + "/" + path;
  auto voc = Vocabulary::load(path);
  if (!voc) return Error{voc.error()};
  return std::make_shared<const Vocabulary>(std::move(*voc));
}

Status PlaceRecognitionParams::validate() const {
  auto bad = [](const std::string& what) {
    return Status(Error{"server.place_recognition: " + what});
  };
  if (max_candidates < 1) return bad("max_candidates must be >= 1");
  if (!(min_score >= 0 && min_score <= 1)) return bad("min_score must be in [0, 1]");
  if (!(min_normalized_score >= 0)) return bad("min_normalized_score must be >= 0");
  if (!(min_neighbour_score >= 0 && min_neighbour_score <= 1))
    return bad("min_neighbour_score must be in [0, 1]");
  if (neighbour_id_distance < 0 || exclude_id_distance < 0 || island_id_gap < 0)
    return bad("id distances must be >= 0");
  if (!(exclude_time_s >= 0)) return bad("exclude_time_s must be >= 0");
  if (!intra_agent && !inter_agent) return bad("intra_agent and inter_agent are both off");
  return Status::Ok();
}

PlaceRecognizer::PlaceRecognizer(std::shared_ptr<const Vocabulary> vocabulary,
                                 PlaceRecognitionParams params)
    : vocabulary_(std::move(vocabulary)),
      params_(std::move(params)),
      db_(vocabulary_ ? vocabulary_->wordCount() : 0) {
  HERMES_CHECK(vocabulary_ && !vocabulary_->empty(), "PlaceRecognizer needs a vocabulary");
}

Status PlaceRecognizer::add(const KeyframeKey& key, double stamp,
                            const std::vector<Descriptor>& descriptors) {
  return db_.add(key, stamp, vocabulary_->transform(descriptors));
}

Status PlaceRecognizer::addBow(const KeyframeKey& key, double stamp, BowVector bow) {
  return db_.add(key, stamp, std::move(bow));
}

bool PlaceRecognizer::excluded(const KeyframeKey& key, double stamp,
                               const KeyframeKey& candidate) const {
  if (candidate == key) return true;
  const bool same_agent = candidate.agent == key.agent;
  if (same_agent && !params_.intra_agent) return true;
  if (!same_agent && !params_.inter_agent) return true;
  if (!same_agent || candidate.session != key.session) return false;
  if (idDistance(candidate.id, key.id) <= static_cast<std::uint64_t>(params_.exclude_id_distance))
    return true;
  const BowEntry* e = db_.find(candidate);
  return e && std::abs(e->stamp - stamp) < params_.exclude_time_s;
}

PlaceQueryResult PlaceRecognizer::query(const KeyframeKey& key, double stamp,
                                        const BowVector& bow) const {
  PlaceQueryResult result;
  auto all = db_.score(bow);
  result.scored = static_cast<int>(all.size());

  // Normaliser: best score against the query's own temporal neighbours.
  double neighbour = 0;
  for (const auto& [k, s] : all)
    if (k.agent == key.agent && k.session == key.session && !(k == key) &&
        idDistance(k.id, key.id) <= static_cast<std::uint64_t>(params_.neighbour_id_distance))
      neighbour = std::max(neighbour, s);
  if (neighbour < params_.min_neighbour_score) neighbour = 0;
  result.neighbour_score = neighbour;

  struct Scored {
    KeyframeKey key;
    double score, normalized;
  };
  std::vector<Scored> passing;
  for (const auto& [k, s] : all) {
    if (excluded(key, stamp, k)) {
      ++result.excluded;
      continue;
    }
    if (s < params_.min_score) continue;
    const double ns = neighbour > 0 ? s / neighbour : s;
    if (neighbour > 0 && ns < params_.min_normalized_score) continue;
    passing.push_back({k, s, ns});
  }
  std::sort(passing.begin(), passing.end(),
            [](const Scored& a, const Scored& b) { return a.key < b.key; });

  // Islands: runs of one agent/session with id steps <= island_id_gap.
  std::vector<PlaceCandidate> islands;
  for (std::size_t i = 0; i < passing.size();) {
    std::size_t j = i + 1;
    while (j < passing.size() && passing[j].key.agent == passing[i].key.agent &&
           passing[j].key.session == passing[i].key.session &&
           passing[j].key.id - passing[j - 1].key.id <=
               static_cast<std::uint64_t>(params_.island_id_gap))
      ++j;
    PlaceCandidate c;
    std::size_t best = i;
    for (std::size_t m = i; m < j; ++m) {
      c.island_score += passing[m].score;
      if (passing[m].score > passing[best].score) best = m;
    }
    c.key = passing[best].key;
    c.score = passing[best].score;
    c.normalized_score = passing[best].normalized;
    c.island_first = passing[i].key.id;
    c.island_last = passing[j - 1].key.id;
    c.island_size = static_cast<int>(j - i);
    islands.push_back(c);
    i = j;
  }
  std::sort(islands.begin(), islands.end(), [](const PlaceCandidate& a, const PlaceCandidate& b) {
    if (a.island_score != b.island_score) return a.island_score > b.island_score;
    return a.key < b.key;
  });
  if (islands.size() > static_cast<std::size_t>(params_.max_candidates))
    islands.resize(static_cast<std::size_t>(params_.max_candidates));
  result.candidates = std::move(islands);
  return result;
}

}  // namespace hermes
