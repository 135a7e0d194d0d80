#include "hermes/agent/agent_threads.h"

namespace hermes::agent {

Status AgentThreadParams::read(const Config& config) {
  if (Status s = config.get("agent.parallel", &parallel); !s) return s;
  if (Status s = config.get("agent.window_queue", &window_queue); !s) return s;
  if (Status s = config.get("agent.timing_window", &timing_window); !s) return s;
  return validate();
}

void AgentThreadParams::write(ConfigWriter* writer) const {
  writer->set("agent.parallel", parallel);
  writer->set("agent.window_queue", window_queue);
  writer->set("agent.timing_window", timing_window);
}

Status AgentThreadParams::validate() const {
  if (window_queue < 1) return Error{"agent.window_queue must be >= 1"};
  if (timing_window < 0) return Error{"agent.timing_window must be >= 0 (0 = every sample)"};
  return Status::Ok();
}

}  // namespace hermes::agent
