#include "hermes/system/mission.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

namespace hermes::system {
namespace fs = std::filesystem;
namespace {

/// The rows of a `stamp_ns,...` CSV: the header lines and (stamp, rest of the line).
struct StampedCsv {
  std::vector<std::string> header;
  std::vector<std::pair<std::int64_t, std::string>> rows;
};

Expected<StampedCsv> readStampedCsv(const fs::path& path) {
  std::ifstream f(path);
  if (!f) return Error{"cannot read " + path.string()};
  StampedCsv csv;
  std::string line;
  for (int row = 1; std::getline(f, line); ++row) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    if (line[0] == '#') {
      csv.header.push_back(line);
      continue;
    }
    const std::size_t comma = line.find(',');
    std::int64_t ns = 0;
    std::istringstream ls(line.substr(0, comma));
    if (!(ls >> ns)) return Error{path.string() + ":" + std::to_string(row) + ": no stamp in '" + line + "'"};
    csv.rows.emplace_back(ns, comma == std::string::npos ? "" : line.substr(comma));
  }
  return csv;
}

std::int64_t toNs(double s) { return std::llround(s * 1e9); }

}  // namespace

Expected<std::vector<MissionRobot>> planMission(const MissionPlan& plan,
                                                const std::function<double(const std::string&)>& length_s) {
  if (plan.robots < 1) return Error{"mission: at least one robot"};
  if (plan.sorties < 1 || plan.sorties > plan.waves)
    return Error{"mission: sorties per robot must be in [1, waves = " + std::to_string(plan.waves) + "]"};
  if (plan.sequences.empty()) return Error{"mission: no sequence to fly"};
  if (!(plan.duration_s > 0) || !(plan.stagger_s >= 0)) return Error{"mission: duration must be > 0 and stagger >= 0"};
  const double wave = plan.duration_s / plan.waves;
  std::vector<int> in_wave(static_cast<std::size_t>(plan.waves), 0);  // robots placed in each wave so far
  std::vector<MissionRobot> robots;
  for (int k = 0; k < plan.robots; ++k) {
    MissionRobot r;
    char name[16];
    std::snprintf(name, sizeof name, "r%02d", k + 1);
    r.name = name;
    r.sequence = plan.sequences[static_cast<std::size_t>(k) % plan.sequences.size()];
    const double length = length_s(r.sequence);
    std::vector<int> waves;
    for (int j = 0; j < plan.sorties; ++j) waves.push_back((k + j) % plan.waves);
    std::sort(waves.begin(), waves.end());
    for (int w : waves) {
      const double takeoff = w * wave + in_wave[static_cast<std::size_t>(w)]++ * plan.stagger_s;
      if (!r.takeoffs_s.empty() && r.takeoffs_s.back() + length + 2.0 > takeoff)
        return Error{"mission: robot " + r.name + " (" + r.sequence + ", " + std::to_string(length) +
                     " s a sortie) would not have landed before its take-off at " + std::to_string(takeoff) +
                     " s (a longer mission, fewer sorties or a smaller stagger)"};
      r.takeoffs_s.push_back(takeoff);
    }
    robots.push_back(std::move(r));
  }
  return robots;
}

Expected<MissionView> writeMissionView(const std::string& source, const std::vector<double>& takeoffs_s,
                                       double epoch_s, const std::string& out) {
  const fs::path src = fs::absolute(fs::path(source) / "mav0");
  const std::string what = "mission view of " + source + ": ";
  if (!fs::exists(src / "cam0" / "data.csv")) return Error{what + (src / "cam0" / "data.csv").string() + " does not exist"};
  if (takeoffs_s.empty()) return Error{what + "no take-off"};
  auto cam0 = readStampedCsv(src / "cam0" / "data.csv");
  if (!cam0) return Error{what + cam0.error()};
  if (cam0->rows.empty()) return Error{what + "cam0 holds no frame"};
  const std::int64_t t0 = cam0->rows.front().first;
  const fs::path dst = fs::path(out) / "mav0";
  std::error_code ec;
  fs::remove_all(out, ec);
  fs::create_directories(dst, ec);
  if (ec) return Error{what + "cannot create " + dst.string() + ": " + ec.message()};
  MissionView view;
  for (double takeoff : takeoffs_s) {
    const std::int64_t shift = toNs(epoch_s) + toNs(takeoff) - t0;
    view.first_frames.push_back(view.frames);
    view.shifts_s.push_back(static_cast<double>(shift) * 1e-9);
    view.frames += cam0->rows.size();
  }
  for (const fs::directory_entry& e : fs::directory_iterator(src)) {
    const std::string name = e.path().filename().string();
    if (!fs::exists(e.path() / "data.csv")) {
      fs::create_symlink(e.path(), dst / name, ec);
      if (ec) return Error{what + "cannot link " + (dst / name).string() + ": " + ec.message()};
      continue;
    }
    fs::create_directories(dst / name, ec);
    for (const fs::directory_entry& c : fs::directory_iterator(e.path()))
      if (c.path().filename() != "data.csv") fs::create_symlink(c.path(), dst / name / c.path().filename(), ec);
    if (ec) return Error{what + "cannot link into " + (dst / name).string() + ": " + ec.message()};
    auto csv = readStampedCsv(e.path() / "data.csv");
    if (!csv) return Error{what + csv.error()};
    std::ofstream o(dst / name / "data.csv");
    for (const std::string& h : csv->header) o << h << '\n';
    std::int64_t last = std::numeric_limits<std::int64_t>::min();
    for (double takeoff : takeoffs_s) {
      const std::int64_t shift = toNs(epoch_s) + toNs(takeoff) - t0;
      for (const auto& [ns, rest] : csv->rows) {
        if (ns + shift <= last)  // a sensor's rows before cam0's first overlap the sortie before
          return Error{what + name + "/data.csv: its rows span more than the gap between two take-offs"};
        last = ns + shift;
        o << last << rest << '\n';
      }
    }
    if (!o) return Error{what + "error writing " + (dst / name / "data.csv").string()};
  }
  return view;
}

}  // namespace hermes::system
