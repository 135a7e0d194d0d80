// Optional scene effects of the synthetic renderer (internal to buildScene):
// surface grain, perceptual aliasing (exact copies of objects elsewhere) and
// dark regions.
#pragma once

#include <vector>

#include "hermes/core/render/scene.h"

namespace hermes {
namespace render {

/// Whether boxes a and b (grown by gap) overlap.
bool overlaps(const SceneBox& a, const SceneBox& b, double gap);
/// Whether b overlaps no object of s and keeps clearance_m to every point.
bool placeable(const Scene& s, const SceneBox& b, const std::vector<Vec3>& pts, double clearance_m);

/// Adds fine Gaussian grain (p.grain_sigma, correlated over
/// p.grain_scale_texels) to every texture; deterministic per texture.
void addGrain(const SceneParams& p, Scene* s);

/// Appends up to p.aliasing_copies copies of textured objects (same size and
/// texture content, own texture entries) at free places of the hall.
void addAliasingCopies(const SceneParams& p, const std::vector<Vec3>& pts, Scene* s);

/// Appends up to p.moving_objects movers: copies of textured objects whose
/// whole swept box is free and keeps clearance from every camera position.
void addMovers(const SceneParams& p, const std::vector<Vec3>& pts, Scene* s);

/// Picks p.dark_zones zones centred on camera positions and bakes their
/// darkening into every face texture (mip levels rebuilt).
void addDarkZones(const SceneParams& p, const std::vector<Vec3>& pts, Scene* s);

/// Brightness factor of the dark zones at world point x (1 outside every zone).
double darkFactor(const std::vector<DarkZone>& zones, const Vec3& x);

}  // namespace render
}  // namespace hermes
