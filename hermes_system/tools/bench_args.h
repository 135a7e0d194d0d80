// Shared by the hermes_system benchmarks (bench_system, bench_soak, bench_relay,
// bench_mapuse): their command-line options, comma lists and where whole-sequence
// renders take their trajectories.
// Header-only: HERMES_SOURCE_DIR is one of the tools' own
// compile definitions (cmake/HermesModule.cmake).
#pragma once

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <utility>
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

/// A tool's options in order, every value checked:
///   Options opt(argc, argv, "hermes_bench_soak");
///   while (opt.next())
///     if (opt.is("--robots")) robots = opt.whole(1, 100);
///     else if (opt.is("--out")) out = opt.value();
///     else return opt.unknown();
/// A missing or malformed value prints "TOOL: OPTION ..." and exits with status 2.
class Options {
 public:
  Options(int argc, char** argv, std::string tool) : argc_(argc), argv_(argv), tool_(std::move(tool)) {}

  /// Moves to the next option; false after the last.
  bool next() {
    if (i_ + 1 >= argc_) return false;
    name_ = argv_[++i_];
    return true;
  }
  const std::string& name() const { return name_; }
  bool is(const char* option) const { return name_ == option; }

  /// The option's value (the next argument).
  std::string value() {
    if (i_ + 1 >= argc_) fail("needs a value");
    return argv_[++i_];
  }
  /// A number in [lo, hi].
  double number(double lo = -HUGE_VAL, double hi = HUGE_VAL) {
    const std::string v = value();
    char* end = nullptr;
    errno = 0;
    const double x = std::strtod(v.c_str(), &end);
    if (v.empty() || *end != '\0' || errno != 0 || !std::isfinite(x)) fail("needs a number (got '" + v + "')");
    if (x < lo || x > hi) fail("is out of range [" + fmt(lo) + ", " + fmt(hi) + "] (got '" + v + "')");
    return x;
  }
  /// A whole number in [lo, hi].
  int whole(long lo, long hi) {
    const std::string v = value();
    char* end = nullptr;
    errno = 0;
    const long x = std::strtol(v.c_str(), &end, 10);
    if (v.empty() || *end != '\0' || errno != 0) fail("needs a whole number (got '" + v + "')");
    if (x < lo || x > hi) fail("is out of range [" + fmt(lo) + ", " + fmt(hi) + "] (got '" + v + "')");
    return static_cast<int>(x);
  }
  /// For the caller's last else: "TOOL: unknown option 'X' (see --help)", status 2.
  int unknown() const {
    std::fprintf(stderr, "%s: unknown option '%s' (see --help)\n", tool_.c_str(), name_.c_str());
    return 2;
  }

 private:
  [[noreturn]] void fail(const std::string& why) const {
    std::fprintf(stderr, "%s: %s %s\n", tool_.c_str(), name_.c_str(), why.c_str());
    std::exit(2);
  }
  static std::string fmt(double x) {
    if (std::isinf(x)) return x < 0 ? "-inf" : "inf";
    char b[32];
    std::snprintf(b, sizeof b, "%g", x);
    return b;
  }

  int argc_;
  char** argv_;
  std::string tool_;
  int i_ = 0;
  std::string name_;
};

/// The EuRoC ground truths shipped in config/trajectories (20 Hz: the poses the
/// renders sample).
inline std::string groundTruthDir() {
  return (std::filesystem::path(HERMES_SOURCE_DIR) / "config" / "trajectories").string();
}

}  // namespace hermes::system::bench
