#include "rendered_hall.h"

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>

namespace hermes::test_support {
namespace fs = std::filesystem;

const std::vector<std::string>& hallSequences() {
  static const std::vector<std::string> seqs = {"MH_01_easy", "MH_02_easy", "MH_03_medium"};
  return seqs;
}

namespace {

/// Renders `seqs` (config/trajectories) into the temp dir's test cache as
/// `name`, once per machine; "" when rendering failed.
std::string renderOnce(const std::string& name, const std::vector<std::string>& seqs,
                       const std::string& options) {
  const fs::path dir = fs::temp_directory_path() / "hermes_test_cache" / name;
  if (fs::exists(dir / "done")) return dir.string();
  const fs::path tmp = dir.string() + ".tmp" + std::to_string(::getpid());
  fs::remove_all(tmp);
  const fs::path bin = fs::read_symlink("/proc/self/exe").parent_path().parent_path() / "bin";
  std::string cmd = (bin / "hermes_sim").string();
  for (const std::string& s : seqs)
    cmd += std::string(" --trajectory ") + HERMES_SOURCE_DIR + "/config/trajectories/" + s + ".txt";
  cmd += " --out " + tmp.string() + " " + options + " >/dev/null 2>&1";
  if (std::system(cmd.c_str()) != 0) return "";
  std::ofstream(tmp / "done") << "ok\n";
  std::error_code ec;
  fs::create_directories(dir.parent_path(), ec);
  fs::rename(tmp, dir, ec);  // another process may have won the race: fine
  if (ec) fs::remove_all(tmp);
  return fs::exists(dir / "done") ? dir.string() : "";
}

}  // namespace

std::string renderedHall() {
  return renderOnce("hall_d10_r10_s1", hallSequences(), "--duration 10 --rate 10 --seed 1 --plain");
}

const std::vector<std::string>& meetingSequences() {
  static const std::vector<std::string> seqs = {"MH_01_easy", "MH_02_easy"};
  return seqs;
}

std::string renderedMeeting() {
  return renderOnce("meeting_s40_d30_r10_s1", meetingSequences(),
                    "--start 40 --duration 30 --rate 10 --seed 1 --plain");
}

}  // namespace hermes::test_support
