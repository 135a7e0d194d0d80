#include <algorithm>

#include "hermes/server/pcm.h"

namespace hermes {
namespace server {

int PcmCache::verdict(const Group& group, std::uint64_t i, std::uint64_t j) const {
  auto t = tables_.find(group);
  if (t == tables_.end()) return -1;
  auto ri = t->second.index.find(i), rj = t->second.index.find(j);
  if (ri == t->second.index.end() || rj == t->second.index.end() || ri->second == rj->second)
    return -1;
  const int hi = std::max(ri->second, rj->second), lo = std::min(ri->second, rj->second);
  return t->second.rows[hi][lo];
}

int PcmCache::row(Table* t, std::uint64_t id) {
  auto [it, added] = t->index.emplace(id, static_cast<int>(t->rows.size()));
  if (added) t->rows.emplace_back(t->rows.size(), static_cast<signed char>(-1));
  return it->second;
}

void PcmCache::store(const Group& group, std::uint64_t i, std::uint64_t j, bool consistent) {
  Table& t = tables_[group];
  const int ri = row(&t, i), rj = row(&t, j);
  if (ri == rj) return;
  t.rows[std::max(ri, rj)][std::min(ri, rj)] = consistent ? 1 : 0;
}

void PcmCache::forget(std::uint64_t loop) {
  for (auto& [group, t] : tables_) {
    auto it = t.index.find(loop);
    if (it == t.index.end()) continue;
    const int r = it->second;
    std::fill(t.rows[r].begin(), t.rows[r].end(), static_cast<signed char>(-1));
    for (std::size_t k = r + 1; k < t.rows.size(); ++k) t.rows[k][r] = -1;
  }
}

void PcmCache::clear() { tables_.clear(); }

std::size_t PcmCache::bytes() const {
  std::size_t b = 0;
  for (const auto& [group, t] : tables_) {
    b += t.index.size() * (sizeof(std::uint64_t) + sizeof(int) + 32);
    for (const auto& r : t.rows) b += r.capacity() + sizeof(r);
  }
  return b;
}

}  // namespace server
}  // namespace hermes
