// Shared by the hermes_system benchmarks (bench_system, bench_soak): comma lists
// on the command line and where whole-sequence renders take their trajectories.
// Header-only: HERMES_SOURCE_DIR / HERMES_SHARED_DATA_DIR are the tools' own
// compile definitions (cmake/HermesModule.cmake).
#pragma once

#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

namespace hermes::system::bench {

/// The whole Machine Hall set (five robots in one hall).
constexpr const char* kMachineHall = "MH_01_easy,MH_02_easy,MH_03_medium,MH_04_difficult,MH_05_difficult";

/// "a,b,,c" -> {a, b, c}
inline std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string item; std::getline(ss, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

/// The shared data's EuRoC ground truth, or (a machine without it) the 20-Hz
/// copies shipped in config/trajectories (the renders sample 20 Hz: the same poses).
inline std::string groundTruthDir() {
  namespace fs = std::filesystem;
  const fs::path shared = fs::path(HERMES_SHARED_DATA_DIR) / "euroc_gt";
  if (fs::is_directory(shared)) return shared.string();
  return (fs::path(HERMES_SOURCE_DIR) / "config" / "trajectories").string();
}

}  // namespace hermes::system::bench
