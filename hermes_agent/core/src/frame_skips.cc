#include "hermes/agent/frame_skips.h"

namespace hermes {

std::string FrameSkips::causeOf(const std::string& error) {
  auto has = [&](const char* s) { return error.find(s) != std::string::npos; };
  if (has("calibration says") || has("camera says") || has("size differs")) return "wrong_size";
  if (has("not a 16-bit")) return "wrong_format";
  return "unreadable";
}

std::string FrameSkips::summary() const {
  if (total_ == 0) return "";
  std::string s = std::to_string(total_) + " frame" + (total_ == 1 ? "" : "s") + " skipped (";
  for (const auto& [cause, n] : by_cause_)
    s += (s.back() == '(' ? "" : ", ") + cause + " " + std::to_string(n);
  return s + ")";
}

bool FrameSkips::add(const std::string& error) {
  ++total_;
  return ++by_cause_[causeOf(error)] == 1;
}

}  // namespace hermes
