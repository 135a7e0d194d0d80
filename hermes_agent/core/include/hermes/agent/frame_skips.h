// Frames an agent could not read (a missing, truncated or wrongly sized image): counted
// by cause, so a bad frame costs that frame and not the run.
#pragma once

#include <cstdint>
#include <map>
#include <string>

namespace hermes {

/// Frames a run could not read, counted by cause: "unreadable" (missing, truncated or
/// not an image), "wrong_size" (not the calibration's size), "wrong_format" (e.g. a
/// depth image that is not 16-bit). A bad frame costs that frame, not the run.
class FrameSkips {
 public:
  /// The cause of a loadCameraFrame() error.
  static std::string causeOf(const std::string& error);
  /// Counts one skipped frame; true when it is the first of its cause (log it then).
  bool add(const std::string& error);
  std::int64_t total() const { return total_; }
  const std::map<std::string, std::int64_t>& byCause() const { return by_cause_; }
  /// "N frames skipped (cause n, ...)"; empty when none.
  std::string summary() const;

 private:
  std::int64_t total_ = 0;
  std::map<std::string, std::int64_t> by_cause_;
};

}  // namespace hermes
