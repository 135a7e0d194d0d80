// Rendered datasets for benchmarks, made once: runs hermes_sim (found beside
// the running tool, both live in <build>/bin) into a private folder that is
// renamed when complete, so an interrupted render is never taken for a cached
// one. A folder holding a `done` marker counts as cached when its
// render_config.yaml (every scene and sensor setting, written by hermes_sim)
// equals the request's; otherwise it is rendered again. Folders from before
// render_config.yaml existed count only for requests of the plain look
// (render::kPlainLook; without settings a request is realistic).
#pragma once

#include <string>
#include <vector>

#include "hermes/core/status.h"

namespace hermes {

struct RenderRequest {
  std::vector<std::string> trajectories;  ///< TUM trajectory files, one robot each (one hall)
  double start_s = 0;                     ///< hermes_sim --start
  double duration_s = 0;                  ///< hermes_sim --duration (0: whole trajectories)
  double rate_hz = 0;                     ///< hermes_sim --rate (0: its default)
  int seed = 1;                           ///< hermes_sim --seed
  double poor_fraction = -1;              ///< hermes_sim --poor-fraction (< 0: its default)
  std::vector<std::string> settings;      ///< hermes_sim --set key=value (e.g. render.realistic=true)
};

/// The render_config.yaml text hermes_sim writes for `req` (or an error
/// naming a bad setting).
Expected<std::string> renderFingerprint(const RenderRequest& req);

/// Whether `fingerprint` (of `req`) is the plain look: every realism effect off.
bool isPlainLook(const RenderRequest& req, const std::string& fingerprint);

/// `folder`, rendering `req` into it first unless a finished render is there
/// (one robot per core at once: hermes_sim --jobs).
/// The render's output goes to `folder`.log. Errors name the failing command.
Status renderCached(const RenderRequest& req, const std::string& folder);

}  // namespace hermes
