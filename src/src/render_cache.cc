#include "hermes/core/render_cache.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <sstream>
#include <thread>

#include <unistd.h>

#include "hermes/core/render/settings.h"

namespace hermes {
namespace fs = std::filesystem;

namespace {

std::string quote(const std::string& s) { return "'" + s + "'"; }

std::string number(const char* flag, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, " %s %.17g", flag, v);  // exact: the fingerprint must match
  return buf;
}

std::string readText(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

}  // namespace

Expected<std::string> renderFingerprint(const RenderRequest& req) {
  auto s = render::readRenderSettings(Config(), req.settings);
  if (!s.ok()) return Error{s.error()};
  s->scene.seed = static_cast<std::uint64_t>(req.seed);
  if (req.poor_fraction >= 0) s->scene.poor_fraction = req.poor_fraction;
  return s->fingerprint();
}

bool isPlainLook(const RenderRequest& req, const std::string& fingerprint) {
  RenderRequest plain = req;
  plain.settings = {render::kPlainLook};
  auto f = renderFingerprint(plain);
  return f.ok() && *f == fingerprint;
}

Status renderCached(const RenderRequest& req, const std::string& folder) {
  const fs::path done(folder);
  auto fingerprint = renderFingerprint(req);
  if (!fingerprint.ok()) return Error{"render " + folder + ": " + fingerprint.error()};
  if (fs::exists(done / "done")) {
    if (fs::exists(done / "render_config.yaml")) {
      if (readText(done / "render_config.yaml") == *fingerprint) return Status::Ok();
      std::fprintf(stderr, "[render] %s was rendered with other settings: rendering again\n", folder.c_str());
    } else if (isPlainLook(req, *fingerprint)) {
      return Status::Ok();  // rendered before the settings file existed, with the plain look
    }
  }
  if (req.trajectories.empty()) return Error{"render " + folder + ": no trajectory given"};
  std::error_code ec;
  const fs::path sim = fs::read_symlink("/proc/self/exe", ec).parent_path() / "hermes_sim";
  if (ec || !fs::exists(sim)) return Error{"hermes_sim not found at " + sim.string() + " (build target hermes_sim)"};
  const fs::path partial = folder + ".partial." + std::to_string(::getpid());
  const std::string log = folder + ".log";
  std::string cmd = quote(sim.string());
  for (const std::string& t : req.trajectories) {
    if (!fs::exists(t)) return Error{"render " + folder + ": trajectory not found: " + t};
    cmd += " --trajectory " + quote(t);
  }
  cmd += " --out " + quote(partial.string()) + number("--start", req.start_s) +
         " --seed " + std::to_string(req.seed);
  if (req.duration_s > 0) cmd += number("--duration", req.duration_s);
  if (req.rate_hz > 0) cmd += number("--rate", req.rate_hz);
  if (req.poor_fraction >= 0) cmd += number("--poor-fraction", req.poor_fraction);
  for (const std::string& kv : req.settings) cmd += " --set " + quote(kv);
  // Robots rendered at once, one per core (the bytes do not depend on it).
  const std::size_t cores = std::max(1u, std::thread::hardware_concurrency());
  cmd += " --jobs " + std::to_string(std::min<std::size_t>({cores, req.trajectories.size(), 64}));
  std::fprintf(stderr, "[render] %zu trajectories into %s (log %s)\n", req.trajectories.size(),
               folder.c_str(), log.c_str());
  fs::create_directories(done.parent_path(), ec);
  if (std::system((cmd + " >" + quote(log) + " 2>&1").c_str()) != 0) {
    fs::remove_all(partial, ec);
    return Error{"rendering failed (" + cmd + "; see " + log + ")"};
  }
  std::ofstream(partial / "done") << "ok\n";
  fs::remove_all(done, ec);  // an unfinished render of an older version
  fs::rename(partial, done, ec);
  if (ec) {  // another run finished the same render first: use that one
    fs::remove_all(partial, ec);
    if (!fs::exists(done / "done")) return Error{"cannot move the render to " + folder};
  }
  return Status::Ok();
}

}  // namespace hermes
