// Ray casting against axis-aligned boxes with trilinear mip-mapped texture
// sampling (footprint-based level selection) and edge supersampling.
#include "hermes/core/render/raycaster.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace hermes {
namespace render {

namespace {
/// log2 with ~0.005 absolute error (exponent + quadratic mantissa fit); x > 0.
inline float fastLog2(float x) {
  std::uint32_t i;
  std::memcpy(&i, &x, 4);
  const float e = static_cast<float>(static_cast<int>((i >> 23) & 255) - 128);
  i = (i & 0x7FFFFFu) | 0x3F800000u;
  float m;
  std::memcpy(&m, &i, 4);
  return e + (-0.34484843f * m + 2.02466578f) * m - 0.67487759f;
}

/// Simple fixed lighting: brightness per face orientation (2*axis + side).
constexpr float kFaceLight[6] = {1.0f, 0.88f, 0.93f, 0.8f, 0.85f, 0.72f};

inline int fastFloor(float x) {
  const int i = static_cast<int>(x);
  return i - (x < static_cast<float>(i));
}

/// Bilinear sample of one mip level at continuous level-0 texel coordinates
/// (x, y) (texel i covers [i, i+1)). cv::pyrDown centres level-L texel j on
/// level-0 texel index 2^L j, i.e. continuous coordinate 2^L j + 0.5.
template <class L>
inline float sampleLevel(const L& m, float x, float y, float inv_scale) {
  const float fx = (x - 0.5f) * inv_scale, fy = (y - 0.5f) * inv_scale;
  int x0 = fastFloor(fx), y0 = fastFloor(fy);
  const float ax = fx - x0, ay = fy - y0;
  int x1 = x0 + 1, y1 = y0 + 1;
  const int wm = m.w - 1, hm = m.h - 1;
  x0 = std::clamp(x0, 0, wm);
  x1 = std::clamp(x1, 0, wm);
  y0 = std::clamp(y0, 0, hm);
  y1 = std::clamp(y1, 0, hm);
  const std::uint8_t* r0 = m.data + y0 * m.step;
  const std::uint8_t* r1 = m.data + y1 * m.step;
  const float top = r0[x0] + ax * (r0[x1] - r0[x0]);
  const float bot = r1[x0] + ax * (r1[x1] - r1[x0]);
  return top + ay * (bot - top);
}

}  // namespace

// ---------------------------------------------------------------- RayGrid
RayGrid RayGrid::fromRadtan(const PinholeRadtan& cam) {
  RayGrid g;
  g.w_ = cam.K.width;
  g.h_ = cam.K.height;
  g.ray_.resize(static_cast<std::size_t>(g.w_) * g.h_);
  for (int v = 0; v < g.h_; ++v)
    for (int u = 0; u < g.w_; ++u) {
      const Vec2 xd((u - cam.K.cx) / cam.K.fx, (v - cam.K.cy) / cam.K.fy);
      const Vec2 xn = cam.undistortNormalized(xd);
      g.ray_[static_cast<std::size_t>(v) * g.w_ + u] = Eigen::Vector3f(xn.x(), xn.y(), 1.0f);
    }
  g.finish();
  return g;
}

RayGrid RayGrid::fromPinhole(const PinholeIntrinsics& K) {
  RayGrid g;
  g.w_ = K.width;
  g.h_ = K.height;
  g.ray_.resize(static_cast<std::size_t>(g.w_) * g.h_);
  for (int v = 0; v < g.h_; ++v)
    for (int u = 0; u < g.w_; ++u)
      g.ray_[static_cast<std::size_t>(v) * g.w_ + u] =
          Eigen::Vector3f((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0f);
  g.finish();
  return g;
}

void RayGrid::finish() {
  auto at = [&](int u, int v) -> const Eigen::Vector3f& {
    u = std::clamp(u, 0, w_ - 1);
    v = std::clamp(v, 0, h_ - 1);
    return ray_[static_cast<std::size_t>(v) * w_ + u];
  };
  pix_angle_.resize(ray_.size());
  for (int v = 0; v < h_; ++v)
    for (int u = 0; u < w_; ++u) {
      const Eigen::Vector3f c = at(u, v).normalized();
      const int du = u + 1 < w_ ? 1 : -1, dv = v + 1 < h_ ? 1 : -1;
      const float ah = (at(u + du, v).normalized() - c).norm();
      const float av = (at(u, v + dv).normalized() - c).norm();
      pix_angle_[static_cast<std::size_t>(v) * w_ + u] = std::sqrt(ah * av);
    }
  // Local Jacobian of the normalised coordinates by central differences, inverted.
  jinv_.resize(ray_.size());
  for (int v = 0; v < h_; ++v)
    for (int u = 0; u < w_; ++u) {
      const int ul = std::max(u - 1, 0), ur = std::min(u + 1, w_ - 1);
      const int vt = std::max(v - 1, 0), vb = std::min(v + 1, h_ - 1);
      const Eigen::Vector3f ju = (at(ur, v) - at(ul, v)) / static_cast<float>(std::max(ur - ul, 1));
      const Eigen::Vector3f jv = (at(u, vb) - at(u, vt)) / static_cast<float>(std::max(vb - vt, 1));
      const float det = ju.x() * jv.y() - jv.x() * ju.y();
      jinv_[static_cast<std::size_t>(v) * w_ + u] =
          std::abs(det) > 1e-12f ? Eigen::Vector4f(jv.y() / det, -jv.x() / det, -ju.y() / det, ju.x() / det)
                                 : Eigen::Vector4f::Zero();
    }
  tiles_x_ = (w_ + kTile - 1) / kTile;
  tiles_y_ = (h_ + kTile - 1) / kTile;
  tiles_.resize(static_cast<std::size_t>(tiles_x_) * tiles_y_);
  for (int ty = 0; ty < tiles_y_; ++ty)
    for (int tx = 0; tx < tiles_x_; ++tx) {
      // Cone over the tile grown by one pixel (edge supersampling reaches +-0.5 px).
      const int u0 = tx * kTile - 1, v0 = ty * kTile - 1;
      const int u1 = std::min(w_, (tx + 1) * kTile + 1), v1 = std::min(h_, (ty + 1) * kTile + 1);
      Eigen::Vector3f axis = Eigen::Vector3f::Zero();
      for (int v = v0; v <= v1; ++v)
        for (int u = u0; u <= u1; ++u) axis += at(u, v).normalized();
      axis.normalize();
      float cmin = 1;
      for (int v = v0; v <= v1; ++v)
        for (int u = u0; u <= u1; ++u) cmin = std::min(cmin, axis.dot(at(u, v).normalized()));
      Tile& t = tiles_[static_cast<std::size_t>(ty) * tiles_x_ + tx];
      t.axis = axis;
      t.half = std::acos(std::clamp(cmin, -1.0f, 1.0f)) + 1e-3f;
      t.cos_half = std::cos(t.half);
    }
}

// -------------------------------------------------------------- Raycaster
struct Raycaster::Hit {
  float t;
  int box;   ///< -1 = room
  int face;  ///< 2*axis + side
};

Raycaster::Raycaster(const Scene& scene, RayGrid rays) : scene_(scene), rays_(std::move(rays)) {
  for (const MipTexture& t : scene_.textures) {
    levels_.emplace_back();
    for (const cv::Mat& m : t.levels)
      levels_.back().push_back(Level{m.ptr<std::uint8_t>(), m.cols, m.rows, m.step[0]});
  }
  room_lo_ = scene_.room.lo.cast<float>();
  room_hi_ = scene_.room.hi.cast<float>();
  inv_texel_ = static_cast<float>(1.0 / scene_.texel_m);
  for (const SceneBox& b : scene_.objects) {
    lo_.push_back(b.lo.cast<float>());
    hi_.push_back(b.hi.cast<float>());
    centre_.push_back((0.5 * (b.lo + b.hi)).cast<float>());
    radius_.push_back(static_cast<float>(0.5 * (b.hi - b.lo).norm()) + 1e-3f);
  }
}

void Raycaster::placeMovers(double t) {
  for (const MovingObject& m : scene_.movers) {
    const SceneBox& b = scene_.objects[m.object];
    const Vec3 off = m.offsetAt(t);
    lo_[m.object] = (b.lo + off).cast<float>();
    hi_[m.object] = (b.hi + off).cast<float>();
    centre_[m.object] = (0.5 * (b.lo + b.hi) + off).cast<float>();
  }
}

void Raycaster::castRay(const Eigen::Vector3f& o, const Eigen::Vector3f& d, float /*range_scale*/,
                        const int* cand, int ncand, Hit* hit) const {
  Eigen::Vector3f inv;
  for (int k = 0; k < 3; ++k) {
    const float dk = std::abs(d[k]) < 1e-12f ? (d[k] < 0 ? -1e-12f : 1e-12f) : d[k];
    inv[k] = 1.0f / dk;
  }
  // Room, seen from inside: the exit of the slab box.
  const Eigen::Vector3f& rlo = room_lo_;
  const Eigen::Vector3f& rhi = room_hi_;
  float best = 3.4e38f;
  int axis = 0;
  for (int k = 0; k < 3; ++k) {
    const float tk = ((inv[k] > 0 ? rhi[k] : rlo[k]) - o[k]) * inv[k];
    if (tk < best) {
      best = tk;
      axis = k;
    }
  }
  hit->t = best;
  hit->box = -1;
  hit->face = 2 * axis + (inv[axis] > 0 ? 1 : 0);
  for (int c = 0; c < ncand; ++c) {
    const Eigen::Vector3f& blo = lo_[cand[c]];
    const Eigen::Vector3f& bhi = hi_[cand[c]];
    float tnear = 0, tfar = hit->t;
    int near_axis = -1;
    bool ok = true;
    for (int k = 0; k < 3 && ok; ++k) {
      float t0 = (blo[k] - o[k]) * inv[k];
      float t1 = (bhi[k] - o[k]) * inv[k];
      if (t0 > t1) std::swap(t0, t1);
      if (t0 > tnear) {
        tnear = t0;
        near_axis = k;
      }
      tfar = std::min(tfar, t1);
      ok = tnear <= tfar;
    }
    if (ok && near_axis >= 0 && tnear < hit->t) {
      hit->t = tnear;
      hit->box = cand[c];
      hit->face = 2 * near_axis + (inv[near_axis] > 0 ? 0 : 1);
    }
  }
}

float Raycaster::shade(const Eigen::Vector3f& o, const Eigen::Vector3f& d, const Hit& hit,
                       float pix_angle, float ray_norm) const {
  const SceneBox& b = hit.box < 0 ? scene_.room : scene_.objects[hit.box];
  const int tex_id = b.texture[hit.face];
  if (tex_id < 0) return 0.0f;
  const std::vector<Level>& tex = levels_[tex_id];
  const int a = hit.face / 2, ua = (a + 1) % 3, va = (a + 2) % 3;
  const float inv_texel = inv_texel_;
  const Eigen::Vector3f p = o + hit.t * d;
  const Eigen::Vector3f& lo = hit.box < 0 ? room_lo_ : lo_[hit.box];
  const float x = (p[ua] - lo[ua]) * inv_texel;
  const float y = (p[va] - lo[va]) * inv_texel;
  // Footprint: pixel angle x range, stretched by obliquity (exponent < 1 keeps
  // grazing floors from blurring away entirely; aliasing stays negligible).
  const float cos_inc = std::max(std::abs(d[a]) / ray_norm, 0.05f);
  const float lod_raw =
      fastLog2(pix_angle * hit.t * ray_norm * inv_texel) - 0.75f * fastLog2(cos_inc);
  // Light: faces seen from inside the room face the opposite way of objects' faces.
  const int lf = hit.box < 0 ? (hit.face ^ 1) : hit.face;
  const float light = kFaceLight[lf];
  const int nlev = static_cast<int>(tex.size());
  if (lod_raw <= 0.0f) return light * sampleLevel(tex[0], x, y, 1.0f);
  const float lod = std::min(lod_raw, static_cast<float>(nlev - 1));
  const int l0 = std::min(static_cast<int>(lod), nlev - 1);
  const int l1 = std::min(l0 + 1, nlev - 1);
  const float f = lod - l0;
  const float s0 = sampleLevel(tex[l0], x, y, 1.0f / static_cast<float>(1 << l0));
  if (f < 1e-3f || l1 == l0) return light * s0;
  const float s1 = sampleLevel(tex[l1], x, y, 1.0f / static_cast<float>(1 << l1));
  return light * (s0 + f * (s1 - s0));
}

void Raycaster::render(const SE3& T_W_C, RenderOutput* out, bool want_depth, bool want_face) const {
  const int w = rays_.w_, h = rays_.h_;
  out->radiance.create(h, w, CV_32F);
  out->face.create(h, w, CV_32S);  // always filled: the edge pass needs it
  cv::Mat& face = out->face;
  if (want_depth) out->depth.create(h, w, CV_32F);
  cv::Mat& depth = out->depth;
  const Eigen::Matrix3f R = T_W_C.rotation().cast<float>();
  const Eigen::Vector3f o = T_W_C.translation().cast<float>();
  const int nobj = static_cast<int>(scene_.objects.size());
  std::vector<int> cand(nobj);
  std::vector<int> all(nobj);
  for (int i = 0; i < nobj; ++i) all[i] = i;

  for (int ty = 0; ty < rays_.tiles_y_; ++ty)
    for (int tx = 0; tx < rays_.tiles_x_; ++tx) {
      const RayGrid::Tile& tile = rays_.tiles_[static_cast<std::size_t>(ty) * rays_.tiles_x_ + tx];
      const Eigen::Vector3f axis = R * tile.axis;
      int ncand = 0;
      for (int i = 0; i < nobj; ++i) {
        const Eigen::Vector3f v = centre_[i] - o;
        const float dist = v.norm();
        if (dist <= radius_[i]) {
          cand[ncand++] = i;
          continue;
        }
        const float beta = std::acos(std::clamp(v.dot(axis) / dist, -1.0f, 1.0f));
        const float gamma = std::asin(radius_[i] / dist);
        if (beta <= tile.half + gamma) cand[ncand++] = i;
      }
      const int u1 = std::min(w, (tx + 1) * RayGrid::kTile);
      const int v1 = std::min(h, (ty + 1) * RayGrid::kTile);
      for (int v = ty * RayGrid::kTile; v < v1; ++v) {
        float* rad = out->radiance.ptr<float>(v);
        int* fc = face.ptr<int>(v);
        float* dp = want_depth ? depth.ptr<float>(v) : nullptr;
        for (int u = tx * RayGrid::kTile; u < u1; ++u) {
          const std::size_t idx = static_cast<std::size_t>(v) * w + u;
          const Eigen::Vector3f d = R * rays_.ray_[idx];
          const float dn = d.norm();
          Hit hit;
          castRay(o, d, dn, cand.data(), ncand, &hit);
          rad[u] = shade(o, d, hit, rays_.pix_angle_[idx], dn);
          fc[u] = (hit.box + 1) * 6 + hit.face;
          if (dp) dp[u] = hit.t;
        }
      }
    }

  // Anti-alias silhouettes and face boundaries: 4 sub-rays where the hit face changes.
  auto rayAt = [&](float uf, float vf) {
    uf = std::clamp(uf, 0.0f, static_cast<float>(w - 1));
    vf = std::clamp(vf, 0.0f, static_cast<float>(h - 1));
    const int u0 = std::min(static_cast<int>(uf), w - 2), v0 = std::min(static_cast<int>(vf), h - 2);
    const float a = uf - u0, b = vf - v0;
    const auto& r00 = rays_.ray_[static_cast<std::size_t>(v0) * w + u0];
    const auto& r10 = rays_.ray_[static_cast<std::size_t>(v0) * w + u0 + 1];
    const auto& r01 = rays_.ray_[static_cast<std::size_t>(v0 + 1) * w + u0];
    const auto& r11 = rays_.ray_[static_cast<std::size_t>(v0 + 1) * w + u0 + 1];
    return Eigen::Vector3f((1 - b) * ((1 - a) * r00 + a * r10) + b * ((1 - a) * r01 + a * r11));
  };
  out->scratch.create(h, w, CV_8U);
  out->scratch.setTo(0);
  cv::Mat& edge = out->scratch;
  for (int v = 0; v < h; ++v) {
    const int* f0 = face.ptr<int>(v);
    const int* f1 = v + 1 < h ? face.ptr<int>(v + 1) : nullptr;
    for (int u = 0; u < w; ++u) {
      if (u + 1 < w && f0[u] != f0[u + 1]) edge.at<std::uint8_t>(v, u) = edge.at<std::uint8_t>(v, u + 1) = 1;
      if (f1 && f0[u] != f1[u]) edge.at<std::uint8_t>(v, u) = edge.at<std::uint8_t>(v + 1, u) = 1;
    }
  }
  static const float kOff[4][2] = {{-0.25f, -0.25f}, {0.25f, -0.25f}, {-0.25f, 0.25f}, {0.25f, 0.25f}};
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      if (!edge.at<std::uint8_t>(v, u)) continue;
      const float pa = rays_.pix_angle_[static_cast<std::size_t>(v) * w + u];
      float acc = 0;
      for (const auto& off : kOff) {
        const Eigen::Vector3f d = R * rayAt(u + off[0], v + off[1]);
        const float dn = d.norm();
        Hit hit;
        castRay(o, d, dn, all.data(), nobj, &hit);
        acc += shade(o, d, hit, 0.5f * pa, dn);
      }
      out->radiance.at<float>(v, u) = 0.25f * acc;
    }
  (void)want_face;
}

}  // namespace render
}  // namespace hermes
