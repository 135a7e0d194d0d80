// Shared test helpers: windows built from real EuRoC ground truth, random Eq. 14
// instances and a brute-force Eq. 14 solver.
#pragma once

#include <random>
#include <string>
#include <vector>

#include "hermes/distill/landmark_selection.h"
#include "hermes/distill/synthetic_window.h"

namespace hermes {
namespace distill {
namespace testing {

/// Scene around a TUM ground-truth trajectory file (cached per path); aborts the
/// test binary with a message if the file is missing.
const SyntheticScene& sceneFromFile(const std::string& path);
SyntheticWindow windowFromFile(const std::string& path, double t_start, std::uint64_t seq);

#ifdef HERMES_TRAJECTORY_DIR  // defined for test executables, not the support library
inline std::string groundTruthPath(const std::string& sequence) {
  return std::string(HERMES_TRAJECTORY_DIR) + "/" + sequence + ".txt";
}

/// Scene / 5-s window of a EuRoC sequence of config/trajectories.
inline const SyntheticScene& scene(const std::string& sequence) {
  return sceneFromFile(groundTruthPath(sequence));
}
inline SyntheticWindow window(const std::string& sequence, double t_start,
                              std::uint64_t seq = 1) {
  return windowFromFile(groundTruthPath(sequence), t_start, seq);
}
#endif

/// Random Eq. 14 instance with n landmarks and n_kf keyframes (grid cells drawn
/// per keyframe); budget = budget_fraction of all landmarks' bytes.
SelectionProblem randomProblem(std::mt19937_64& rng, int n, int n_kf, int k,
                               double budget_fraction);

/// Exhaustive optimum of Eq. 14 (n <= 20); returns the best objective and selection.
double bruteForce(const SelectionProblem& p, std::vector<int>* best = nullptr);

}  // namespace testing
}  // namespace distill
}  // namespace hermes
