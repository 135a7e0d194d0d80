#include "hermes/system/dataset_window.h"

#include "hermes/core/render_cache.h"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

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

Expected<double> blackOutFrames(const std::string& view, double from_s, double to_s) {
  const fs::path mav0 = fs::path(view) / "mav0";
  std::error_code ec;
  std::int64_t first_ns = -1;
  double first_after = -1;
  std::size_t blacked = 0;
  for (const char* cam : {"cam0", "cam1"}) {
    const fs::path csv = mav0 / cam / "data.csv", images = mav0 / cam / "data";
    std::ifstream f(csv);
    if (!f) return Error{"black out: cannot read " + csv.string()};
    if (!fs::is_symlink(images)) return Error{"black out: " + images.string() + " is not a window view's link"};
    const fs::path source = fs::read_symlink(images);
    fs::remove(images, ec);
    fs::create_directory(images, ec);
    if (ec) return Error{"black out: cannot create " + images.string() + ": " + ec.message()};
    std::string line;
    for (int row = 1; std::getline(f, line); ++row) {
      if (line.empty() || line[0] == '#') continue;
      const std::size_t comma = line.find(',');
      std::int64_t ns = 0;
      std::istringstream ls(line.substr(0, comma));
      if (!(ls >> ns) || comma == std::string::npos)
        return Error{csv.string() + ":" + std::to_string(row) + ": not 'stamp,file' in '" + line + "'"};
      std::string name = line.substr(comma + 1);
      while (!name.empty() && (name.back() == '\r' || name.back() == ' ')) name.pop_back();
      if (first_ns < 0) first_ns = ns;
      const double t = static_cast<double>(ns - first_ns) * 1e-9;
      if (t < from_s || t >= to_s) {
        if (t >= to_s && first_after < 0) first_after = static_cast<double>(ns) * 1e-9;
        fs::create_symlink(source / name, images / name, ec);
        if (ec) return Error{"black out: cannot link " + (images / name).string() + ": " + ec.message()};
        continue;
      }
      const cv::Mat image = cv::imread((source / name).string(), cv::IMREAD_UNCHANGED);
      if (image.empty()) return Error{"black out: cannot read " + (source / name).string()};
      if (!cv::imwrite((images / name).string(), cv::Mat::zeros(image.size(), image.type())))
        return Error{"black out: cannot write " + (images / name).string()};
      ++blacked;
    }
  }
  if (blacked == 0)
    return Error{"black out " + view + ": no frame in [" + std::to_string(from_s) + ", " + std::to_string(to_s) + ") s"};
  return first_after;
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
