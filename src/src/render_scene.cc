// Procedural hall around camera paths: room box, inner objects with clearance,
// one synthesised texture per face.
#include "hermes/core/render/scene.h"

#include <algorithm>
#include <cmath>
#include <unordered_set>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "hermes/core/render/sensor.h"
#include "render_scene_effects.h"

namespace hermes {
namespace render {

Status SceneParams::validate() const {
  if (!(wall_margin_m > clearance_m)) return Error{"scene: wall_margin_m must exceed clearance_m"};
  if (!(floor_margin_m > 0) || !(ceiling_margin_m > 0))
    return Error{"scene: floor_margin_m and ceiling_margin_m must be > 0"};
  if (!(clearance_m >= 0)) return Error{"scene: clearance_m must be >= 0"};
  if (num_objects < 0 || num_objects > 200) return Error{"scene: num_objects must be in [0, 200]"};
  if (!(texel_m >= 1e-3 && texel_m <= 0.1)) return Error{"scene: texel_m must be in [0.001, 0.1]"};
  if (!(poor_fraction >= 0 && poor_fraction <= 1)) return Error{"scene: poor_fraction must be in [0, 1]"};
  if (dark_zones < 1 || dark_zones > 50) return Error{"scene: dark_zones must be in [1, 50]"};
  if (!(dark_radius_m > 0 && dark_radius_m <= 100)) return Error{"scene: dark_radius_m must be in (0, 100]"};
  if (!(dark_level >= 0 && dark_level <= 1)) return Error{"scene: dark_level must be in [0, 1]"};
  if (!(grain_sigma >= 0 && grain_sigma <= 50)) return Error{"scene: grain_sigma must be in [0, 50]"};
  if (!(grain_scale_texels >= 0.3 && grain_scale_texels <= 20))
    return Error{"scene: grain_scale_texels must be in [0.3, 20]"};
  if (moving_objects < 0 || moving_objects > 20) return Error{"scene: moving_objects must be in [0, 20]"};
  if (!(moving_speed_mps > 0 && moving_speed_mps <= 20)) return Error{"scene: moving_speed_mps must be in (0, 20]"};
  if (aliasing_copies < 1 || aliasing_copies > 50) return Error{"scene: aliasing_copies must be in [1, 50]"};
  return Status::Ok();
}

Status SceneParams::read(const Config& c, const std::string& prefix) {
  int seed_i = static_cast<int>(seed);
  for (Status st : {c.get(prefix + ".seed", &seed_i), c.get(prefix + ".wall_margin_m", &wall_margin_m),
                    c.get(prefix + ".floor_margin_m", &floor_margin_m),
                    c.get(prefix + ".ceiling_margin_m", &ceiling_margin_m),
                    c.get(prefix + ".clearance_m", &clearance_m), c.get(prefix + ".num_objects", &num_objects),
                    c.get(prefix + ".texel_m", &texel_m), c.get(prefix + ".poor_fraction", &poor_fraction),
                    c.get(prefix + ".poor_walls", &poor_walls), c.get(prefix + ".photo_folder", &photo_folder),
                    c.get(prefix + ".dark_regions", &dark_regions), c.get(prefix + ".dark_zones", &dark_zones),
                    c.get(prefix + ".dark_radius_m", &dark_radius_m), c.get(prefix + ".dark_level", &dark_level),
                    c.get(prefix + ".grain", &grain), c.get(prefix + ".grain_sigma", &grain_sigma),
                    c.get(prefix + ".grain_scale_texels", &grain_scale_texels),
                    c.get(prefix + ".moving_objects", &moving_objects),
                    c.get(prefix + ".moving_speed_mps", &moving_speed_mps),
                    c.get(prefix + ".aliasing", &aliasing), c.get(prefix + ".aliasing_copies", &aliasing_copies)})
    if (!st) return st;
  if (seed_i < 0) return Error{prefix + ".seed must be >= 0 (" + c.origin() + ")"};
  seed = static_cast<std::uint64_t>(seed_i);
  if (Status st = validate(); !st) return Error{st.error() + " (" + c.origin() + ")"};
  return Status::Ok();
}

void SceneParams::write(ConfigWriter* w, const std::string& prefix) const {
  w->set(prefix + ".seed", static_cast<int>(seed));
  w->set(prefix + ".wall_margin_m", wall_margin_m);
  w->set(prefix + ".floor_margin_m", floor_margin_m);
  w->set(prefix + ".ceiling_margin_m", ceiling_margin_m);
  w->set(prefix + ".clearance_m", clearance_m);
  w->set(prefix + ".num_objects", num_objects);
  w->set(prefix + ".texel_m", texel_m);
  w->set(prefix + ".poor_fraction", poor_fraction);
  w->set(prefix + ".poor_walls", poor_walls);
  w->set(prefix + ".photo_folder", photo_folder);
  w->set(prefix + ".dark_regions", dark_regions);
  w->set(prefix + ".dark_zones", dark_zones);
  w->set(prefix + ".dark_radius_m", dark_radius_m);
  w->set(prefix + ".dark_level", dark_level);
  w->set(prefix + ".grain", grain);
  w->set(prefix + ".grain_sigma", grain_sigma);
  w->set(prefix + ".grain_scale_texels", grain_scale_texels);
  w->set(prefix + ".moving_objects", moving_objects);
  w->set(prefix + ".moving_speed_mps", moving_speed_mps);
  w->set(prefix + ".aliasing", aliasing);
  w->set(prefix + ".aliasing_copies", aliasing_copies);
}

double distanceToBox(const Vec3& p, const Vec3& lo, const Vec3& hi) {
  const Vec3 d = (lo - p).cwiseMax(p - hi).cwiseMax(Vec3::Zero());
  return d.norm();
}

double clearance(const Scene& s, const Vec3& p) {
  double c = std::min((p - s.room.lo).minCoeff(), (s.room.hi - p).minCoeff());
  for (const SceneBox& b : s.objects) {
    const bool inside = (p.array() > b.lo.array()).all() && (p.array() < b.hi.array()).all();
    c = std::min(c, inside ? -1.0 : distanceToBox(p, b.lo, b.hi));
  }
  return c;
}

namespace {

struct VoxelKey {
  std::size_t operator()(const Eigen::Vector3i& v) const {
    return static_cast<std::size_t>(v.x() * 73856093) ^ static_cast<std::size_t>(v.y() * 19349663) ^
           static_cast<std::size_t>(v.z() * 83492791);
  }
};

/// Camera positions thinned to one per 10 cm voxel (clearance checks stay exact
/// to ~9 cm, covered by checking against clearance + 0.09).
std::vector<Vec3> thin(const std::vector<Vec3>& pts) {
  std::unordered_set<Eigen::Vector3i, VoxelKey> seen;
  std::vector<Vec3> out;
  for (const Vec3& p : pts) {
    const Eigen::Vector3i k = (p / 0.1).array().floor().cast<int>();
    if (seen.insert(k).second) out.push_back(p);
  }
  return out;
}

SceneBox proposeObject(const SceneBox& room, cv::RNG& rng) {
  SceneBox b;
  const Vec3 size = room.hi - room.lo;
  const double u = rng.uniform(0.0, 1.0);
  Vec3 ext;
  double z0 = room.lo.z();
  if (u < 0.3) {
    b.kind = "pillar";
    const double s = rng.uniform(0.4, 1.0);
    ext = Vec3(s, s * rng.uniform(0.7, 1.4), size.z());
  } else if (u < 0.65) {
    b.kind = "crate";
    ext = Vec3(rng.uniform(0.5, 2.2), rng.uniform(0.5, 2.2), rng.uniform(0.4, 2.0));
  } else {
    b.kind = "panel";
    const double w = rng.uniform(1.2, 4.0), t = 0.06;
    ext = rng.uniform(0, 2) ? Vec3(w, t, rng.uniform(1.5, 3.0)) : Vec3(t, w, rng.uniform(1.5, 3.0));
    if (rng.uniform(0, 3) == 0) z0 = room.lo.z() + rng.uniform(0.0, std::max(0.0, size.z() - ext.z()));
  }
  ext = ext.cwiseMin(size * 0.6);
  const Vec3 lo(rng.uniform(room.lo.x() + 0.2, room.hi.x() - 0.2 - ext.x()),
                rng.uniform(room.lo.y() + 0.2, room.hi.y() - 0.2 - ext.y()), z0);
  b.lo = lo;
  b.hi = lo + ext;
  return b;
}

}  // namespace

bool overlaps(const SceneBox& a, const SceneBox& b, double gap) {
  return (a.lo.array() - gap < b.hi.array()).all() && (b.lo.array() - gap < a.hi.array()).all();
}

bool placeable(const Scene& s, const SceneBox& b, const std::vector<Vec3>& pts, double clearance_m) {
  for (const SceneBox& o : s.objects)
    if (overlaps(o, b, 0.3)) return false;
  for (const Vec3& p : pts)
    if (distanceToBox(p, b.lo, b.hi) <= clearance_m + 0.09) return false;
  return true;
}

void appendRigPositions(const Trajectory& trajectory, const std::vector<SE3>& T_B_C,
                        std::vector<Vec3>* positions) {
  for (const StampedPose& pose : trajectory) {
    positions->push_back(pose.T_W_B.translation());
    for (const SE3& T : T_B_C) positions->push_back((pose.T_W_B * T).translation());
  }
}

Expected<Scene> buildScene(const std::vector<Vec3>& camera_positions, const SceneParams& p) {
  if (Status st = p.validate(); !st) return Error{st.error()};
  if (camera_positions.empty()) return Error{"scene: no camera positions to enclose"};
  Scene s;
  s.seed = p.seed;
  s.texel_m = p.texel_m;
  s.poor_fraction = p.poor_fraction;
  Vec3 lo = camera_positions.front(), hi = lo;
  for (const Vec3& c : camera_positions) {
    if (!c.allFinite()) return Error{"scene: non-finite camera position"};
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  s.room.kind = "room";
  s.room.lo = lo - Vec3(p.wall_margin_m, p.wall_margin_m, p.floor_margin_m);
  s.room.hi = hi + Vec3(p.wall_margin_m, p.wall_margin_m, p.ceiling_margin_m);

  cv::RNG rng(mixSeed(p.seed, 1));
  const std::vector<Vec3> pts = thin(camera_positions);
  for (int i = 0; i < p.num_objects; ++i) {
    for (int attempt = 0; attempt < 60; ++attempt) {
      SceneBox b = proposeObject(s.room, rng);
      if (placeable(s, b, pts, p.clearance_m)) {
        s.objects.push_back(b);
        break;
      }
    }
  }

  // Textures: one per face, sized to the face at texel_m.
  const PhotoLibrary photos =
      PhotoLibrary::load(p.photo_folder.empty() ? PhotoLibrary::defaultFolder() : p.photo_folder);
  s.photo_names = photos.names;
  s.photo_folder = photos.folder;
  const int poor_wall = p.poor_walls ? rng.uniform(0, 4) : -1;  // one of the faces 0..3
  auto texturize = [&](SceneBox& b, bool all_poor, bool is_room) {
    for (int f = 0; f < 6; ++f) {
      const int a = f / 2, ua = (a + 1) % 3, va = (a + 2) % 3;
      const Vec3 ext = b.hi - b.lo;
      const int w = std::max(4, static_cast<int>(std::ceil(ext[ua] / p.texel_m)) + 1);
      const int h = std::max(4, static_cast<int>(std::ceil(ext[va] / p.texel_m)) + 1);
      const bool poor = all_poor || (is_room && f == poor_wall);
      const TextureStyle style = poor ? TextureStyle::kPoor : TextureStyle::kRich;
      const std::uint64_t tseed = mixSeed(p.seed, 1000 + s.textures.size());
      b.texture[f] = static_cast<int>(s.textures.size());
      s.textures.push_back(
          MipTexture::fromImage(synthesizeTexture(w, h, p.texel_m, style, p.poor_fraction, tseed, photos)));
      s.texture_styles.push_back(style);
    }
  };
  texturize(s.room, false, true);
  for (SceneBox& b : s.objects) texturize(b, p.poor_walls && rng.uniform(0, 5) == 0, false);
  // The effects draw from their own random streams: without them the scene is
  // exactly the one built before they existed.
  if (p.grain) addGrain(p, &s);  // before the copies, so they repeat the grain too
  if (p.aliasing) addAliasingCopies(p, pts, &s);
  if (p.moving_objects > 0) addMovers(p, pts, &s);
  if (p.dark_regions) addDarkZones(p, pts, &s);
  return s;
}

std::string sceneToJson(const Scene& s) {
  using nlohmann::json;
  auto box = [&](const SceneBox& b) {
    json j;
    j["kind"] = b.kind;
    j["lo"] = {b.lo.x(), b.lo.y(), b.lo.z()};
    j["hi"] = {b.hi.x(), b.hi.y(), b.hi.z()};
    json faces = json::array();
    for (int f = 0; f < 6; ++f) {
      const int t = b.texture[f];
      json fj;
      fj["texture"] = t;
      fj["style"] = (t >= 0 && s.texture_styles[t] == TextureStyle::kPoor) ? "poor" : "rich";
      if (t >= 0) fj["texels"] = {s.textures[t].levels[0].cols, s.textures[t].levels[0].rows};
      faces.push_back(fj);
    }
    j["faces"] = faces;
    if (b.copy_of >= 0) j["copy_of"] = b.copy_of;
    return j;
  };
  json j;
  j["seed"] = s.seed;
  j["texel_m"] = s.texel_m;
  j["poor_fraction"] = s.poor_fraction;
  j["face_order"] = "f = 2*axis + side (side 0 = low, 1 = high); texture u/v along axes (a+1)%3, (a+2)%3";
  j["room"] = box(s.room);
  j["objects"] = json::array();
  for (const SceneBox& b : s.objects) j["objects"].push_back(box(b));
  j["dark_zones"] = json::array();
  for (const DarkZone& z : s.dark_zones)
    j["dark_zones"].push_back({{"centre", {z.centre.x(), z.centre.y(), z.centre.z()}},
                               {"radius_m", z.radius_m}, {"level", z.level}});
  j["movers"] = json::array();
  for (const MovingObject& m : s.movers)
    j["movers"].push_back({{"object", m.object}, {"from", {m.from.x(), m.from.y(), m.from.z()}},
                           {"to", {m.to.x(), m.to.y(), m.to.z()}}, {"period_s", m.period_s}});
  j["photo_folder"] = s.photo_folder;
  j["photos"] = s.photo_names;
  return j.dump(2);
}

}  // namespace render
}  // namespace hermes
