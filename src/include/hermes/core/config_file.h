// A run's configuration as a user gives it: a YAML file plus `--set key=value` overrides.
#pragma once

#include <string>
#include <vector>

#include "hermes/core/config.h"

namespace hermes {

/// Builds a run's Config: `file` (empty: no file, all defaults) plus the `--set`
/// overrides in order. Errors name the file or the bad assignment.
Expected<Config> loadConfig(const std::string& file, const std::vector<std::string>& sets);

}  // namespace hermes
