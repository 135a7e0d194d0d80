// Vocabulary file IO, descriptor -> word and image -> tf-idf BoW vector.
#include "hermes/server/vocabulary.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>

#include <opencv2/core.hpp>

namespace hermes {

namespace {

constexpr char kMagic[8] = {'H', 'R', 'M', 'S', 'V', 'O', 'C', '\0'};
constexpr std::uint32_t kVersion = 1;
constexpr std::size_t kHeaderBytes = 8 + 6 * 4;
constexpr std::size_t kNodeBytes = 32 + 3 * 4;
constexpr std::size_t kWordBytes = 2 * 4;

std::uint32_t vocabCrc32(const std::uint8_t* data, std::size_t size) {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int b = 0; b < 8; ++b) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  std::uint32_t c = 0xffffffffu;
  for (std::size_t i = 0; i < size; ++i) c = table[(c ^ data[i]) & 0xffu] ^ (c >> 8);
  return c ^ 0xffffffffu;
}

void putU32(std::vector<std::uint8_t>* out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out->push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
std::uint32_t getU32(const std::uint8_t* p) {
  return std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 |
         std::uint32_t{p[3]} << 24;
}

}  // namespace

double BowVector::l1Norm() const {
  double n = 0;
  for (const auto& e : entries) n += std::abs(e.second);
  return n;
}

double bowScore(const BowVector& a, const BowVector& b) {
  const double na = a.l1Norm(), nb = b.l1Norm();
  if (na <= 0 || nb <= 0) return 0.0;
  double diff = 0;  // | a/|a| - b/|b| |_1 over the union of words
  std::size_t i = 0, j = 0;
  while (i < a.entries.size() || j < b.entries.size()) {
    if (j == b.entries.size() ||
        (i < a.entries.size() && a.entries[i].first < b.entries[j].first)) {
      diff += a.entries[i++].second / na;
    } else if (i == a.entries.size() || b.entries[j].first < a.entries[i].first) {
      diff += b.entries[j++].second / nb;
    } else {
      diff += std::abs(a.entries[i++].second / na - b.entries[j++].second / nb);
    }
  }
  return std::clamp(1.0 - 0.5 * diff, 0.0, 1.0);
}

Status VocabularyParams::read(const Config& config, const std::string& prefix) {
  int seed_int = static_cast<int>(seed);
  for (auto s : {config.get(prefix + "k", &k), config.get(prefix + "levels", &levels),
                 config.get(prefix + "max_iterations", &max_iterations),
                 config.get(prefix + "seed", &seed_int)})
    if (!s) return s;
  seed = static_cast<std::uint64_t>(seed_int);
  return validate();
}

void VocabularyParams::write(ConfigWriter& w, const std::string& p) const {
  w.set(p + "k", k);
  w.set(p + "levels", levels);
  w.set(p + "max_iterations", max_iterations);
  w.set(p + "seed", static_cast<int>(seed));
}

Status VocabularyParams::validate() const {
  if (k < 2 || k > 64) return Error{"vocabulary: k=" + std::to_string(k) + " must be in [2, 64]"};
  if (levels < 1 || levels > 8)
    return Error{"vocabulary: levels=" + std::to_string(levels) + " must be in [1, 8]"};
  if (std::pow(static_cast<double>(k), levels) > 5e7)
    return Error{"vocabulary: k^levels = " + std::to_string(std::pow(double(k), levels)) +
                 " words is too large (max 5e7)"};
  if (max_iterations < 1)
    return Error{"vocabulary: max_iterations=" + std::to_string(max_iterations) + " must be >= 1"};
  return Status::Ok();
}

WordId Vocabulary::word(const Descriptor& d) const {
  HERMES_CHECK(!nodes_.empty(), "word() on an empty vocabulary");
  std::uint32_t node = 0;
  while (nodes_[node].word == kInvalidWord) {
    const Node& n = nodes_[node];
    std::uint32_t best = n.first_child;
    int best_d = 257;
    for (std::uint32_t c = n.first_child; c < n.first_child + n.child_count; ++c) {
      const int dist = hammingDistance(d, nodes_[c].centre);
      if (dist < best_d) {
        best_d = dist;
        best = c;
      }
    }
    node = best;
  }
  return nodes_[node].word;
}

BowVector Vocabulary::transform(const std::vector<Descriptor>& descriptors,
                                std::vector<WordId>* words_out) const {
  BowVector v;
  if (words_out) words_out->clear();
  if (descriptors.empty() || nodes_.empty()) return v;
  std::map<WordId, float> counts;
  for (const auto& d : descriptors) {
    const WordId w = word(d);
    if (words_out) words_out->push_back(w);
    counts[w] += 1.f;
  }
  const float inv_n = 1.f / static_cast<float>(descriptors.size());
  double sum = 0;
  for (const auto& [w, c] : counts) {
    const float weight = c * inv_n * words_[w].idf;  // tf * idf
    if (weight <= 0.f) continue;  // words in every training image carry no information
    v.entries.emplace_back(w, weight);
    sum += weight;
  }
  if (sum > 0)
    for (auto& e : v.entries) e.second = static_cast<float>(e.second / sum);
  return v;
}

bool Vocabulary::operator==(const Vocabulary& o) const {
  if (k_ != o.k_ || levels_ != o.levels_ || training_images_ != o.training_images_ ||
      nodes_.size() != o.nodes_.size() || words_.size() != o.words_.size())
    return false;
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const Node &a = nodes_[i], &b = o.nodes_[i];
    if (a.centre != b.centre || a.first_child != b.first_child ||
        a.child_count != b.child_count || a.word != b.word)
      return false;
  }
  for (std::size_t i = 0; i < words_.size(); ++i)
    if (words_[i].idf != o.words_[i].idf || words_[i].node != o.words_[i].node) return false;
  return true;
}

std::vector<std::uint8_t> Vocabulary::toBytes() const {
  std::vector<std::uint8_t> out(8);
  std::memcpy(out.data(), kMagic, 8);
  out.reserve(kHeaderBytes + nodes_.size() * kNodeBytes + words_.size() * kWordBytes + 4);
  putU32(&out, kVersion);
  putU32(&out, static_cast<std::uint32_t>(k_));
  putU32(&out, static_cast<std::uint32_t>(levels_));
  putU32(&out, static_cast<std::uint32_t>(nodes_.size()));
  putU32(&out, static_cast<std::uint32_t>(words_.size()));
  putU32(&out, static_cast<std::uint32_t>(training_images_));
  for (const Node& n : nodes_) {
    out.insert(out.end(), n.centre.begin(), n.centre.end());
    putU32(&out, n.first_child);
    putU32(&out, n.child_count);
    putU32(&out, n.word);
  }
  for (const Word& w : words_) {
    std::uint32_t bits;
    std::memcpy(&bits, &w.idf, 4);
    putU32(&out, bits);
    putU32(&out, w.node);
  }
  putU32(&out, vocabCrc32(out.data(), out.size()));
  return out;
}

Status Vocabulary::save(const std::string& path) const {
  if (nodes_.empty()) return Error{"vocabulary " + path + ": refusing to save an empty vocabulary"};
  const std::vector<std::uint8_t> bytes = toBytes();
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) return Error{"vocabulary " + path + ": cannot open for writing"};
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  f.close();
  if (!f) return Error{"vocabulary " + path + ": write failed"};
  return Status::Ok();
}

Expected<Vocabulary> Vocabulary::load(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return Error{"vocabulary " + path + ": cannot open file"};
  f.seekg(0, std::ios::end);
  const std::streamoff size = f.tellg();
  if (size < 0) return Error{"vocabulary " + path + ": cannot read file size"};
  f.seekg(0, std::ios::beg);
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(size));
  if (size > 0) f.read(reinterpret_cast<char*>(bytes.data()), size);
  if (!f) return Error{"vocabulary " + path + ": read failed"};
  return fromBytes(bytes, path);
}

Expected<Vocabulary> Vocabulary::fromBytes(const std::vector<std::uint8_t>& bytes,
                                           const std::string& origin) {
  auto fail = [&](const std::string& what) {
    return Error{"vocabulary " + origin + ": " + what};
  };
  if (bytes.size() < kHeaderBytes + 4)
    return fail("file too short (" + std::to_string(bytes.size()) + " bytes)");
  if (std::memcmp(bytes.data(), kMagic, 8) != 0) return fail("bad magic (not a Hermes vocabulary)");
  const std::uint8_t* p = bytes.data() + 8;
  const std::uint32_t version = getU32(p);
  if (version != kVersion)
    return fail("unsupported version " + std::to_string(version) + " (expected " +
                std::to_string(kVersion) + ")");
  const std::uint32_t k = getU32(p + 4), levels = getU32(p + 8), node_count = getU32(p + 12),
                      word_count = getU32(p + 16), images = getU32(p + 20);
  const std::uint64_t expected = kHeaderBytes + std::uint64_t{node_count} * kNodeBytes +
                                 std::uint64_t{word_count} * kWordBytes + 4;
  if (bytes.size() != expected)
    return fail("size " + std::to_string(bytes.size()) + " bytes does not match header (" +
                std::to_string(expected) + " bytes expected for " + std::to_string(node_count) +
                " nodes, " + std::to_string(word_count) + " words)");
  const std::uint32_t stored_crc = getU32(bytes.data() + bytes.size() - 4);
  const std::uint32_t crc = vocabCrc32(bytes.data(), bytes.size() - 4);
  if (stored_crc != crc) return fail("CRC mismatch (file corrupt or truncated)");
  if (k < 2 || levels < 1 || node_count < 1 || word_count < 1 || word_count > node_count)
    return fail("inconsistent header (k=" + std::to_string(k) + ", levels=" +
                std::to_string(levels) + ", nodes=" + std::to_string(node_count) +
                ", words=" + std::to_string(word_count) + ")");
  Vocabulary v;
  v.k_ = static_cast<int>(k);
  v.levels_ = static_cast<int>(levels);
  v.training_images_ = static_cast<int>(images);
  v.nodes_.resize(node_count);
  v.words_.resize(word_count);
  p = bytes.data() + kHeaderBytes;
  for (std::uint32_t i = 0; i < node_count; ++i, p += kNodeBytes) {
    Node& n = v.nodes_[i];
    std::memcpy(n.centre.data(), p, 32);
    n.first_child = getU32(p + 32);
    n.child_count = getU32(p + 36);
    n.word = getU32(p + 40);
    const bool leaf = n.word != kInvalidWord;
    if (leaf ? (n.word >= word_count || n.child_count != 0)
             : (n.child_count == 0 || n.child_count > k || n.first_child <= i ||
                std::uint64_t{n.first_child} + n.child_count > node_count))
      return fail("node " + std::to_string(i) + " is malformed");
  }
  for (std::uint32_t i = 0; i < word_count; ++i, p += kWordBytes) {
    const std::uint32_t bits = getU32(p);
    std::memcpy(&v.words_[i].idf, &bits, 4);
    v.words_[i].node = getU32(p + 4);
    if (v.words_[i].node >= node_count || v.nodes_[v.words_[i].node].word != i ||
        !std::isfinite(v.words_[i].idf) || v.words_[i].idf < 0.f)
      return fail("word " + std::to_string(i) + " is malformed");
  }
  // Every node except the root must be the child of exactly one inner node,
  // so that descending from the root always reaches a leaf (no cycles: first_child > parent).
  std::vector<std::uint32_t> parents(node_count, 0);
  for (const Node& n : v.nodes_)
    if (n.word == kInvalidWord)
      for (std::uint32_t c = n.first_child; c < n.first_child + n.child_count; ++c) ++parents[c];
  for (std::uint32_t i = 1; i < node_count; ++i)
    if (parents[i] != 1) return fail("node " + std::to_string(i) + " has " +
                                     std::to_string(parents[i]) + " parents");
  return v;
}

std::vector<Descriptor> descriptorsFromMat(const cv::Mat& m) {
  std::vector<Descriptor> out;
  if (m.empty() || m.type() != CV_8U || m.cols != 32) return out;
  out.resize(static_cast<std::size_t>(m.rows));
  for (int r = 0; r < m.rows; ++r) std::memcpy(out[r].data(), m.ptr<std::uint8_t>(r), 32);
  return out;
}

}  // namespace hermes
