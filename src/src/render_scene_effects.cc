// Scene effects: surface grain, aliasing copies of objects and dark zones
// baked into textures.
#include "render_scene_effects.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "hermes/core/render/sensor.h"

namespace hermes {
namespace render {

void addGrain(const SceneParams& p, Scene* s) {
  for (std::size_t t = 0; t < s->textures.size(); ++t) {
    const cv::Mat base = s->textures[t].levels[0];
    cv::Mat noise(base.size(), CV_32F);
    cv::RNG rng(mixSeed(p.seed, 0x9a1000 + t));
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
    cv::GaussianBlur(noise, noise, cv::Size(0, 0), p.grain_scale_texels);
    cv::Scalar mean, sd;
    cv::meanStdDev(noise, mean, sd);
    cv::Mat out;
    base.convertTo(out, CV_32F);
    out += noise * (sd[0] > 1e-6 ? p.grain_sigma / sd[0] : 0.0);
    out.convertTo(out, CV_8U);  // saturating
    s->textures[t] = MipTexture::fromImage(out);
  }
}

namespace {

/// Objects whose faces are richly textured (worth repeating or moving).
std::vector<int> richObjects(const Scene& s) {
  std::vector<int> out;
  for (int i = 0; i < static_cast<int>(s.objects.size()); ++i)
    if (s.objects[i].copy_of < 0 && s.texture_styles[s.objects[i].texture[0]] == TextureStyle::kRich)
      out.push_back(i);
  return out;
}

/// Gives b its own copies of its textures (same content).
void cloneTextures(SceneBox* b, Scene* s) {
  for (int f = 0; f < 6; ++f) {
    const int t = b->texture[f];
    if (t < 0) continue;
    b->texture[f] = static_cast<int>(s->textures.size());
    s->textures.push_back(MipTexture::fromImage(s->textures[t].levels[0].clone()));
    s->texture_styles.push_back(s->texture_styles[t]);
  }
}

}  // namespace

Vec3 MovingObject::offsetAt(double t) const {
  const double phase = t / period_s - std::floor(t / period_s);
  const double a = phase < 0.5 ? 2 * phase : 2 - 2 * phase;
  return a * (to - from);
}

void addMovers(const SceneParams& p, const std::vector<Vec3>& pts, Scene* s) {
  const std::vector<int> sources = richObjects(*s);
  if (sources.empty()) return;
  cv::RNG rng(mixSeed(p.seed, 0x30f3));
  const Vec3 room = s->room.hi - s->room.lo;
  for (int m = 0; m < p.moving_objects; ++m) {
    for (int attempt = 0; attempt < 200; ++attempt) {
      const SceneBox& src = s->objects[sources[rng.uniform(0, static_cast<int>(sources.size()))]];
      const Vec3 ext = (src.hi - src.lo).cwiseMin(Vec3(1.2, 1.2, 1.6));
      const double len = rng.uniform(2.0, 8.0), ang = rng.uniform(0.0, 6.283185307);
      const Vec3 step(len * std::cos(ang), len * std::sin(ang), 0.0);
      const Vec3 lo(rng.uniform(s->room.lo.x() + 0.2, s->room.hi.x() - 0.2 - ext.x()),
                    rng.uniform(s->room.lo.y() + 0.2, s->room.hi.y() - 0.2 - ext.y()), s->room.lo.z());
      SceneBox swept;
      swept.lo = lo.cwiseMin(lo + step);
      swept.hi = (lo + ext).cwiseMax(lo + ext + step);
      const bool in_room = (swept.lo.head<2>().array() > s->room.lo.head<2>().array() + 0.1).all() &&
                           (swept.hi.head<2>().array() < s->room.hi.head<2>().array() - 0.1).all();
      if (!in_room) continue;
      if ((ext.array() >= room.array()).any() || !placeable(*s, swept, pts, p.clearance_m)) continue;
      SceneBox b = src;
      b.lo = lo;
      b.hi = lo + ext;
      b.kind = "mover";
      cloneTextures(&b, s);
      s->objects.push_back(b);
      s->movers.push_back({static_cast<int>(s->objects.size()) - 1, lo, lo + step, 2.0 * len / p.moving_speed_mps});
      break;
    }
  }
}

void addAliasingCopies(const SceneParams& p, const std::vector<Vec3>& pts, Scene* s) {
  const std::vector<int> sources = richObjects(*s);
  if (sources.empty()) return;
  cv::RNG rng(mixSeed(p.seed, 0xa11a5));
  const Vec3 room = s->room.hi - s->room.lo;
  for (int c = 0; c < p.aliasing_copies; ++c) {
    const int src = sources[rng.uniform(0, static_cast<int>(sources.size()))];
    const SceneBox source = s->objects[src];
    const Vec3 ext = source.hi - source.lo;
    if ((ext.array() >= room.array() - 0.4).any()) continue;
    for (int attempt = 0; attempt < 80; ++attempt) {
      SceneBox b = source;
      b.copy_of = src;
      b.lo = Vec3(rng.uniform(s->room.lo.x() + 0.2, s->room.hi.x() - 0.2 - ext.x()),
                  rng.uniform(s->room.lo.y() + 0.2, s->room.hi.y() - 0.2 - ext.y()), source.lo.z());
      b.hi = b.lo + ext;
      if (!placeable(*s, b, pts, p.clearance_m)) continue;
      cloneTextures(&b, s);  // own entries: dark zones may darken them differently
      s->objects.push_back(b);
      break;
    }
  }
}

double darkFactor(const std::vector<DarkZone>& zones, const Vec3& x) {
  double f = 1.0;
  for (const DarkZone& z : zones) {
    const double r = (x - z.centre).norm() / z.radius_m;
    if (r >= 1.0) continue;
    const double a = 1.0 - r;                       // 1 at the centre, 0 at the rim
    const double smooth = a * a * (3.0 - 2.0 * a);  // smoothstep
    f *= 1.0 - (1.0 - z.level) * smooth;
  }
  return f;
}

namespace {

/// Darkens the texture of face f of box b by the zones (factor computed every
/// `step` texels and interpolated: the zones are metres wide).
void darkenFace(const SceneBox& b, int f, double texel_m, const std::vector<DarkZone>& zones, Scene* s) {
  const int t = b.texture[f];
  if (t < 0) return;
  cv::Mat tex = s->textures[t].levels[0];
  const int a = f / 2, ua = (a + 1) % 3, va = (a + 2) % 3;
  const double plane = (f % 2) ? b.hi[a] : b.lo[a];
  constexpr int step = 16;
  const int gw = tex.cols / step + 2, gh = tex.rows / step + 2;
  cv::Mat grid(gh, gw, CV_32F);
  bool any = false;
  for (int j = 0; j < gh; ++j)
    for (int i = 0; i < gw; ++i) {
      Vec3 x;
      x[a] = plane;
      x[ua] = b.lo[ua] + i * step * texel_m;
      x[va] = b.lo[va] + j * step * texel_m;
      const float k = static_cast<float>(darkFactor(zones, x));
      grid.at<float>(j, i) = k;
      any = any || k < 0.999f;
    }
  if (!any) return;
  cv::Mat full;
  cv::resize(grid, full, cv::Size((gw - 1) * step, (gh - 1) * step), 0, 0, cv::INTER_LINEAR);
  cv::Mat out(tex.size(), CV_8U);
  for (int v = 0; v < tex.rows; ++v) {
    const std::uint8_t* in = tex.ptr<std::uint8_t>(v);
    const float* k = full.ptr<float>(v);
    std::uint8_t* o = out.ptr<std::uint8_t>(v);
    for (int u = 0; u < tex.cols; ++u) o[u] = cv::saturate_cast<std::uint8_t>(in[u] * k[u]);
  }
  s->textures[t] = MipTexture::fromImage(out);
}

}  // namespace

void addDarkZones(const SceneParams& p, const std::vector<Vec3>& pts, Scene* s) {
  if (pts.empty()) return;
  cv::RNG rng(mixSeed(p.seed, 0xda4c));
  for (int i = 0; i < p.dark_zones; ++i) {
    DarkZone z;
    z.centre = pts[rng.uniform(0, static_cast<int>(pts.size()))];
    z.radius_m = p.dark_radius_m;
    z.level = p.dark_level;
    s->dark_zones.push_back(z);
  }
  for (int f = 0; f < 6; ++f) darkenFace(s->room, f, s->texel_m, s->dark_zones, s);
  for (const SceneBox& b : s->objects)
    for (int f = 0; f < 6; ++f) darkenFace(b, f, s->texel_m, s->dark_zones, s);
}

}  // namespace render
}  // namespace hermes
