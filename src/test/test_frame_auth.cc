// Authenticated frames: HMAC tag round trip, tamper detection on every byte,
// wrong key, key files and the keyring, and a bounded mutation fuzz of tagged
// frames through both the tag check and the decoder.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>

#include "hermes/core/crc32.h"
#include "hermes/core/frame_auth.h"
#include "hermes/core/keyring.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"

using namespace hermes;

namespace {

using Frame = std::vector<std::uint8_t>;

FrameKey keyOf(std::uint8_t seed) {
  FrameKey k;
  for (std::size_t i = 0; i < k.bytes.size(); ++i) k.bytes[i] = static_cast<std::uint8_t>(seed + 13 * i);
  return k;
}

Frame smallFrame(bool zstd, std::uint64_t seed = 3) {
  SyntheticSubmapOptions o;
  o.keyframes = 2;
  o.keypoints_per_keyframe = 6;
  o.landmarks = 5;
  o.seed = seed;
  Submap s = makeSyntheticSubmap(o);
  s.header.agent = agentUuid("r1");
  s.header.session = 2;
  s.header.seq = 9;
  WireOptions w;
  w.zstd = zstd;
  auto f = encodeSubmap(s, w);
  EXPECT_TRUE(f.ok()) << f.error();
  return f.ok() ? *f : Frame{};
}

void putLE(Frame* f, std::size_t at, std::uint64_t v, int n) {
  for (int i = 0; i < n; ++i) (*f)[at + i] = static_cast<std::uint8_t>(v >> (8 * i));
}

/// Recomputes the CRC so that only the tag (not the CRC) can catch a change.
void reseal(Frame* f) {
  if (f->size() < kWireFixedBytes) return;
  std::uint32_t c = crc32(f->data(), kWireCrcOffset);
  c = crc32(f->data() + kWireCrcOffset + 4, f->size() - kWireCrcOffset - 4, c);
  putLE(f, kWireCrcOffset, c, 4);
}

std::string writeFile(const std::string& dir, const std::string& name, const std::string& text,
                      mode_t mode) {
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/" + name;
  std::ofstream(path) << text;
  ::chmod(path.c_str(), mode);
  return path;
}

const char* kHex = "00112233445566778899aabbccddeeff00112233445566778899AABBCCDDEEFF";

}  // namespace

TEST(FrameAuth, SignedFrameVerifiesAndDecodesLikeTheUnsignedOne) {
  for (bool zstd : {false, true}) {
    const Frame plain = smallFrame(zstd);
    auto tagged = signFrame(plain, keyOf(1));
    ASSERT_TRUE(tagged.ok()) << tagged.error();
    EXPECT_EQ(tagged->size(), plain.size() + kWireTagBytes);
    EXPECT_EQ(verifyFrameTag(tagged->data(), tagged->size(), keyOf(1)), TagCheck::kValid);
    EXPECT_EQ(verifyFrameTag(plain.data(), plain.size(), keyOf(1)), TagCheck::kMissing);
    auto h = peekFrame(tagged->data(), tagged->size());
    ASSERT_TRUE(h.ok()) << h.error();
    EXPECT_TRUE(h->tagged());
    EXPECT_EQ(h->frameBytes(), tagged->size());
    auto a = decodeSubmap(plain);
    auto b = decodeSubmap(*tagged);
    ASSERT_TRUE(a.ok() && b.ok()) << (b ? "" : b.error());
    EXPECT_EQ(a->keyframes.size(), b->keyframes.size());
    EXPECT_EQ(a->landmarks.size(), b->landmarks.size());
    EXPECT_EQ(b->header.seq, 9u);
  }
}

TEST(FrameAuth, WrongKeyAndResigning) {
  const Frame plain = smallFrame(false);
  auto tagged = signFrame(plain, keyOf(1));
  ASSERT_TRUE(tagged.ok());
  EXPECT_EQ(verifyFrameTag(tagged->data(), tagged->size(), keyOf(2)), TagCheck::kMismatch);
  FrameKey one_bit = keyOf(1);
  one_bit.bytes[31] ^= 1;
  EXPECT_EQ(verifyFrameTag(tagged->data(), tagged->size(), one_bit), TagCheck::kMismatch);
  // Re-signing an already tagged frame replaces its tag (a spool written under an old key).
  auto again = signFrame(*tagged, keyOf(2));
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->size(), tagged->size());
  EXPECT_EQ(verifyFrameTag(again->data(), again->size(), keyOf(2)), TagCheck::kValid);
  EXPECT_EQ(verifyFrameTag(again->data(), again->size(), keyOf(1)), TagCheck::kMismatch);
  // Malformed input: not signed, not verified.
  Frame junk(100, 0x5a);
  EXPECT_FALSE(signFrame(junk, keyOf(1)).ok());
  EXPECT_EQ(verifyFrameTag(junk.data(), junk.size(), keyOf(1)), TagCheck::kMalformed);
}

// Flip any single byte of a tagged frame (the CRC recomputed, so only the tag
// can notice): the frame never verifies.
TEST(FrameAuth, EveryFlippedByteIsDetected) {
  for (bool zstd : {false, true}) {
    auto tagged = signFrame(smallFrame(zstd), keyOf(4));
    ASSERT_TRUE(tagged.ok());
    std::size_t mismatch = 0, other = 0;
    for (std::size_t i = 0; i < tagged->size(); ++i) {
      if (i >= kWireCrcOffset && i < kWireCrcOffset + 4) continue;  // the CRC itself
      for (std::uint8_t bit : {0x01, 0x80}) {
        Frame f = *tagged;
        f[i] ^= bit;
        reseal(&f);
        const TagCheck c = verifyFrameTag(f.data(), f.size(), keyOf(4));
        ASSERT_NE(c, TagCheck::kValid) << "byte " << i << " bit " << int(bit);
        (c == TagCheck::kMismatch ? mismatch : other) += 1;
      }
      // Without the CRC fixed the frame is malformed before any tag is looked at.
      Frame g = *tagged;
      g[i] ^= 0x10;
      ASSERT_NE(verifyFrameTag(g.data(), g.size(), keyOf(4)), TagCheck::kValid);
    }
    // Header and body flips reach the HMAC; only length/flag/version/magic
    // flips make the frame unreadable or untagged first.
    EXPECT_GT(mismatch, 2 * (tagged->size() - kWireFixedBytes));
    std::printf("zstd=%d: %zu flips caught by the tag, %zu by the frame checks\n", int(zstd),
                mismatch, other);
  }
  // Truncating the tag or stripping it (flag cleared) is caught too.
  auto tagged = signFrame(smallFrame(false), keyOf(4));
  Frame cut(tagged->begin(), tagged->end() - 1);
  reseal(&cut);
  EXPECT_EQ(verifyFrameTag(cut.data(), cut.size(), keyOf(4)), TagCheck::kMalformed);
  Frame stripped(tagged->begin(), tagged->end() - kWireTagBytes);
  stripped[6] &= static_cast<std::uint8_t>(~kWireFlagTag);
  reseal(&stripped);
  EXPECT_EQ(verifyFrameTag(stripped.data(), stripped.size(), keyOf(4)), TagCheck::kMissing);
}

TEST(FrameAuth, MutatedTaggedFramesNeverVerifyAndDecodeCleanly) {
  std::mt19937_64 rng(77);
  std::vector<Frame> seeds;
  for (bool zstd : {false, true})
    for (std::uint64_t s : {1, 2}) seeds.push_back(*signFrame(smallFrame(zstd, s), keyOf(9)));
  std::size_t iterations = 0, decoded = 0;
  const auto start = std::chrono::steady_clock::now();
  while (iterations < 20000 &&
         std::chrono::steady_clock::now() - start < std::chrono::seconds(3)) {
    ++iterations;
    const Frame& seed = seeds[rng() % seeds.size()];
    Frame f = seed;
    const int edits = 1 + static_cast<int>(rng() % 3);
    for (int e = 0; e < edits && !f.empty(); ++e) {
      const std::size_t at = rng() % f.size();
      switch (rng() % 4) {
        case 0: f[at] ^= static_cast<std::uint8_t>(1u << (rng() % 8)); break;
        case 1: f[at] = static_cast<std::uint8_t>(rng()); break;
        case 2: f.erase(f.begin() + at); break;
        case 3: f.insert(f.begin() + at, static_cast<std::uint8_t>(rng())); break;
      }
    }
    if (rng() % 4 != 0) {  // most mutants get consistent lengths and CRC
      if (f.size() >= kWireFixedBytes) {
        const bool tag = (f[6] & kWireFlagTag) != 0;
        const std::size_t trailer =
            tag && f.size() >= kWireFixedBytes + kWireTagBytes ? kWireTagBytes : 0;
        const std::size_t body = f.size() - kWireFixedBytes - trailer;
        putLE(&f, 8, body, 4);
      }
      reseal(&f);
    }
    const TagCheck c = verifyFrameTag(f.data(), f.size(), keyOf(9));
    if (c == TagCheck::kValid) {
      ASSERT_EQ(f, seed) << "a changed frame verified, iteration " << iterations;
    }
    auto d = decodeSubmap(f);
    if (d.ok()) {
      ++decoded;
      ASSERT_EQ(d->validate(), "");
    } else {
      ASSERT_EQ(d.error().rfind("wire: ", 0), 0u) << d.error();
    }
  }
  std::printf("tagged fuzz: %zu iterations, %zu decoded\n", iterations, decoded);
  EXPECT_GT(iterations, 1000u);
}

TEST(FrameAuth, KeyFiles) {
  const std::string dir = ::testing::TempDir() + "/hermes_keyfiles";
  std::filesystem::remove_all(dir);
  auto good = readKeyFile(writeFile(dir, "r1.key", std::string(kHex) + "\n", 0600));
  ASSERT_TRUE(good.ok()) << good.error();
  EXPECT_EQ(good->bytes[0], 0x00);
  EXPECT_EQ(good->bytes[31], 0xff);
  auto open = readKeyFile(writeFile(dir, "open.key", kHex, 0644));
  ASSERT_FALSE(open.ok());
  EXPECT_NE(open.error().find("chmod 600"), std::string::npos) << open.error();
  auto shortk = readKeyFile(writeFile(dir, "short.key", "abcd\n", 0600));
  ASSERT_FALSE(shortk.ok());
  EXPECT_NE(shortk.error().find("short.key has 4 characters"), std::string::npos) << shortk.error();
  std::string bad = kHex;
  bad[10] = 'x';
  auto nonhex = readKeyFile(writeFile(dir, "nonhex.key", bad, 0600));
  ASSERT_FALSE(nonhex.ok());
  EXPECT_NE(nonhex.error().find("position 10"), std::string::npos) << nonhex.error();
  auto missing = readKeyFile(dir + "/nobody.key");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("does not exist"), std::string::npos);
}

TEST(FrameAuth, KeyringFromADirectory) {
  const std::string dir = ::testing::TempDir() + "/hermes_keyring";
  std::filesystem::remove_all(dir);
  EXPECT_FALSE(Keyring::loadDir(dir).ok());  // missing folder
  std::filesystem::create_directories(dir);
  auto empty = Keyring::loadDir(dir);
  ASSERT_FALSE(empty.ok());
  EXPECT_NE(empty.error().find("holds no <robot>.key"), std::string::npos) << empty.error();
  writeFile(dir, "alpha.key", kHex, 0600);
  writeFile(dir, "beta.key", std::string(kHex).replace(0, 2, "ff"), 0600);
  writeFile(dir, "notes.txt", "not a key", 0644);
  auto ring = Keyring::loadDir(dir);
  ASSERT_TRUE(ring.ok()) << ring.error();
  EXPECT_EQ(ring->size(), 2u);
  const Keyring::Entry* beta = ring->find(agentUuid("beta"));
  ASSERT_NE(beta, nullptr);
  EXPECT_EQ(beta->robot, "beta");
  EXPECT_EQ(beta->key.bytes[0], 0xff);
  EXPECT_EQ(ring->find(agentUuid("gamma")), nullptr);
  writeFile(dir, "gamma.key", kHex, 0640);  // one bad file fails the whole directory, by name
  auto bad = Keyring::loadDir(dir);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().find("gamma.key"), std::string::npos) << bad.error();
  const char* home = std::getenv("HOME");
  EXPECT_EQ(expandHome("~/k"), std::string(home ? home : "") + "/k");
  EXPECT_EQ(expandHome("/abs/~/k"), "/abs/~/k");
}
