// Inverted-index BoW database.
#include "hermes/server/bow_database.h"

#include <algorithm>
#include <string>

namespace hermes {

namespace {
std::string keyName(const KeyframeKey& k) {
  return "keyframe (agent " + std::to_string(k.agent) + ", session " + std::to_string(k.session) +
         ", id " + std::to_string(k.id) + ")";
}
}  // namespace

Status BowDatabase::add(const KeyframeKey& key, double stamp, BowVector bow) {
  for (const auto& [w, weight] : bow.entries) {
    if (w >= postings_.size())
      return Error{"bow database: " + keyName(key) + " has word " + std::to_string(w) +
                   " outside the vocabulary (" + std::to_string(postings_.size()) + " words)"};
    if (!(weight >= 0.f))
      return Error{"bow database: " + keyName(key) + " has a negative or NaN weight"};
  }
  std::sort(bow.entries.begin(), bow.entries.end());
  const double n = bow.l1Norm();
  if (n > 0)
    for (auto& e : bow.entries) e.second = static_cast<float>(e.second / n);
  remove(key);
  std::uint32_t slot;
  if (!free_slots_.empty()) {
    slot = free_slots_.back();
    free_slots_.pop_back();
    slots_[slot] = key;
  } else {
    slot = static_cast<std::uint32_t>(slots_.size());
    slots_.push_back(key);
  }
  slot_of_[key] = slot;
  for (const auto& [w, weight] : bow.entries)
    if (weight > 0.f) postings_[w].push_back({slot, weight});
  entries_[key] = BowEntry{key, stamp, std::move(bow)};
  return Status::Ok();
}

bool BowDatabase::remove(const KeyframeKey& key) {
  auto it = entries_.find(key);
  if (it == entries_.end()) return false;
  const std::uint32_t slot = slot_of_.at(key);
  for (const auto& [w, weight] : it->second.bow.entries) {
    auto& list = postings_[w];
    list.erase(std::remove_if(list.begin(), list.end(),
                              [slot](const Posting& p) { return p.slot == slot; }),
               list.end());
  }
  entries_.erase(it);
  slot_of_.erase(key);
  slots_[slot] = KeyframeKey{};
  free_slots_.push_back(slot);
  return true;
}

const BowEntry* BowDatabase::find(const KeyframeKey& key) const {
  auto it = entries_.find(key);
  return it == entries_.end() ? nullptr : &it->second;
}

std::vector<std::pair<KeyframeKey, double>> BowDatabase::score(
    const BowVector& query, const std::function<bool(const KeyframeKey&)>& accept) const {
  std::vector<std::pair<KeyframeKey, double>> out;
  BowVector merged;  // the min() identity needs one entry per word
  const bool strictly_sorted = std::adjacent_find(query.entries.begin(), query.entries.end(),
                                                  [](const auto& a, const auto& b) {
                                                    return a.first >= b.first;
                                                  }) == query.entries.end();
  if (!strictly_sorted) {
    std::map<WordId, float> sum;
    for (const auto& [w, v] : query.entries) sum[w] += v;
    merged.entries.assign(sum.begin(), sum.end());
  }
  const BowVector& q = strictly_sorted ? query : merged;
  const double n = q.l1Norm();
  if (n <= 0 || entries_.empty()) return out;
  // For L1-normalised q, v: 1 - 1/2 |q - v|_1 = sum_shared min(q_w, v_w).
  std::vector<double> acc(slots_.size(), 0.0);
  std::vector<std::uint8_t> touched(slots_.size(), 0);
  for (const auto& [w, qw_raw] : q.entries) {
    if (w >= postings_.size() || qw_raw <= 0.f) continue;
    const double qw = qw_raw / n;
    for (const Posting& p : postings_[w]) {
      acc[p.slot] += std::min(qw, static_cast<double>(p.weight));
      touched[p.slot] = 1;
    }
  }
  for (std::size_t s = 0; s < slots_.size(); ++s) {
    if (!touched[s]) continue;
    if (accept && !accept(slots_[s])) continue;
    out.emplace_back(slots_[s], std::min(1.0, acc[s]));
  }
  return out;
}

std::vector<KeyframeKey> BowDatabase::keysInSlotOrder() const {
  std::vector<KeyframeKey> out;
  for (const KeyframeKey& k : slots_)
    if (slot_of_.count(k)) out.push_back(k);
  return out;
}

}  // namespace hermes
