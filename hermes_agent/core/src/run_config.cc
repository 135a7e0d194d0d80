#include "hermes/agent/run_config.h"

namespace hermes::agent {

Status AgentPipelineParams::read(const Config& config) {
  if (Status s = tracker.read(config); !s) return s;
  if (Status s = distill.read(config); !s) return s;
  distill.window_s = tracker.window.period_s;  // one key for the window cut and Δt of Eq. 17
  if (Status s = uplink.read(config); !s) return s;
  if (Status s = threads.read(config); !s) return s;
  if (Status s = borrowed.read(config); !s) return s;
  return validate();
}

Status AgentPipelineParams::validate() const {
  if (Status s = tracker.validate(); !s) return s;
  if (distill.window_s != tracker.window.period_s)
    return Error{"distill.window_s (Δt of the bandwidth budget, in code) is " + std::to_string(distill.window_s) +
                 " s but window.period_s (the tracker cuts a window this often) is " +
                 std::to_string(tracker.window.period_s) + " s: they must be equal (window.period_s sets both)"};
  if (Status s = distill.validate(); !s) return s;
  if (Status s = threads.validate(); !s) return s;
  if (Status s = borrowed.validate(); !s) return s;
  return uplink.validate();
}

void AgentPipelineParams::write(ConfigWriter* out) const {
  tracker.write(out);
  distill.write(out);
  uplink.write(*out);
  threads.write(out);
  borrowed.write(out);
}

Status RunParams::read(const Config& config) {
  if (Status s = agent.read(config); !s) return s;
  if (Status s = dataset.read(config); !s) return s;
  if (Status s = camera_input.read(config); !s) return s;
  if (Status s = eval.read(config, "eval"); !s) return s;
  return validate();
}

Status RunParams::validate() const {
  if (Status s = agent.validate(); !s) return s;
  if (Status s = dataset.validate(); !s) return s;
  if (Status s = camera_input.validate(); !s) return s;
  return eval.validate();
}

void RunParams::write(ConfigWriter* out) const {
  agent.write(out);
  dataset.write(*out);
  camera_input.write(out);
  out->set("eval.align", std::string(toString(eval.align)));
  out->set("eval.max_dt", eval.max_dt);
  out->set("eval.rpe_delta_s", eval.rpe_delta_s);
  out->set("eval.rpe_delta_frames", eval.rpe_delta_frames);
  out->set("eval.rpe_tolerance", eval.rpe_tolerance);
}

Status rejectUnreadKeys(const Config& config) {
  const std::vector<std::string> unused = config.unusedKeys();
  if (unused.empty()) return Status::Ok();
  std::string list;
  for (const std::string& k : unused) list += (list.empty() ? "" : ", ") + k;
  return Error{"unknown configuration key" + std::string(unused.size() > 1 ? "s" : "") + " " +
               list + " (in " + config.origin() + ")"};
}

Expected<RunParams> readRunParams(const Config& config) {
  RunParams params;
  if (Status s = params.read(config); !s) return Error{s.error()};
  if (Status s = rejectUnreadKeys(config); !s) return Error{s.error()};
  return params;
}

std::string configUsedYaml(const RunParams& params) {
  ConfigWriter writer;
  params.write(&writer);
  return writer.yaml();
}

}  // namespace hermes::agent
