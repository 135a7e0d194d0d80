// Configuration of one offline run (hermes_run): every module's Params read
// from one Config (YAML file + `--set key=value` overrides), the check that no
// key was left unread (typos are errors), and the config_used.yaml text.
#pragma once

#include <string>
#include <vector>

#include "hermes/agent/agent_threads.h"
#include "hermes/agent/borrowed_map.h"
#include "hermes/agent/camera_input_params.h"
#include "hermes/agent/tracker.h"
#include "hermes/agent/uplink_sender.h"
#include "hermes/core/config_file.h"
#include "hermes/core/dataset.h"
#include "hermes/core/evaluation.h"
#include "hermes/distill/params.h"

namespace hermes::agent {

/// Parameters of the agent pipeline proper (front end, distillation, uplink).
struct AgentPipelineParams {
  /// Default spool folder "spool" (uplink.buffer.dir); hermes_run resolves a
  /// relative folder under its --out folder.
  AgentPipelineParams() { uplink.buffer.dir = "spool"; }

  TrackerParams tracker;             ///< sections orb, stereo, rgbd, matching, pose, keyframe, tracker
  distill::DistillParams distill;    ///< section distill
  UplinkParams uplink;               ///< section uplink (buffer, monitor)
  AgentThreadParams threads;         ///< section agent (parallel, window_queue)
  BorrowedMapParams borrowed;        ///< section borrowed (the map the server sends down)

  /// The window period: the tracker's cut (window.period_s) and the budget's Δt.
  void setWindowPeriod(double period_s) { tracker.window.period_s = distill.window_s = period_s; }

  /// Reads every section; distill.window_s comes from window.period_s.
  Status read(const Config& config);
  /// Every section's validate(), and distill.window_s == tracker.window.period_s.
  Status validate() const;
  void write(ConfigWriter* out) const;
};

/// Everything a run reads: the pipeline plus dataset reading and evaluation.
struct RunParams {
  AgentPipelineParams agent;
  DatasetParams dataset;   ///< section dataset
  CameraInputParams camera_input;  ///< section camera_input (images from ROS topics)
  eval::EvalParams eval;   ///< section eval

  Status read(const Config& config);
  Status validate() const;
  void write(ConfigWriter* out) const;
};

/// Error listing every key of `config` that no module read (typos), with its origin.
Status rejectUnreadKeys(const Config& config);

/// Reads RunParams from `config` and fails when a key was not read by any
/// module (the message lists the unknown keys and the config origin).
Expected<RunParams> readRunParams(const Config& config);

/// The YAML written as OUT/config_used.yaml.
std::string configUsedYaml(const RunParams& params);

}  // namespace hermes::agent
