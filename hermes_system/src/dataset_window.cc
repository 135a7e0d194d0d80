#include "hermes/system/dataset_window.h"

#include "hermes/core/render_cache.h"

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace hermes::system {
namespace fs = std::filesystem;
namespace {

/// Copies the header and the rows of `in` whose first column (stamp [ns]) lies
/// in [lo, hi) to `out`; `*first_ns` (< 0: not yet known) is cam0's first stamp.
Expected<WindowInfo> filterCsv(const fs::path& in, const fs::path& out, double start_s, double duration_s,
                               std::int64_t* first_ns) {
  std::ifstream f(in);
  if (!f) return Error{"cannot read " + in.string()};
  std::ofstream o(out);
  if (!o) return Error{"cannot write " + out.string()};
  WindowInfo info;
  std::string line;
  int row = 0;
  while (std::getline(f, line)) {
    ++row;
    if (line.empty()) continue;
    if (line[0] == '#') {
      o << line << '\n';
      continue;
    }
    std::int64_t ns = 0;
    std::istringstream ls(line.substr(0, line.find(',')));
    if (!(ls >> ns)) return Error{in.string() + ":" + std::to_string(row) + ": no stamp in '" + line + "'"};
    if (*first_ns < 0) *first_ns = ns;
    const double t = static_cast<double>(ns - *first_ns) * 1e-9;
    if (t < start_s || t >= start_s + duration_s) continue;
    if (info.frames == 0) info.first_stamp_s = static_cast<double>(ns) * 1e-9;
    ++info.frames;
    o << line << '\n';
  }
  if (!o) return Error{"error writing " + out.string()};
  return info;
}

}  // namespace

Expected<WindowInfo> writeEurocWindow(const std::string& source, double start_s, double duration_s,
                                      const std::string& out) {
  const fs::path src = fs::absolute(fs::path(source) / "mav0");
  if (!fs::exists(src / "cam0" / "data.csv"))
    return Error{"dataset window: " + (src / "cam0" / "data.csv").string() + " does not exist"};
  if (!(duration_s > 0) || start_s < 0)
    return Error{"dataset window of " + source + ": start must be >= 0 and duration > 0"};
  const fs::path dst = fs::path(out) / "mav0";
  std::error_code ec;
  fs::remove_all(out, ec);
  fs::create_directories(dst, ec);
  if (ec) return Error{"dataset window: cannot create " + dst.string() + ": " + ec.message()};
  std::int64_t first_ns = -1;
  WindowInfo info;
  for (const fs::directory_entry& e : fs::directory_iterator(src)) {
    const std::string name = e.path().filename().string();
    const bool camera = name.rfind("cam", 0) == 0 && fs::exists(e.path() / "data.csv");
    if (!camera) {
      fs::create_symlink(e.path(), dst / name, ec);
      if (ec) return Error{"dataset window: cannot link " + (dst / name).string() + ": " + ec.message()};
      continue;
    }
    fs::create_directories(dst / name, ec);
    for (const fs::directory_entry& c : fs::directory_iterator(e.path()))
      if (c.path().filename() != "data.csv") fs::create_symlink(c.path(), dst / name / c.path().filename(), ec);
    if (ec) return Error{"dataset window: cannot link into " + (dst / name).string() + ": " + ec.message()};
  }
  // cam0 first: its first stamp is the window's time origin for every camera.
  std::vector<std::string> cams{"cam0"};
  for (const fs::directory_entry& e : fs::directory_iterator(dst))
    if (e.is_directory() && !e.is_symlink() && e.path().filename() != "cam0") cams.push_back(e.path().filename());
  for (const std::string& cam : cams) {
    auto r = filterCsv(src / cam / "data.csv", dst / cam / "data.csv", start_s, duration_s, &first_ns);
    if (!r) return Error{"dataset window: " + r.error()};
    if (cam == "cam0") info = *r;
  }
  if (info.frames == 0)
    return Error{"dataset window of " + source + ": no frame in [" + std::to_string(start_s) + ", " +
                 std::to_string(start_s + duration_s) + ") s"};
  return info;
}

Status ensureWholeRenders(const std::string& data, const std::vector<std::string>& sequences,
                          const std::string& trajectories_dir, double rate_hz,
                          const std::vector<std::string>& settings) {
  RenderRequest req;  // all of them in one scene
  for (const std::string& s : sequences)
    req.trajectories.push_back((fs::path(trajectories_dir) / (s + ".txt")).string());
  req.rate_hz = rate_hz;
  req.settings = settings;
  auto fingerprint = renderFingerprint(req);
  if (!fingerprint.ok()) return Error{"render " + data + ": " + fingerprint.error()};
  // Any look but the plain one: compare the settings it was made with.
  if (!isPlainLook(req, *fingerprint) || fs::exists(fs::path(data) / "render_config.yaml"))
    return renderCached(req, data);
  // The plain look, rendered before render_config.yaml existed (or by hand):
  // complete when every sequence is there.
  for (const std::string& seq : sequences)
    if (!fs::exists(fs::path(data) / seq / "mav0")) return renderCached(req, data);
  return Status::Ok();
}

}  // namespace hermes::system
