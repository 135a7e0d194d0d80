// Window extraction for distillation (DESIGN.md §3/§4): every period the agent
// hands over the keyframes inserted since the previous window as a Submap.
//
// Odometry edge information: the odometry noise model (core/odometry_noise.h,
// keys odometry.*) for the relative pose between consecutive keyframes, the
// landmarks they share and whether tracking was lost between them.
#pragma once

#include <cstddef>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/map_types.h"
#include "hermes/core/odometry_noise.h"

namespace hermes {

struct SubmapWindowParams {
  double period_s = 5.0;         ///< Δt between windows [s]
  OdometryNoiseParams odometry;  ///< odometry.*

  /// Keys window.period_s and odometry.*.
  Status read(const Config& config);
  void write(ConfigWriter* writer) const;
  Status validate() const;
};

/// Builds the submap of keyframes [first, last) of `keyframes` (ids = indices):
/// keyframes copied with their current poses, landmark links outside the
/// window's landmark set cleared, landmarks observed by them with observations
/// restricted to the window, odometry edges between consecutive keyframes
/// (`lost_before[k]`: tracking was lost between keyframe k-1 and k; shorter
/// than `keyframes` = not lost), cameras = {K}. header.t_start / t_end are set
/// from the keyframe stamps.
Submap buildWindow(const std::vector<Keyframe>& keyframes, const std::vector<Landmark>& landmarks,
                   const std::vector<char>& lost_before, std::size_t first, std::size_t last,
                   const PinholeIntrinsics& K, SubmapHeader header,
                   const SubmapWindowParams& params);

/// One window made of a window that could not be sent (deferred: link down or
/// too slow; refused: spool full) and the next one: keyframes of both (ids are
/// disjoint), landmarks united by id (position and descriptor of `later`,
/// observations of both), both windows' odometry edges (the server bridges the
/// two with an edge from the keyframe poses), header of `later` spanning both.
/// Errors when the camera tables differ (then `earlier` cannot be merged).
Expected<Submap> mergeWindows(Submap earlier, const Submap& later);

/// Keeps the newest `max_keyframes` keyframes of `s` (drops the oldest, their
/// observations, odometry edges and landmarks left unobserved); returns how
/// many keyframes were dropped.
std::size_t keepNewestKeyframes(Submap* s, std::size_t max_keyframes);

}  // namespace hermes
