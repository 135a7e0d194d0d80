// Render settings: the realism preset, then scene and sensor keys over it.
#include "hermes/core/render/settings.h"

namespace hermes {
namespace render {

void applyRealisticPreset(SceneParams* scene, SensorParams* sensor) {
  sensor->noise = true;
  sensor->photon_noise = true;
  sensor->noise_sigma = 1.0;   // read noise; measured on EuRoC V1_01 (bench realism)
  sensor->photon_gain = 0.02;  // [grey levels^2 per grey level], same measurement
  sensor->motion_blur = true;
  sensor->exposure_s = 0.005;
  scene->dark_regions = true;
  scene->aliasing = true;
}

Status RenderSettings::read(const Config& c) {
  if (Status st = c.get("render.realistic", &realistic); !st) return st;
  if (realistic) applyRealisticPreset(&scene, &sensor);
  if (Status st = scene.read(c, "render.scene"); !st) return st;
  return sensor.read(c, "render.sensor");
}

void RenderSettings::write(ConfigWriter* w) const {
  w->set("render.realistic", realistic);
  scene.write(w, "render.scene");
  sensor.write(w, "render.sensor");
}

std::string RenderSettings::fingerprint() const {
  ConfigWriter w;
  write(&w);
  return w.yaml();
}

Expected<RenderSettings> readRenderSettings(Config base, const std::vector<std::string>& overrides) {
  for (const std::string& kv : overrides)
    if (Status st = base.applyOverride(kv); !st) return Error{st.error()};
  RenderSettings s;
  if (Status st = s.read(base); !st) return Error{st.error()};
  for (const std::string& k : base.unusedKeys()) return Error{"unknown render setting '" + k + "'"};
  return s;
}

}  // namespace render
}  // namespace hermes
