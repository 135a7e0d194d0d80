// A time window of a EuRoC sequence folder as a dataset folder of its own,
// without copying images: camX/data.csv keeps the rows whose stamps lie in
// [first + start_s, first + start_s + duration_s), camX/data and every other
// entry (sensor.yaml, ground truth, body.yaml) are symbolic links to the
// source. How the swarm sweep makes 20 robots out of five whole-sequence
// renders (time-shifted robots in one hall) without rendering again.
#pragma once

#include <string>
#include <vector>

#include "hermes/core/status.h"

namespace hermes::system {

struct WindowInfo {
  std::size_t frames = 0;     ///< cam0 rows kept
  double first_stamp_s = 0;   ///< stamp of the first kept row [s]
};

/// Writes the view of `source` (a sequence folder holding mav0/) into `out`
/// (created; an existing view there is replaced). Errors name the file: a
/// source without mav0/cam0/data.csv, an unreadable row, or a window holding
/// no frame.
Expected<WindowInfo> writeEurocWindow(const std::string& source, double start_s, double duration_s,
                                      const std::string& out);

/// Blacks out the stereo images of the window view `view` (writeEurocWindow)
/// stamped in [from_s, to_s) after its first frame: a camera gone dark. The
/// view's image folders become folders of their own (links to the source's
/// images, black files in their place for those frames); the source is never
/// written. Returns the stamp [s] of the first frame after the stretch. Errors
/// name the file; a stretch holding no frame is an error.
Expected<double> blackOutFrames(const std::string& view, double from_s, double to_s);

/// Makes sure `data` holds whole-sequence renders of every one of `sequences`
/// (<data>/<sequence>/mav0): if one is missing, renders all of them in one
/// scene from `trajectories_dir`/<sequence>.txt at `rate_hz` (render_cache.h).
/// `settings` are hermes_sim --set overrides: none gives the realistic look,
/// {render::kPlainLook} the plain one. A render made with other settings is made
/// again (render_config.yaml is compared); a plain-look folder from before that
/// file existed counts when every sequence is there.
Status ensureWholeRenders(const std::string& data, const std::vector<std::string>& sequences,
                          const std::string& trajectories_dir, double rate_hz,
                          const std::vector<std::string>& settings = {});

}  // namespace hermes::system
