// The uplink tags every frame it sends with the robot's key (uplink.auth.*);
// the spool keeps the frames as encoded. A missing or open key file stops the
// uplink from starting, naming the file.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <filesystem>
#include <fstream>

#include "hermes/agent/uplink_sender.h"
#include "hermes/core/frame_auth.h"
#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"

using namespace hermes;
using namespace hermes::agent;

namespace {

const char* kHex = "0f1e2d3c4b5a69788796a5b4c3d2e1f000112233445566778899aabbccddeeff";

UplinkParams paramsIn(const std::string& dir) {
  UplinkParams p;
  p.buffer.dir = dir + "/spool";
  p.buffer.fsync = false;
  p.auth.enabled = true;
  p.auth.key_file = dir + "/keys/{robot}.key";
  return p;
}

void writeKey(const std::string& dir, const std::string& robot, mode_t mode) {
  std::filesystem::create_directories(dir + "/keys");
  const std::string path = dir + "/keys/" + robot + ".key";
  std::ofstream(path) << kHex << "\n";
  ::chmod(path.c_str(), mode);
}

}  // namespace

TEST(UplinkAuth, SentFramesCarryTheRobotsTag) {
  const std::string dir = ::testing::TempDir() + "/uplink_auth";
  std::filesystem::remove_all(dir);
  writeKey(dir, "r7", 0600);
  std::vector<std::vector<std::uint8_t>> wire;
  auto s = UplinkSender::create(
      paramsIn(dir),
      [&](std::uint32_t, std::uint64_t, const std::vector<std::uint8_t>& f) { wire.push_back(f); },
      "r7");
  ASSERT_TRUE(s.ok()) << s.error();
  const std::uint32_t session = *s->buffer().newSession();
  SyntheticSubmapOptions o;
  o.keyframes = 2;
  o.keypoints_per_keyframe = 20;
  o.landmarks = 10;
  Submap submap = makeSyntheticSubmap(o);
  submap.header.agent = agentUuid("r7");
  submap.header.session = session;
  auto frame = encodeSubmap(submap);
  ASSERT_TRUE(frame.ok());
  const std::size_t plain = frame->size();
  ASSERT_TRUE(s->submit(session, 0, *frame, 0.0));
  ASSERT_TRUE(s->submit(session, 1, std::vector<std::uint8_t>(100, 7), 0.0));  // not a frame
  ASSERT_EQ(wire.size(), 2u);
  auto key = parseKeyHex(kHex, "test");
  ASSERT_TRUE(key.ok());
  EXPECT_EQ(wire[0].size(), plain + kWireTagBytes);
  EXPECT_EQ(verifyFrameTag(wire[0].data(), wire[0].size(), *key), TagCheck::kValid);
  FrameKey other = *key;
  other.bytes[0] ^= 1;
  EXPECT_EQ(verifyFrameTag(wire[0].data(), wire[0].size(), other), TagCheck::kMismatch);
  EXPECT_EQ(wire[1].size(), 100u);  // cannot be tagged: sent as it is, counted
  EXPECT_EQ(s->stats().untagged, 1u);
  EXPECT_EQ(s->stats().bytes_sent, plain + kWireTagBytes + 100);
  EXPECT_EQ(s->buffer().pendingBytes(), plain + 100);  // the spool keeps what was encoded
}

TEST(UplinkAuth, MissingOrOpenKeyFileIsAnError) {
  const std::string dir = ::testing::TempDir() + "/uplink_auth_bad";
  std::filesystem::remove_all(dir);
  auto none = [](std::uint32_t, std::uint64_t, const std::vector<std::uint8_t>&) {};
  auto missing = UplinkSender::create(paramsIn(dir), none, "r8");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find(dir + "/keys/r8.key does not exist"), std::string::npos)
      << missing.error();
  EXPECT_NE(missing.error().find("uplink.auth.key_file"), std::string::npos);
  writeKey(dir, "r8", 0644);
  auto open = UplinkSender::create(paramsIn(dir), none, "r8");
  ASSERT_FALSE(open.ok());
  EXPECT_NE(open.error().find("chmod 600"), std::string::npos) << open.error();
  UplinkParams off = paramsIn(dir);
  off.auth.enabled = false;  // no key needed
  EXPECT_TRUE(UplinkSender::create(off, none, "nobody").ok());
  UplinkAuthParams a;
  a.key_file = "/k/{robot}/{robot}.key";
  EXPECT_EQ(a.keyFileFor("x"), "/k/x/x.key");
}
