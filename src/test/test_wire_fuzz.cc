// Deterministic mutation fuzzer for the wire decoder, run as a bounded gtest.
// Valid frames are mutated (bit flips, byte sets, truncation, insertion,
// deletion, duplication, splicing two frames); most mutants then get their
// length fields and CRC recomputed (compressed bodies are mutated before
// recompression) so that the body decoder itself is exercised, not only the
// CRC check. Every outcome must be a clean "wire: " error or a submap that
// passes validate() and survives a re-encode/decode round trip.
//
// Default budget ≈5 s and 400k iterations; HERMES_FUZZ_SECONDS=N runs N seconds
// without an iteration cap, HERMES_FUZZ_SEED=N changes the seed.
#include <gtest/gtest.h>
#include <zstd.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <map>
#include <random>
#include <string>

#include "hermes/core/crc32.h"
#include "hermes/core/frame_auth.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"

using namespace hermes;

namespace {

using Frame = std::vector<std::uint8_t>;

struct Corpus {
  std::vector<Frame> raw_bodies;  // uncompressed bodies of the seed frames
  std::vector<SubmapHeader> routing;
};

void putLE(Frame* f, std::size_t at, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) (*f)[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

/// A frame around `body` with correct lengths and CRC (header layout per wire_format.h),
/// taking the routing bytes from `like`.
Frame seal(const Frame& like, const Frame& body, bool compress, std::mt19937_64& rng) {
  Frame f(like.begin(), like.begin() + kWireFixedBytes);
  std::uint32_t raw = static_cast<std::uint32_t>(body.size());
  if (compress) {
    Frame packed(ZSTD_compressBound(body.size()));
    packed.resize(ZSTD_compress(packed.data(), packed.size(), body.data(), body.size(), 1));
    f.insert(f.end(), packed.begin(), packed.end());
  } else {
    f.insert(f.end(), body.begin(), body.end());
  }
  putLE(&f, 6, compress ? kWireFlagZstd : 0, 2);
  putLE(&f, 8, f.size() - kWireFixedBytes, 4);
  putLE(&f, 12, raw, 4);
  if (rng() % 50 == 0) putLE(&f, 12, rng() % (2 * raw + 2), 4);  // lying raw length
  std::uint32_t c = crc32(f.data(), kWireCrcOffset);
  c = crc32(f.data() + kWireCrcOffset + 4, f.size() - kWireCrcOffset - 4, c);
  putLE(&f, kWireCrcOffset, c, 4);
  return f;
}

std::uint8_t interestingByte(std::mt19937_64& rng) {
  static const std::uint8_t kValues[] = {0x00, 0x01, 0x02, 0x7f, 0x80, 0x81, 0xfe, 0xff, 0x40};
  return rng() % 2 ? kValues[rng() % sizeof(kValues)] : static_cast<std::uint8_t>(rng());
}

/// One to four random edits of `b` (positions from `from` on).
void mutate(Frame* b, std::size_t from, const Frame& other, std::mt19937_64& rng) {
  const int edits = 1 + static_cast<int>(rng() % 4);
  for (int e = 0; e < edits; ++e) {
    const std::size_t n = b->size();
    const std::size_t span = n > from ? n - from : 0;
    const std::size_t at = from + (span ? rng() % span : 0);
    switch (rng() % 9) {
      case 0:
      case 1:  // bit flip
        if (span) (*b)[at] ^= static_cast<std::uint8_t>(1u << (rng() % 8));
        break;
      case 2:  // byte set
        if (span) (*b)[at] = interestingByte(rng);
        break;
      case 3:  // truncate
        if (span) b->resize(at);
        break;
      case 4: {  // insert random bytes
        const std::size_t k = 1 + rng() % 8;
        for (std::size_t i = 0; i < k; ++i) b->insert(b->begin() + std::min(at, b->size()), interestingByte(rng));
        break;
      }
      case 5: {  // delete a range
        if (!span) break;
        const std::size_t k = std::min<std::size_t>(1 + rng() % 16, n - at);
        b->erase(b->begin() + at, b->begin() + at + k);
        break;
      }
      case 6: {  // duplicate a range
        if (!span) break;
        const std::size_t k = std::min<std::size_t>(1 + rng() % 64, n - at);
        Frame chunk(b->begin() + at, b->begin() + at + k);
        b->insert(b->begin() + at, chunk.begin(), chunk.end());
        break;
      }
      case 7: {  // splice: our prefix + the other's suffix
        if (other.size() <= from) break;
        const std::size_t cut = from + rng() % (other.size() - from);
        b->resize(std::min(at, b->size()));
        b->insert(b->end(), other.begin() + cut, other.end());
        break;
      }
      case 8:  // a huge little-endian varint
        if (span) {
          static const std::uint8_t kHuge[] = {0xff, 0xff, 0xff, 0xff, 0x0f};
          for (std::size_t i = 0; i < 5 && at + i < b->size(); ++i) (*b)[at + i] = kHuge[i];
        }
        break;
    }
  }
}

/// Error class for the summary: the message with numbers replaced by N and
/// without its body offset.
std::string category(const std::string& msg) {
  std::string out;
  for (std::size_t i = 0; i < msg.size() && out.size() < 72; ++i) {
    if (msg.compare(i, 13, " (body offset") == 0) break;
    if (std::isdigit(static_cast<unsigned char>(msg[i]))) {
      out += 'N';
      const bool hex = msg.compare(i, 2, "0x") == 0;
      if (hex) ++i;
      while (i + 1 < msg.size() && (hex ? std::isxdigit(static_cast<unsigned char>(msg[i + 1]))
                                        : std::isdigit(static_cast<unsigned char>(msg[i + 1]))))
        ++i;
    } else {
      out += msg[i];
    }
  }
  return out;
}

bool samePose(const SE3& a, const SE3& b) {
  return (a.matrix() - b.matrix()).cwiseAbs().maxCoeff() < 1e-12;
}

bool sameSubmap(const Submap& a, const Submap& b) {
  if (a.header.seq != b.header.seq || a.header.agent != b.header.agent ||
      a.cameras.size() != b.cameras.size() || a.keyframes.size() != b.keyframes.size() ||
      a.landmarks.size() != b.landmarks.size() || a.odometry.size() != b.odometry.size())
    return false;
  for (std::size_t i = 0; i < a.keyframes.size(); ++i) {
    const Keyframe& x = a.keyframes[i];
    const Keyframe& y = b.keyframes[i];
    if (x.id != y.id || x.stamp != y.stamp || x.camera_id != y.camera_id ||
        !samePose(x.T_A_C, y.T_A_C) || x.descriptors != y.descriptors ||
        x.keypoint_landmark != y.keypoint_landmark || x.keypoints.size() != y.keypoints.size())
      return false;
    for (std::size_t k = 0; k < x.keypoints.size(); ++k)
      if (std::memcmp(&x.keypoints[k].u, &y.keypoints[k].u, 4) ||
          std::memcmp(&x.keypoints[k].v, &y.keypoints[k].v, 4) ||
          std::memcmp(&x.keypoints[k].depth, &y.keypoints[k].depth, 4) ||
          x.keypoints[k].octave != y.keypoints[k].octave)
        return false;
  }
  for (std::size_t j = 0; j < a.landmarks.size(); ++j) {
    const Landmark& x = a.landmarks[j];
    const Landmark& y = b.landmarks[j];
    if (x.id != y.id || x.p_A != y.p_A || x.descriptor != y.descriptor ||
        x.observations.size() != y.observations.size())
      return false;
    for (std::size_t o = 0; o < x.observations.size(); ++o)
      if (x.observations[o].keyframe != y.observations[o].keyframe ||
          x.observations[o].keypoint != y.observations[o].keypoint)
        return false;
  }
  for (std::size_t i = 0; i < a.odometry.size(); ++i)
    if (a.odometry[i].from != b.odometry[i].from || a.odometry[i].to != b.odometry[i].to ||
        !samePose(a.odometry[i].T_from_to, b.odometry[i].T_from_to) ||
        a.odometry[i].information != b.odometry[i].information)
      return false;
  return true;
}

}  // namespace

TEST(WireFuzz, MutatedFramesFailCleanlyOrDecodeValid) {
  double seconds = 5.0;
  std::uint64_t max_iterations = 400000;
  if (const char* env = std::getenv("HERMES_FUZZ_SECONDS")) {
    seconds = std::atof(env);
    max_iterations = ~std::uint64_t{0};
  }
  std::uint64_t seed = 20240601;
  if (const char* env = std::getenv("HERMES_FUZZ_SEED")) seed = std::strtoull(env, nullptr, 10);
  std::mt19937_64 rng(seed);

  // Seed corpus: empty, tiny, small with random ids, a few cameras.
  std::vector<Frame> plain, packed, tagged;  // tagged: authenticated (frame_auth.h)
  FrameKey key;
  for (std::size_t i = 0; i < key.bytes.size(); ++i) key.bytes[i] = static_cast<std::uint8_t>(7 * i + 1);
  std::vector<Frame> bodies;
  Submap empty;
  std::vector<Submap> seeds = {empty};
  for (int i = 0; i < 4; ++i) {
    SyntheticSubmapOptions o;
    o.keyframes = 1 + i;
    o.keypoints_per_keyframe = 4 + 6 * i;
    o.landmarks = 3 + 8 * i;
    o.cameras = 1 + i % 2;
    o.random_ids = i % 2 == 1;
    o.seed = 100 + i;
    seeds.push_back(makeSyntheticSubmap(o));
  }
  for (const Submap& s : seeds) {
    auto f = encodeSubmap(s);
    ASSERT_TRUE(f.ok()) << f.error();
    plain.push_back(f.value());
    bodies.emplace_back(f->begin() + kWireFixedBytes, f->end());
    WireOptions z;
    z.zstd = true;
    auto fz = encodeSubmap(s, z);
    ASSERT_TRUE(fz.ok()) << fz.error();
    packed.push_back(fz.value());
    for (const Frame* unsigned_frame : {&plain.back(), &packed.back()}) {
      auto t = signFrame(*unsigned_frame, key);
      ASSERT_TRUE(t.ok()) << t.error();
      tagged.push_back(std::move(*t));
    }
  }

  const DecodeLimits limits;
  std::uint64_t iterations = 0, decoded = 0, rejected = 0, past_crc = 0;
  std::map<std::string, std::uint64_t> categories;
  const auto start = std::chrono::steady_clock::now();
  const auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  while (iterations < max_iterations && (iterations % 256 != 0 || elapsed() < seconds)) {
    ++iterations;
    const std::size_t a = rng() % plain.size();
    const std::size_t b = rng() % plain.size();
    Frame f;
    const unsigned mode = rng() % 100;
    if (mode < 15) {  // raw frame mutation, CRC left stale (header fields too)
      const auto pick = [&](std::size_t i) -> const Frame& {
        const unsigned k = rng() % 3;
        return k == 0 ? plain[i] : k == 1 ? packed[i] : tagged[2 * i + rng() % 2];
      };
      f = pick(a);
      mutate(&f, 0, pick(b), rng);
    } else if (mode < 80) {  // body mutation, resealed uncompressed
      Frame body = bodies[a];
      mutate(&body, 0, bodies[b], rng);
      f = seal(plain[a], body, false, rng);
    } else if (mode < 95) {  // body mutation, recompressed and resealed
      Frame body = bodies[a];
      mutate(&body, 0, bodies[b], rng);
      f = seal(plain[a], body, true, rng);
    } else {  // compressed bytes mutated, resealed: exercises zstd's own checks
      Frame zbody(packed[a].begin() + kWireFixedBytes, packed[a].end());
      mutate(&zbody, 0, Frame(packed[b].begin() + kWireFixedBytes, packed[b].end()), rng);
      f = Frame(packed[a].begin(), packed[a].begin() + kWireFixedBytes);
      f.insert(f.end(), zbody.begin(), zbody.end());
      putLE(&f, 8, zbody.size(), 4);
      std::uint32_t c = crc32(f.data(), kWireCrcOffset);
      c = crc32(f.data() + kWireCrcOffset + 4, f.size() - kWireCrcOffset - 4, c);
      putLE(&f, kWireCrcOffset, c, 4);
    }
    auto result = decodeSubmap(f, limits);
    if (result.ok()) {
      ++decoded;
      ++past_crc;
      ASSERT_EQ(result->validate(), "");
      // What decodes must re-encode and decode to the same submap (poses up to
      // the last-bit changes of quaternion re-normalisation).
      auto again = encodeSubmap(*result);
      ASSERT_TRUE(again.ok()) << again.error();
      ASSERT_EQ(again->size(), encodedSizeUncompressed(*result));
      auto twice = decodeSubmap(again.value(), limits);
      ASSERT_TRUE(twice.ok()) << twice.error();
      ASSERT_TRUE(sameSubmap(*result, *twice));
    } else {
      ++rejected;
      ASSERT_EQ(result.error().rfind("wire: ", 0), 0u) << result.error();
      if (result.error().find("CRC mismatch") == std::string::npos) ++past_crc;
      ++categories[category(result.error())];
    }
  }
  const double secs = elapsed();
  std::printf("[fuzz] seed %llu: %llu iterations in %.2f s (%.0f/s): %llu decoded valid, "
              "%llu rejected, %llu got past the CRC\n",
              static_cast<unsigned long long>(seed), static_cast<unsigned long long>(iterations),
              secs, iterations / secs, static_cast<unsigned long long>(decoded),
              static_cast<unsigned long long>(rejected), static_cast<unsigned long long>(past_crc));
  std::vector<std::pair<std::uint64_t, std::string>> top;
  for (const auto& c : categories) top.emplace_back(c.second, c.first);
  std::sort(top.rbegin(), top.rend());
  for (std::size_t i = 0; i < top.size() && i < (std::getenv("HERMES_FUZZ_ALL") ? top.size() : 25); ++i)
    std::printf("[fuzz]   %8llu  %s\n", static_cast<unsigned long long>(top[i].first),
                top[i].second.c_str());
  std::printf("[fuzz]   (%zu error classes in all)\n", top.size());
  // The fuzzer must really reach the body decoder, and some mutants stay valid.
  EXPECT_GT(iterations, 1000u);
  EXPECT_GT(decoded, 0u);
  EXPECT_GT(past_crc, iterations / 2);
  EXPECT_GT(categories.size(), 15u);
}
