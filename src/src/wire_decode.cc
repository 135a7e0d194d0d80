// Body -> Submap. Every read is bounds-checked against the bytes that remain,
// every count is checked against the minimum size of what it counts before
// anything is reserved, and the first problem is thrown as a DecodeError naming
// the element and the body offset.
#include <cereal/archives/portable_binary.hpp>

#include <cmath>
#include <istream>
#include <limits>

#include "wire_internal.h"

namespace hermes {
namespace wire {
namespace {

class BodyReader {
 public:
  BodyReader(const std::uint8_t* data, std::size_t size)
      : buf_(data, size), is_(&buf_), ar_(is_, Archive::Options::Default()) {}
  // (Input options name the *host* order; cereal swaps when the stream's marker
  // differs from it, so little-endian bodies also load on big-endian hosts.)

  std::size_t offset() const { return buf_.offset(); }
  std::size_t remaining() const { return buf_.remaining(); }

  [[noreturn]] void fail(const std::string& what) const {
    throw DecodeError("wire: " + what + " (body offset " + std::to_string(offset()) + ")");
  }

  /// Ensures `n` more bytes exist for `what` (a lazily built description).
  template <class Describe>
  void need(std::size_t n, Describe&& what) {
    if (n > remaining())
      fail("body ends inside " + what() + ": needs " + std::to_string(n) + " bytes, " +
           std::to_string(remaining()) + " left");
  }

  template <class T, class Describe>
  T scalar(Describe&& what) {
    need(sizeof(T), what);
    T v;
    ar_(v);
    return v;
  }
  template <class T, class Describe>
  void array(T* p, std::size_t n, Describe&& what) {
    need(n * sizeof(T), what);  // n is bounded by a checked count, no overflow
    ar_(cereal::binary_data(p, n * sizeof(T)));
  }
  template <class Describe>
  std::uint64_t varint(Describe&& what) {
    std::uint64_t v = 0;
    for (int shift = 0;; shift += 7) {
      need(1, what);
      std::uint8_t b;
      ar_(b);
      if (shift == 63 && b > 1) fail(what() + " varint overflows 64 bits");
      v |= std::uint64_t{b & 0x7fu} << shift;
      if (!(b & 0x80)) {
        if (b == 0 && shift > 0) fail(what() + " varint is not in canonical form");
        return v;
      }
    }
  }
  /// A container count: count × min_bytes may not exceed what remains.
  template <class Describe>
  std::size_t count(std::size_t min_bytes, Describe&& what) {
    const std::uint64_t n = varint(what);
    if (n > remaining() / min_bytes)
      fail(what() + " " + std::to_string(n) + " exceeds remaining " +
           std::to_string(remaining()) + " bytes");
    return static_cast<std::size_t>(n);
  }
  template <class Describe>
  std::uint32_t index(std::size_t bound, Describe&& what) {
    const std::uint64_t i = varint(what);
    if (i >= bound)
      fail(what() + " " + std::to_string(i) + " is out of range (" + std::to_string(bound) +
           " available)");
    return static_cast<std::uint32_t>(i);
  }
  template <class Describe>
  SE3 pose(Describe&& what) {
    double v[7];
    array(v, 7, what);
    for (double x : v)
      if (!std::isfinite(x)) fail(what() + " is not finite");
    const Quat q(v[0], v[1], v[2], v[3]);
    if (std::abs(q.norm() - 1.0) > 1e-6) fail(what() + " quaternion is not unit length");
    return SE3(q, Vec3(v[4], v[5], v[6]));
  }

 private:
  using Archive = cereal::PortableBinaryInputArchive;
  MemoryInBuf buf_;
  std::istream is_;
  Archive ar_;
};

std::string str(std::size_t v) { return std::to_string(v); }

void readCameras(BodyReader& r, Submap* s) {
  const std::size_t n = r.count(kCameraBytes, [] { return std::string("camera count"); });
  s->cameras.resize(n);
  for (std::size_t c = 0; c < n; ++c) {
    const auto what = [c] { return "camera " + str(c); };
    double f[4];
    r.array(f, 4, what);
    for (double x : f)
      if (!std::isfinite(x)) r.fail(what() + " intrinsics are not finite");
    const std::uint32_t w = r.scalar<std::uint32_t>(what);
    const std::uint32_t h = r.scalar<std::uint32_t>(what);
    constexpr std::uint32_t kIntMax = std::numeric_limits<int>::max();
    if (w > kIntMax || h > kIntMax) r.fail(what() + " image size is out of range");
    s->cameras[c] = PinholeIntrinsics{f[0], f[1], f[2], f[3], static_cast<int>(w),
                                      static_cast<int>(h)};
  }
}

void readKeyframe(BodyReader& r, std::size_t i, KeyframeId prev, Keyframe* kf,
                  std::vector<float>* column) {
  const auto what = [i] { return "keyframe #" + str(i); };
  kf->id = unzigzagDelta(r.varint([&] { return what() + " id"; }), prev);
  kf->stamp = r.scalar<double>(what);
  if (!std::isfinite(kf->stamp)) r.fail(what() + " stamp is not finite");
  kf->T_A_C = r.pose([&] { return what() + " pose"; });
  const std::uint64_t camera = r.varint([&] { return what() + " camera id"; });
  if (camera > std::numeric_limits<std::uint32_t>::max()) r.fail(what() + " camera id overflows");
  kf->camera_id = static_cast<std::uint32_t>(camera);
  std::uint8_t flags = 0;
  r.array(&flags, 1, [&] { return what() + " flags"; });
  if (flags & ~kKeyframeFlagLostBefore) r.fail(what() + " has unknown flags " + str(flags));
  kf->lost_before = (flags & kKeyframeFlagLostBefore) != 0;
  const std::size_t n =
      r.count(kKeypointBytes + kDescriptorBytes, [&] { return what() + " keypoint count"; });
  kf->keypoints.resize(n);
  column->resize(n);
  const auto cols = [&] { return what() + " keypoints"; };
  r.array(column->data(), n, cols);
  for (std::size_t k = 0; k < n; ++k) kf->keypoints[k].u = (*column)[k];
  r.array(column->data(), n, cols);
  for (std::size_t k = 0; k < n; ++k) kf->keypoints[k].v = (*column)[k];
  std::vector<std::uint8_t> octaves(n);
  r.array(octaves.data(), n, cols);
  for (std::size_t k = 0; k < n; ++k) kf->keypoints[k].octave = octaves[k];
  r.array(column->data(), n, cols);
  for (std::size_t k = 0; k < n; ++k) {
    Keypoint& kp = kf->keypoints[k];
    kp.depth = (*column)[k];
    if (!std::isfinite(kp.u) || !std::isfinite(kp.v) || !std::isfinite(kp.depth))
      r.fail(what() + " keypoint " + str(k) + " is not finite");
  }
  kf->descriptors.resize(n);
  r.array(n > 0 ? kf->descriptors[0].data() : nullptr, 32 * n,
          [&] { return what() + " descriptors"; });
  kf->keypoint_landmark.assign(n, kInvalidId);
}

void readLandmarks(BodyReader& r, Submap* s) {
  const std::size_t n = r.count(kMinLandmarkBytes, [] { return std::string("landmark count"); });
  s->landmarks.resize(n);
  LandmarkId prev = 0;
  for (std::size_t j = 0; j < n; ++j) {
    Landmark& lm = s->landmarks[j];
    const auto what = [j] { return "landmark #" + str(j); };
    lm.id = unzigzagDelta(r.varint([&] { return what() + " id"; }), prev);
    prev = lm.id;
    float p[3];
    r.array(p, 3, what);
    lm.p_A = Vec3(p[0], p[1], p[2]);
    if (!lm.p_A.allFinite()) r.fail(what() + " position is not finite");
    r.array(lm.descriptor.data(), 32, what);
    const std::size_t m =
        r.count(kMinObservationBytes, [&] { return what() + " observation count"; });
    lm.observations.resize(m);
    for (std::size_t o = 0; o < m; ++o) {
      const auto ob_what = [&] { return what() + " observation " + str(o); };
      const std::uint32_t k =
          r.index(s->keyframes.size(), [&] { return ob_what() + " keyframe index"; });
      Keyframe& kf = s->keyframes[k];
      const std::uint64_t kp = r.varint([&] { return ob_what() + " keypoint index"; });
      if (kp >= kf.keypoints.size())
        r.fail(ob_what() + " keypoint " + str(kp) + " is out of range (keyframe " +
               str(kf.id) + " has " + str(kf.keypoints.size()) + ")");
      LandmarkId& link = kf.keypoint_landmark[kp];
      if (link != kInvalidId)
        r.fail(ob_what() + ": keyframe " + str(kf.id) + " keypoint " + str(kp) +
               " is already observed by landmark " + str(link));
      link = lm.id;
      lm.observations[o] = Observation{kf.id, static_cast<std::uint32_t>(kp)};
    }
  }
}

void readOdometry(BodyReader& r, Submap* s) {
  const std::size_t n =
      r.count(kMinOdometryBytes, [] { return std::string("odometry edge count"); });
  s->odometry.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    OdometryEdge& e = s->odometry[i];
    const auto what = [i] { return "odometry edge #" + str(i); };
    e.from = s->keyframes[r.index(s->keyframes.size(), [&] { return what() + " from index"; })].id;
    e.to = s->keyframes[r.index(s->keyframes.size(), [&] { return what() + " to index"; })].id;
    e.T_from_to = r.pose([&] { return what() + " pose"; });
    float info[21];
    r.array(info, 21, what);
    int k = 0;
    for (int row = 0; row < 6; ++row)
      for (int col = row; col < 6; ++col) {
        if (!std::isfinite(info[k])) r.fail(what() + " information is not finite");
        e.information(row, col) = e.information(col, row) = info[k++];
      }
  }
}

}  // namespace

Submap readBody(const std::uint8_t* data, std::size_t size) {
  if (size < 1) throw DecodeError("wire: body is empty (body offset 0)");
  if (data[0] != kLittleEndianMarker)
    throw DecodeError("wire: body endianness marker is " + std::to_string(data[0]) +
                      ", expected 1 (little-endian) (body offset 0)");
  BodyReader r(data, size);  // consumes the marker
  Submap s;
  readCameras(r, &s);
  const std::size_t n_kf =
      r.count(kMinKeyframeBytes, [] { return std::string("keyframe count"); });
  s.keyframes.resize(n_kf);
  std::vector<float> column;
  KeyframeId prev = 0;
  for (std::size_t i = 0; i < n_kf; ++i) {
    readKeyframe(r, i, prev, &s.keyframes[i], &column);
    prev = s.keyframes[i].id;
  }
  readLandmarks(r, &s);
  readOdometry(r, &s);
  if (r.remaining() != 0) r.fail(str(r.remaining()) + " unread bytes at the end of the body");
  return s;
}

}  // namespace wire
}  // namespace hermes
