// Submap -> frame: encoder-side checks, exact byte accounting, the cereal body
// writer and optional zstd compression. The layout is documented in wire_format.h.
#include <cereal/archives/portable_binary.hpp>
#include <zstd.h>

#include <cmath>
#include <limits>
#include <ostream>
#include <sstream>
#include <unordered_map>

#include "hermes/core/wire_format.h"
#include "wire_internal.h"

namespace hermes {
namespace wire {
namespace {

using KeyframeIndex = std::unordered_map<KeyframeId, std::uint32_t>;

KeyframeIndex indexKeyframes(const Submap& s) {
  KeyframeIndex index;
  index.reserve(s.keyframes.size());
  for (std::size_t i = 0; i < s.keyframes.size(); ++i)
    index.emplace(s.keyframes[i].id, static_cast<std::uint32_t>(i));
  return index;
}

std::size_t indexVarintSize(const KeyframeIndex& index, KeyframeId id) {
  const auto it = index.find(id);
  return varintSize(it == index.end() ? 0 : it->second);
}

bool finitePose(const SE3& T) {
  return T.quat().coeffs().allFinite() && T.translation().allFinite();
}

bool finiteAsFloat(double v) { return std::isfinite(static_cast<float>(v)); }

/// Everything the decoder would reject, checked before any byte is written, so
/// that the agent never sends a frame the server drops. Empty string when fine.
std::string encodableProblem(const Submap& s) {
  std::string problem = s.validate();
  if (!problem.empty()) return "submap is not valid: " + problem;
  std::ostringstream err;
  if (!std::isfinite(s.header.t_start) || !std::isfinite(s.header.t_end))
    return "submap header window stamps are not finite";
  for (std::size_t c = 0; c < s.cameras.size(); ++c) {
    const PinholeIntrinsics& k = s.cameras[c];
    if (!std::isfinite(k.fx) || !std::isfinite(k.fy) || !std::isfinite(k.cx) ||
        !std::isfinite(k.cy) || k.width < 0 || k.height < 0) {
      err << "camera " << c << " has non-finite intrinsics or a negative image size";
      return err.str();
    }
  }
  KeyframeIndex index = indexKeyframes(s);
  std::vector<std::vector<LandmarkId>> seen(s.keyframes.size());
  for (std::size_t i = 0; i < s.keyframes.size(); ++i) {
    const Keyframe& kf = s.keyframes[i];
    if (!std::isfinite(kf.stamp) || !finitePose(kf.T_A_C)) {
      err << "keyframe " << kf.id << " has a non-finite stamp or pose";
      return err.str();
    }
    if (kf.keypoints.size() > std::numeric_limits<std::uint32_t>::max()) {
      err << "keyframe " << kf.id << " has too many keypoints";
      return err.str();
    }
    for (std::size_t k = 0; k < kf.keypoints.size(); ++k) {
      const Keypoint& kp = kf.keypoints[k];
      if (!std::isfinite(kp.u) || !std::isfinite(kp.v) || !std::isfinite(kp.depth)) {
        err << "keyframe " << kf.id << " keypoint " << k << " is not finite";
        return err.str();
      }
    }
    seen[i].assign(kf.keypoints.size(), kInvalidId);
  }
  for (const Landmark& lm : s.landmarks) {
    if (!finiteAsFloat(lm.p_A.x()) || !finiteAsFloat(lm.p_A.y()) || !finiteAsFloat(lm.p_A.z())) {
      err << "landmark " << lm.id << " position does not fit a float";
      return err.str();
    }
    for (const Observation& ob : lm.observations) {
      LandmarkId& slot = seen[index.at(ob.keyframe)][ob.keypoint];
      if (slot != kInvalidId) {
        err << "keyframe " << ob.keyframe << " keypoint " << ob.keypoint
            << " is observed by landmarks " << slot << " and " << lm.id;
        return err.str();
      }
      slot = lm.id;
    }
  }
  for (const OdometryEdge& e : s.odometry) {
    bool ok = finitePose(e.T_from_to);
    for (int r = 0; r < 6 && ok; ++r)
      for (int c = r; c < 6 && ok; ++c) ok = finiteAsFloat(e.information(r, c));
    if (!ok) {
      err << "odometry edge " << e.from << "->" << e.to
          << " has a non-finite pose or an information entry that does not fit a float";
      return err.str();
    }
  }
  return {};
}

/// Thin layer over cereal's portable binary archive (always little-endian).
class BodyWriter {
 public:
  explicit BodyWriter(std::vector<std::uint8_t>* out)
      : buf_(out), os_(&buf_), ar_(os_, Archive::Options::LittleEndian()) {}

  template <class T>
  void scalar(T v) { ar_(v); }
  template <class T>
  void array(const T* p, std::size_t n) { ar_(cereal::binary_data(p, n * sizeof(T))); }
  void varint(std::uint64_t v) {
    std::uint8_t b[10];
    ar_(cereal::binary_data(b, putVarint(v, b)));
  }
  void pose(const SE3& T) {
    const double v[7] = {T.quat().w(), T.quat().x(), T.quat().y(), T.quat().z(),
                         T.translation().x(), T.translation().y(), T.translation().z()};
    array(v, 7);
  }

 private:
  using Archive = cereal::PortableBinaryOutputArchive;
  VectorOutBuf buf_;
  std::ostream os_;
  Archive ar_;
};

}  // namespace

void writeBody(const Submap& s, std::vector<std::uint8_t>* out) {
  BodyWriter w(out);  // writes cereal's endianness marker
  w.varint(s.cameras.size());
  for (const PinholeIntrinsics& k : s.cameras) {
    const double f[4] = {k.fx, k.fy, k.cx, k.cy};
    w.array(f, 4);
    w.scalar(static_cast<std::uint32_t>(k.width));
    w.scalar(static_cast<std::uint32_t>(k.height));
  }
  w.varint(s.keyframes.size());
  KeyframeId prev_kf = 0;
  std::vector<float> column;
  std::vector<std::uint8_t> octaves;
  for (const Keyframe& kf : s.keyframes) {
    w.varint(zigzagDelta(kf.id, prev_kf));
    prev_kf = kf.id;
    w.scalar(kf.stamp);
    w.pose(kf.T_A_C);
    w.varint(kf.camera_id);
    const std::uint8_t flags = kf.lost_before ? kKeyframeFlagLostBefore : 0;
    w.array(&flags, 1);
    const std::size_t n = kf.keypoints.size();
    w.varint(n);
    column.resize(n);
    for (std::size_t k = 0; k < n; ++k) column[k] = kf.keypoints[k].u;
    w.array(column.data(), n);
    for (std::size_t k = 0; k < n; ++k) column[k] = kf.keypoints[k].v;
    w.array(column.data(), n);
    octaves.resize(n);
    for (std::size_t k = 0; k < n; ++k) octaves[k] = kf.keypoints[k].octave;
    w.array(octaves.data(), n);
    for (std::size_t k = 0; k < n; ++k) column[k] = kf.keypoints[k].depth;
    w.array(column.data(), n);
    w.array(kf.descriptors.empty() ? nullptr : kf.descriptors[0].data(), 32 * n);
  }
  const KeyframeIndex index = indexKeyframes(s);
  w.varint(s.landmarks.size());
  LandmarkId prev_lm = 0;
  for (const Landmark& lm : s.landmarks) {
    w.varint(zigzagDelta(lm.id, prev_lm));
    prev_lm = lm.id;
    const float p[3] = {static_cast<float>(lm.p_A.x()), static_cast<float>(lm.p_A.y()),
                        static_cast<float>(lm.p_A.z())};
    w.array(p, 3);
    w.array(lm.descriptor.data(), 32);
    w.varint(lm.observations.size());
    for (const Observation& ob : lm.observations) {
      w.varint(index.at(ob.keyframe));
      w.varint(ob.keypoint);
    }
  }
  w.varint(s.odometry.size());
  for (const OdometryEdge& e : s.odometry) {
    w.varint(index.at(e.from));
    w.varint(index.at(e.to));
    w.pose(e.T_from_to);
    float info[21];
    int n = 0;
    for (int r = 0; r < 6; ++r)
      for (int c = r; c < 6; ++c) info[n++] = static_cast<float>(e.information(r, c));
    w.array(info, 21);
  }
}

}  // namespace wire

WireStats wireStats(const Submap& s) {
  using namespace wire;
  WireStats st;
  st.header = kWireFixedBytes + 1 + varintSize(s.cameras.size()) +
              s.cameras.size() * kCameraBytes + varintSize(s.keyframes.size()) +
              varintSize(s.landmarks.size()) + varintSize(s.odometry.size());
  KeyframeId prev_kf = 0;
  for (const Keyframe& kf : s.keyframes) {
    st.keyframes += varintSize(zigzagDelta(kf.id, prev_kf)) + 8 + kPoseBytes +
                    varintSize(kf.camera_id) + 1 + varintSize(kf.keypoints.size());
    prev_kf = kf.id;
    st.keypoints += kKeypointBytes * kf.keypoints.size();
    st.descriptors += kDescriptorBytes * kf.keypoints.size();
  }
  const auto index = indexKeyframes(s);
  LandmarkId prev_lm = 0;
  for (const Landmark& lm : s.landmarks) {
    st.landmarks += varintSize(zigzagDelta(lm.id, prev_lm)) + 12 + kDescriptorBytes +
                    varintSize(lm.observations.size());
    prev_lm = lm.id;
    for (const Observation& ob : lm.observations)
      st.observations += indexVarintSize(index, ob.keyframe) + varintSize(ob.keypoint);
  }
  for (const OdometryEdge& e : s.odometry)
    st.odometry += indexVarintSize(index, e.from) + indexVarintSize(index, e.to) + kPoseBytes +
                   kInformationBytes;
  st.total = st.header + st.keyframes + st.keypoints + st.descriptors + st.landmarks +
             st.observations + st.odometry;
  st.frame = st.total;
  return st;
}

std::size_t encodedSizeUncompressed(const Submap& s) { return wireStats(s).total; }

Expected<std::vector<std::uint8_t>> encodeSubmap(const Submap& s, const WireOptions& options,
                                                 WireStats* stats) {
  using namespace wire;
  const std::string problem = encodableProblem(s);
  if (!problem.empty()) return Error{"wire: cannot encode: " + problem};
  WireStats st = wireStats(s);
  const std::size_t raw = st.total - kWireFixedBytes;
  if (raw > std::numeric_limits<std::uint32_t>::max())
    return Error{"wire: cannot encode: body of " + std::to_string(raw) +
                 " bytes exceeds the 4 GiB a frame can describe"};

  std::vector<std::uint8_t> frame(kWireFixedBytes);
  frame.reserve(st.total);
  writeBody(s, &frame);
  HERMES_CHECK(frame.size() == st.total, "wire byte accounting disagrees with the encoder");

  std::uint16_t flags = 0;
  if (options.zstd) {
    std::vector<std::uint8_t> packed(kWireFixedBytes + ZSTD_compressBound(raw));
    const std::size_t n = ZSTD_compress(packed.data() + kWireFixedBytes,
                                        packed.size() - kWireFixedBytes,
                                        frame.data() + kWireFixedBytes, raw, options.zstd_level);
    if (ZSTD_isError(n))
      return Error{std::string("wire: zstd compression failed: ") + ZSTD_getErrorName(n)};
    if (n > std::numeric_limits<std::uint32_t>::max())
      return Error{"wire: cannot encode: compressed body exceeds 4 GiB"};
    packed.resize(kWireFixedBytes + n);
    frame.swap(packed);
    flags |= kWireFlagZstd;
  }
  sealFrame(&frame, s.header, flags, static_cast<std::uint32_t>(raw));
  st.frame = frame.size();
  if (stats) *stats = st;
  return frame;
}

}  // namespace hermes
