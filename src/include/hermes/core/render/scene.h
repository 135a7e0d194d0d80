// Procedural scenes of the synthetic renderer: a hall (axis-aligned box seen
// from inside) around a set of camera paths, with axis-aligned boxes (pillars,
// crates, thin panels) inside that keep a clearance from every camera position.
// Every face is a textured planar quad.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/render/texture.h"
#include "hermes/core/status.h"
#include "hermes/core/trajectory.h"

namespace hermes {
namespace render {

/// Axis-aligned box. The room box is seen from inside, objects from outside.
/// Face f = 2*axis + (0 for the low side, 1 for the high side).
struct SceneBox {
  Vec3 lo = Vec3::Zero(), hi = Vec3::Zero();
  std::string kind;                 ///< "room", "pillar", "crate", "panel", "marker"
  std::array<int, 6> texture{};     ///< index into Scene::textures per face, -1 = none
  int copy_of = -1;                 ///< aliasing copy: index of the object it repeats
};

/// A dark part of the hall (lights off): brightness falls smoothly from 1 at
/// `radius_m` to `level` at the centre.
struct DarkZone {
  Vec3 centre = Vec3::Zero();
  double radius_m = 0;
  double level = 1;
};

/// An object that moves back and forth along a straight segment (its box in
/// Scene::objects is the one at `from`, time 0): the box is offset by
/// offsetAt(t), from 0 to (to - from) in half a period and back.
struct MovingObject {
  int object = -1;            ///< index into Scene::objects
  Vec3 from = Vec3::Zero(), to = Vec3::Zero();  ///< box lo corner at the ends
  double period_s = 10;       ///< there and back [s]
  Vec3 offsetAt(double t) const;
};

struct Scene {
  std::uint64_t seed = 0;
  double texel_m = 1.0 / 128.0;     ///< texture resolution [m per texel]
  double poor_fraction = 0.25;      ///< SceneParams::poor_fraction it was built with
  SceneBox room;
  std::vector<SceneBox> objects;
  std::vector<MipTexture> textures;
  std::vector<TextureStyle> texture_styles;
  std::vector<DarkZone> dark_zones;      ///< baked into the textures
  std::vector<MovingObject> movers;      ///< objects that move (Raycaster::placeMovers)
  std::vector<std::string> photo_names;  ///< photographs available when built
  std::string photo_folder;
};

struct SceneParams {
  std::uint64_t seed = 1;
  double wall_margin_m = 3.0;       ///< walls this far beyond the camera positions (xy)
  double floor_margin_m = 1.0;      ///< floor below the lowest camera position
  double ceiling_margin_m = 3.0;    ///< ceiling above the highest camera position
  double clearance_m = 0.7;         ///< objects keep this distance to every camera position
  int num_objects = 14;             ///< attempted inner objects
  double texel_m = 1.0 / 128.0;     ///< [m per texel]
  double poor_fraction = 0.25;      ///< share of near-uniform panels on rich faces
  bool poor_walls = true;           ///< make one wall and a few objects texture-poor
  std::string photo_folder;         ///< empty = PhotoLibrary::defaultFolder()
  /// Dark regions: zones centred on camera positions whose textures are darkened.
  bool dark_regions = false;
  int dark_zones = 3;               ///< number of zones
  double dark_radius_m = 6.0;       ///< zone radius [m]
  double dark_level = 0.25;         ///< brightness left at a zone's centre (0..1)
  /// Surface grain: fine correlated noise added to every texture (real
  /// surfaces are never uniform; the gradient histogram of real frames shows it).
  bool grain = false;
  double grain_sigma = 3.0;         ///< standard deviation [grey levels]
  double grain_scale_texels = 1.5;  ///< correlation length [texels]
  /// Perceptual aliasing: exact copies (shape + texture) of textured objects
  /// placed elsewhere in the hall.
  bool aliasing = false;
  int aliasing_copies = 4;          ///< copies attempted
  /// Moving objects: copies of textured objects sliding along free straight
  /// segments in the hall (kept clear of every camera position); 0 = none.
  int moving_objects = 0;
  double moving_speed_mps = 1.0;    ///< [m/s]
  /// Reads keys under `prefix` (e.g. render.scene.clearance_m), then validates.
  Status read(const Config& c, const std::string& prefix = "render.scene");
  Status validate() const;
  /// Writes every field under `prefix` (the configuration actually used).
  void write(ConfigWriter* w, const std::string& prefix = "render.scene") const;
};

/// Builds the scene enclosing every given camera position (world frame).
Expected<Scene> buildScene(const std::vector<Vec3>& camera_positions, const SceneParams& p);

/// Appends, per pose of `trajectory` (body poses), the body position and then
/// each camera's position (T_W_B * T_B_C): what buildScene must enclose.
void appendRigPositions(const Trajectory& trajectory, const std::vector<SE3>& T_B_C,
                        std::vector<Vec3>* positions);

/// Distance from p to the closed box [lo, hi] (0 inside).
double distanceToBox(const Vec3& p, const Vec3& lo, const Vec3& hi);

/// Clearance of a camera position: distance to the nearest face of the scene
/// (room walls from inside, objects from outside; negative when inside an object).
double clearance(const Scene& s, const Vec3& p);

/// JSON description (seed, bounds, boxes, textures, photos) for reproduction.
std::string sceneToJson(const Scene& s);

}  // namespace render
}  // namespace hermes
