#include "hermes/agent/agent_threads.h"

namespace hermes::agent {

Status AgentThreadParams::read(const Config& config) {
  if (Status s = config.get("agent.parallel", &parallel); !s) return s;
  if (Status s = config.get("agent.window_queue", &window_queue); !s) return s;
  return validate();
}

void AgentThreadParams::write(ConfigWriter* writer) const {
  writer->set("agent.parallel", parallel);
  writer->set("agent.window_queue", window_queue);
}

Status AgentThreadParams::validate() const {
  if (window_queue < 1) return Error{"agent.window_queue must be >= 1"};
  return Status::Ok();
}

}  // namespace hermes::agent
