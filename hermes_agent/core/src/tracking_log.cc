#include "hermes/agent/tracking_log.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <type_traits>

#include "hermes/core/crc32.h"

namespace hermes::agent {
namespace {

constexpr char kMagic[4] = {'H', 'T', 'R', 'K'};
enum RecordType : std::uint8_t { kKey = 1, kStep = 2, kSummary = 3 };

// ---- writing ---------------------------------------------------------------

struct Out {
  std::vector<std::uint8_t>* b;
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable<T>::value, "plain values only");
    const auto* p = reinterpret_cast<const std::uint8_t*>(&v);
    b->insert(b->end(), p, p + sizeof(T));
  }
  template <class... T>
  void all(const T&... v) {
    (put(v), ...);
  }
  void count(std::size_t n) { put(static_cast<std::uint64_t>(n)); }
  void text(const std::string& s) {
    put(static_cast<std::uint32_t>(s.size()));
    b->insert(b->end(), s.begin(), s.end());
  }
  void pose(const SE3& T) {
    const Quat& q = T.quat();
    for (double v : {q.w(), q.x(), q.y(), q.z()}) put(v);
    for (int k = 0; k < 3; ++k) put(T.translation()[k]);
  }
};

void putHealth(Out& o, const distill::TrackingHealth& h) {
  for (int v : {h.frames, h.lost, h.weak, h.min_tracked}) o.put(static_cast<std::int32_t>(v));
}

void putMotion(Out& o, const distill::MotionHint& m) {
  o.put(static_cast<std::uint8_t>(m.valid));
  o.pose(m.T_A_C);
  o.pose(m.T_Cprev_Ccurr);
  o.put(m.dt_s);
  o.put(m.camera_id);
  putHealth(o, m.health);
}

void putSubmap(Out& o, const Submap& s) {
  o.all(s.header.agent, s.header.session, s.header.seq, s.header.t_start, s.header.t_end);
  o.count(s.cameras.size());
  for (const PinholeIntrinsics& K : s.cameras) {
    for (double v : {K.fx, K.fy, K.cx, K.cy}) o.put(v);
    o.put(static_cast<std::int32_t>(K.width));
    o.put(static_cast<std::int32_t>(K.height));
  }
  o.count(s.keyframes.size());
  for (const Keyframe& kf : s.keyframes) {
    o.all(kf.id, kf.stamp);
    o.pose(kf.T_A_C);
    o.all(kf.camera_id, static_cast<std::uint8_t>(kf.lost_before));
    o.count(kf.keypoints.size());
    for (const Keypoint& k : kf.keypoints) o.all(k.u, k.v, k.octave, k.depth);
    o.count(kf.descriptors.size());
    for (const Descriptor& d : kf.descriptors) o.put(d);
    o.count(kf.keypoint_landmark.size());
    for (LandmarkId id : kf.keypoint_landmark) o.put(id);
  }
  o.count(s.landmarks.size());
  for (const Landmark& l : s.landmarks) {
    o.put(l.id);
    for (int k = 0; k < 3; ++k) o.put(l.p_A[k]);
    o.put(l.descriptor);
    o.count(l.observations.size());
    for (const Observation& ob : l.observations) {
      o.put(ob.keyframe);
      o.put(ob.keypoint);
    }
  }
  o.count(s.odometry.size());
  for (const OdometryEdge& e : s.odometry) {
    o.put(e.from);
    o.put(e.to);
    o.pose(e.T_from_to);
    for (int k = 0; k < 36; ++k) o.put(e.information(k / 6, k % 6));
  }
}

// ---- reading ---------------------------------------------------------------

/// Bounds-checked reads; every failure is sticky and reads give zeros after it.
struct In {
  const std::uint8_t* p;
  std::size_t n, pos = 0;
  bool ok = true;

  template <class T>
  T get() {
    static_assert(std::is_trivially_copyable<T>::value, "plain values only");
    T v{};
    if (!ok || sizeof(T) > n - pos) {
      ok = false;
      return v;
    }
    std::memcpy(&v, p + pos, sizeof(T));
    pos += sizeof(T);
    return v;
  }
  /// A count of elements of at least `min_bytes` each that fit in what is left.
  std::size_t count(std::size_t min_bytes) {
    const auto c = get<std::uint64_t>();
    if (!ok || c > (n - pos) / min_bytes) {
      ok = false;
      return 0;
    }
    return static_cast<std::size_t>(c);
  }
  std::string text() {
    const auto len = get<std::uint32_t>();
    if (!ok || len > n - pos) {
      ok = false;
      return {};
    }
    std::string s(reinterpret_cast<const char*>(p + pos), len);
    pos += len;
    return s;
  }
  bool flag() {
    const auto b = get<std::uint8_t>();
    if (b > 1) ok = false;
    return b == 1;
  }
  SE3 pose() {
    double q[4], t[3];
    for (double& v : q) v = get<double>();
    for (double& v : t) v = get<double>();
    const Quat quat(q[0], q[1], q[2], q[3]);
    if (!ok || !std::isfinite(quat.norm()) || std::abs(quat.norm() - 1.0) > 1e-6 ||
        !std::isfinite(t[0] + t[1] + t[2])) {
      ok = false;
      return SE3();
    }
    return SE3::fromUnitQuat(quat, Vec3(t[0], t[1], t[2]));
  }
};

distill::TrackingHealth getHealth(In& in) {
  distill::TrackingHealth h;
  for (int* v : {&h.frames, &h.lost, &h.weak, &h.min_tracked}) *v = in.get<std::int32_t>();
  return h;
}

distill::MotionHint getMotion(In& in) {
  distill::MotionHint m;
  m.valid = in.flag();
  m.T_A_C = in.pose();
  m.T_Cprev_Ccurr = in.pose();
  m.dt_s = in.get<double>();
  m.camera_id = in.get<std::uint32_t>();
  m.health = getHealth(in);
  return m;
}

Submap getSubmap(In& in) {
  Submap s;
  s.header.agent = in.get<Uuid>();
  s.header.session = in.get<std::uint32_t>();
  s.header.seq = in.get<std::uint64_t>();
  s.header.t_start = in.get<double>();
  s.header.t_end = in.get<double>();
  s.cameras.resize(in.count(40));
  for (PinholeIntrinsics& K : s.cameras) {
    for (double* v : {&K.fx, &K.fy, &K.cx, &K.cy}) *v = in.get<double>();
    K.width = in.get<std::int32_t>();
    K.height = in.get<std::int32_t>();
  }
  s.keyframes.resize(in.count(97));
  for (Keyframe& kf : s.keyframes) {
    kf.id = in.get<KeyframeId>();
    kf.stamp = in.get<double>();
    kf.T_A_C = in.pose();
    kf.camera_id = in.get<std::uint32_t>();
    kf.lost_before = in.flag();
    kf.keypoints.resize(in.count(13));
    for (Keypoint& k : kf.keypoints) {
      k.u = in.get<float>();
      k.v = in.get<float>();
      k.octave = in.get<std::uint8_t>();
      k.depth = in.get<float>();
    }
    kf.descriptors.resize(in.count(sizeof(Descriptor)));
    for (Descriptor& d : kf.descriptors) d = in.get<Descriptor>();
    kf.keypoint_landmark.resize(in.count(8));
    for (LandmarkId& id : kf.keypoint_landmark) id = in.get<LandmarkId>();
    if (!in.ok) break;
  }
  s.landmarks.resize(in.count(72));
  for (Landmark& l : s.landmarks) {
    l.id = in.get<LandmarkId>();
    for (int k = 0; k < 3; ++k) l.p_A[k] = in.get<double>();
    l.descriptor = in.get<Descriptor>();
    l.observations.resize(in.count(12));
    for (Observation& ob : l.observations) {
      ob.keyframe = in.get<KeyframeId>();
      ob.keypoint = in.get<std::uint32_t>();
    }
    if (!in.ok) break;
  }
  s.odometry.resize(in.count(16 + 56 + 288));
  for (OdometryEdge& e : s.odometry) {
    e.from = in.get<KeyframeId>();
    e.to = in.get<KeyframeId>();
    e.T_from_to = in.pose();
    for (int k = 0; k < 36; ++k) e.information(k / 6, k % 6) = in.get<double>();
  }
  return s;
}

Status decodeStep(In& in, TrackingStep* step) {
  step->flush = in.flag();
  step->stamp = in.get<double>();
  const auto status = in.get<std::uint8_t>();
  if (status > static_cast<std::uint8_t>(TrackingStatus::kLost)) return Error{"bad tracking status"};
  step->status = static_cast<TrackingStatus>(status);
  step->T_W_B = in.pose();
  step->motion = getMotion(in);
  if (in.flag()) step->window = getSubmap(in);
  if (!in.ok) return Error{"damaged step"};
  if (!std::isfinite(step->stamp)) return Error{"non-finite stamp"};
  return Status::Ok();
}

TrackingKey getKey(In& in) {
  TrackingKey key;
  const auto n = in.get<std::uint32_t>();
  for (std::uint32_t i = 0; i < n && in.ok; ++i) {
    std::string name = in.text();
    std::string value = in.text();
    key.add(name, value);
  }
  return key;
}

std::string at(const std::string& what, std::size_t record, std::size_t offset) {
  return "tracking recording " + what + ": record " + std::to_string(record) + " at byte " +
         std::to_string(offset);
}

}  // namespace

std::string textHash(const std::string& text) {
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : text) {
    h ^= c;
    h *= 1099511628211ull;
  }
  char buf[17];
  std::snprintf(buf, sizeof(buf), "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

Status TrackingKey::matches(const TrackingKey& expected) const {
  for (const auto& [name, want] : expected.fields) {
    auto it = std::find_if(fields.begin(), fields.end(),
                           [&](const auto& f) { return f.first == name; });
    if (it == fields.end()) return Error{"the recording has no field '" + name + "'"};
    if (it->second != want)
      return Error{"'" + name + "' differs: recorded '" + it->second + "', this run '" + want + "'"};
  }
  if (fields.size() != expected.fields.size())
    return Error{"the recording's key has " + std::to_string(fields.size()) +
                 " fields, this run's " + std::to_string(expected.fields.size())};
  return Status::Ok();
}

void encodeSubmapLossless(const Submap& submap, std::vector<std::uint8_t>* out) {
  Out o{out};
  putSubmap(o, submap);
}

Expected<std::unique_ptr<TrackingLogWriter>> TrackingLogWriter::create(const std::string& path,
                                                                       const TrackingKey& key) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return Error{"cannot create tracking recording " + path};
  out.write(kMagic, 4);
  const std::uint16_t version = kTrackingLogVersion;
  out.write(reinterpret_cast<const char*>(&version), sizeof(version));
  std::unique_ptr<TrackingLogWriter> w(new TrackingLogWriter(path, std::move(out)));
  std::vector<std::uint8_t> payload;
  Out o{&payload};
  o.put(static_cast<std::uint32_t>(key.fields.size()));
  for (const auto& [name, value] : key.fields) {
    o.text(name);
    o.text(value);
  }
  if (Status s = w->writeRecord(kKey, payload); !s) return Error{s.error()};
  return w;
}

Status TrackingLogWriter::writeRecord(std::uint8_t type, const std::vector<std::uint8_t>& payload) {
  std::vector<std::uint8_t> head;
  Out o{&head};
  o.put(type);
  o.put(static_cast<std::uint32_t>(payload.size()));
  std::uint32_t crc = crc32(head.data(), head.size());
  crc = crc32(payload.data(), payload.size(), crc);
  out_.write(reinterpret_cast<const char*>(head.data()), static_cast<std::streamsize>(head.size()));
  out_.write(reinterpret_cast<const char*>(payload.data()), static_cast<std::streamsize>(payload.size()));
  out_.write(reinterpret_cast<const char*>(&crc), sizeof(crc));
  if (!out_) return Error{"error writing tracking recording " + path_};
  return Status::Ok();
}

Status TrackingLogWriter::append(const TrackingStep& step) {
  std::vector<std::uint8_t> payload;
  Out o{&payload};
  o.put(static_cast<std::uint8_t>(step.flush));
  o.put(step.stamp);
  o.put(static_cast<std::uint8_t>(step.status));
  o.pose(step.T_W_B);
  putMotion(o, step.motion);
  o.put(static_cast<std::uint8_t>(step.window.has_value()));
  if (step.window) putSubmap(o, *step.window);
  return writeRecord(kStep, payload);
}

Status TrackingLogWriter::close(const TrackingSummary& summary) {
  std::vector<std::uint8_t> payload;
  Out o{&payload};
  for (std::int64_t v : {summary.frames, summary.lost, summary.keyframes, summary.landmarks}) o.put(v);
  putHealth(o, summary.total_health);
  if (Status s = writeRecord(kSummary, payload); !s) return s;
  out_.close();
  if (!out_) return Error{"error closing tracking recording " + path_};
  return Status::Ok();
}

namespace {

/// Magic and version at the start of `bytes`.
Status checkPreamble(const std::vector<std::uint8_t>& bytes, const std::string& what) {
  if (bytes.size() < 6 || std::memcmp(bytes.data(), kMagic, 4) != 0)
    return Error{"tracking recording " + what + ": not a tracking recording (no HTRK magic)"};
  std::uint16_t version = 0;
  std::memcpy(&version, bytes.data() + 4, sizeof(version));
  if (version != kTrackingLogVersion)
    return Error{"tracking recording " + what + ": version " + std::to_string(version) +
                 ", this build reads " + std::to_string(kTrackingLogVersion)};
  return Status::Ok();
}

struct Record {
  std::uint8_t type = 0;
  In payload{nullptr, 0};
  std::size_t end = 0;  ///< offset after the record
};

/// The record at `pos`, its CRC checked. Errors start with `where`.
Expected<Record> recordAt(const std::vector<std::uint8_t>& bytes, std::size_t pos,
                          const std::string& where) {
  if (bytes.size() - pos < 5 + 4) return Error{where + ": truncated"};
  In head{bytes.data() + pos, 5};
  Record r;
  r.type = head.get<std::uint8_t>();
  const auto size = head.get<std::uint32_t>();
  if (size > bytes.size() - pos - 9) return Error{where + ": truncated"};
  std::uint32_t stored = 0;
  std::memcpy(&stored, bytes.data() + pos + 5 + size, sizeof(stored));
  if (crc32(bytes.data() + pos, 5 + size) != stored) return Error{where + ": CRC mismatch (damaged)"};
  r.payload = In{bytes.data() + pos + 5, size};
  r.end = pos + 5 + size + 4;
  return r;
}

}  // namespace

Expected<TrackingLog> decodeTrackingLog(const std::vector<std::uint8_t>& bytes,
                                        const std::string& what) {
  if (Status s = checkPreamble(bytes, what); !s) return Error{s.error()};
  TrackingLog log;
  bool have_key = false, have_summary = false;
  std::size_t pos = 6;
  for (std::size_t record = 0; pos < bytes.size(); ++record) {
    const std::string where = at(what, record, pos);
    if (have_summary) return Error{where + ": data after the summary record"};
    auto rec = recordAt(bytes, pos, where);
    if (!rec) return Error{rec.error()};
    In& in = rec->payload;
    const std::uint8_t type = rec->type;
    if (!have_key && type != kKey) return Error{where + ": the key record must come first"};
    if (type == kKey) {
      if (have_key) return Error{where + ": a second key record"};
      log.key = getKey(in);
      have_key = true;
    } else if (type == kStep) {
      TrackingStep step;
      if (Status s = decodeStep(in, &step); !s) return Error{where + ": " + s.error()};
      log.steps.push_back(std::move(step));
    } else if (type == kSummary) {
      TrackingSummary& s = log.summary;
      for (std::int64_t* v : {&s.frames, &s.lost, &s.keyframes, &s.landmarks}) *v = in.get<std::int64_t>();
      s.total_health = getHealth(in);
      have_summary = true;
    } else {
      return Error{where + ": unknown record type " + std::to_string(type)};
    }
    if (!in.ok || in.pos != in.n) return Error{where + ": damaged record (bad length or value)"};
    pos = rec->end;
  }
  if (!have_summary)
    return Error{"tracking recording " + what +
                 ": ends without its summary record (truncated, or the recording run did not finish)"};
  return log;
}

Expected<TrackingLog> readTrackingLog(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{"cannot open tracking recording " + path};
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return Error{"error reading tracking recording " + path};
  return decodeTrackingLog(bytes, path);
}

Expected<TrackingKey> readTrackingKey(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) return Error{"cannot open tracking recording " + path};
  std::vector<std::uint8_t> bytes(6 + 5);
  file.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  if (!file) return Error{"tracking recording " + path + ": truncated before its key"};
  if (Status s = checkPreamble(bytes, path); !s) return Error{s.error()};
  std::uint32_t size = 0;
  std::memcpy(&size, bytes.data() + 7, sizeof(size));
  if (bytes[6] != kKey || size > (1u << 20)) return Error{"tracking recording " + path + ": no key record first"};
  bytes.resize(bytes.size() + size + 4);
  file.read(reinterpret_cast<char*>(bytes.data() + 11), static_cast<std::streamsize>(size + 4));
  if (!file) return Error{"tracking recording " + path + ": truncated in its key"};
  auto rec = recordAt(bytes, 6, at(path, 0, 6));
  if (!rec) return Error{rec.error()};
  TrackingKey key = getKey(rec->payload);
  if (!rec->payload.ok || rec->payload.pos != rec->payload.n)
    return Error{at(path, 0, 6) + ": damaged key"};
  return key;
}

void shiftTrackingLog(TrackingLog* log, double dt_s) {
  for (TrackingStep& step : log->steps) {
    step.stamp += dt_s;
    if (!step.window) continue;
    step.window->header.t_start += dt_s;
    step.window->header.t_end += dt_s;
    for (Keyframe& kf : step.window->keyframes) kf.stamp += dt_s;
  }
}

}  // namespace hermes::agent
