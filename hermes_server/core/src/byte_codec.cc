#include "hermes/server/byte_codec.h"

#include <cmath>

namespace hermes {
namespace server {

void ByteWriter::pose(const SE3& T) {
  const Quat& q = T.quat();
  for (double v : {q.x(), q.y(), q.z(), q.w()}) pod(v);
  vec3(T.translation());
}

void ByteWriter::key(const KeyframeKey& k) {
  pod(k.agent);
  pod(k.session);
  pod(k.id);
}

void ByteWriter::mat6(const Mat6& m) {
  for (int i = 0; i < 36; ++i) pod(m.data()[i]);
}

void ByteWriter::vec3(const Vec3& v) {
  for (int i = 0; i < 3; ++i) pod(v[i]);
}

void ByteWriter::text(const std::string& s) {
  count(s.size());
  out.insert(out.end(), s.begin(), s.end());
}

void ByteWriter::blob(const std::uint8_t* data, std::size_t size) {
  count(size);
  out.insert(out.end(), data, data + size);
}

bool ByteReader::flag(bool* b) {
  std::uint8_t v = 0;
  if (!pod(&v) || v > 1) return false;
  *b = v != 0;
  return true;
}

bool ByteReader::count(std::uint64_t* n, std::size_t min_element_bytes) {
  if (!pod(n)) return false;
  const std::uint64_t per = min_element_bytes > 0 ? min_element_bytes : 1;
  return *n <= remaining() / per;
}

bool ByteReader::pose(SE3* T) {
  double q[4];
  for (double& v : q)
    if (!pod(&v)) return false;
  Vec3 t;
  if (!vec3(&t)) return false;
  const Quat quat(q[3], q[0], q[1], q[2]);
  const double norm = quat.norm();
  if (!std::isfinite(norm) || norm < 1e-6) return false;
  *T = SE3(quat, t);
  return true;
}

bool ByteReader::mat6(Mat6* m) {
  for (int i = 0; i < 36; ++i)
    if (!pod(m->data() + i) || !std::isfinite(m->data()[i])) return false;
  return true;
}

bool ByteReader::vec3(Vec3* v) {
  for (int i = 0; i < 3; ++i)
    if (!pod(&(*v)[i]) || !std::isfinite((*v)[i])) return false;
  return true;
}

bool ByteReader::text(std::string* s) {
  std::uint64_t n = 0;
  if (!count(&n, 1)) return false;
  s->assign(reinterpret_cast<const char*>(data_ + pos_), static_cast<std::size_t>(n));
  pos_ += static_cast<std::size_t>(n);
  return true;
}

bool ByteReader::blob(std::vector<std::uint8_t>* b) {
  std::uint64_t n = 0;
  if (!count(&n, 1)) return false;
  b->assign(data_ + pos_, data_ + pos_ + n);
  pos_ += static_cast<std::size_t>(n);
  return true;
}

void saveTimings(ByteWriter* w, const TimingStats& t) {
  w->count(t.samples().size());
  for (const auto& [stage, samples] : t.samples()) {
    w->text(stage);
    w->count(samples.size());
    for (double v : samples) w->pod(v);
  }
}

bool loadTimings(ByteReader* r, TimingStats* t) {
  std::uint64_t stages = 0;
  if (!r->count(&stages, 16)) return false;
  for (std::uint64_t i = 0; i < stages; ++i) {
    std::string stage;
    std::uint64_t n = 0;
    if (!r->text(&stage) || !r->count(&n, 8)) return false;
    for (std::uint64_t k = 0; k < n; ++k) {
      double v = 0;
      if (!r->pod(&v) || !std::isfinite(v)) return false;
      t->add(stage, v);
    }
  }
  return true;
}

}  // namespace server
}  // namespace hermes
