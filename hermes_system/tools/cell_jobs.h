// bench system --full --jobs N: the table's runs ("cells") as child processes of
// the tool, N at a time. Each cell is the same command line narrowed to one
// variant and bandwidth (--variants V --bandwidths B --tracking-dir D --cell);
// it stores its row in the table's folder as a sequential run would, and the
// offline runner is deterministic, so the rows are the ones a sequential table
// gives. Before the cells of a tracking folder start, one recorder per robot
// (--record-robot NAME) tracks that robot alone and records it there, unless its
// recording fits already: a robot's recording does not depend on the others or
// on the server (a one-robot and a three-robot run record the same bytes), so
// the recording, the slowest part of a table, runs N robots at a time too.
// Header-only, like bench_args.h.
#pragma once

#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace hermes::system::bench {

struct Cell {
  std::string name;          ///< e.g. hermes_10
  std::string variant;       ///< --variants
  std::string bandwidth;     ///< --bandwidths
  std::string tracking_dir;  ///< empty: live tracking (no dependency)
  std::string record_robot;  ///< set: a recorder of this robot (no row), not a cell
};

/// Runs every cell as `argv` + its narrowing options, at most `jobs` at once.
/// Returns the names of the cells that failed (exit status != 0).
inline std::vector<std::string> runCellsInChildren(const std::vector<Cell>& cells, int jobs,
                                                   const std::vector<std::string>& argv) {
  std::vector<std::string> failed;
  std::map<std::string, int> recorders_left;  // per tracking folder: recorders not finished
  std::set<std::string> broken;               // tracking folders a recorder failed for
  std::map<pid_t, const Cell*> running;
  std::vector<const Cell*> waiting;
  for (const Cell& c : cells) {
    waiting.push_back(&c);
    if (!c.record_robot.empty()) ++recorders_left[c.tracking_dir];
  }
  auto launch = [&](const Cell& c) {
    std::vector<std::string> args = argv;
    args.insert(args.end(), {"--variants", c.variant, "--bandwidths", c.bandwidth});
    if (!c.tracking_dir.empty()) args.insert(args.end(), {"--tracking-dir", c.tracking_dir});
    if (!c.record_robot.empty()) args.insert(args.end(), {"--record-robot", c.record_robot});
    args.push_back("--cell");
    const pid_t pid = ::fork();
    if (pid == 0) {
      std::vector<char*> cargs;
      for (std::string& a : args) cargs.push_back(a.data());
      cargs.push_back(nullptr);
      ::execv("/proc/self/exe", cargs.data());
      std::perror("hermes_bench_system: exec");
      ::_exit(127);
    }
    if (pid < 0) {
      failed.push_back(c.name + " (fork failed)");
      return;
    }
    running[pid] = &c;
    std::fprintf(stderr, "hermes_bench_system: %s started (pid %d, %zu running)\n", c.name.c_str(), pid,
                 running.size());
  };
  while (!waiting.empty() || !running.empty()) {
    // Recorders start at once; a cell once its tracking folder's recorders are done.
    for (auto it = waiting.begin(); it != waiting.end() && static_cast<int>(running.size()) < jobs;) {
      const Cell& c = **it;
      const bool ready = !c.record_robot.empty() || c.tracking_dir.empty() || recorders_left[c.tracking_dir] == 0;
      if (!ready || broken.count(c.tracking_dir)) {
        ++it;
        continue;
      }
      launch(c);
      it = waiting.erase(it);
    }
    if (running.empty()) break;  // what waits cannot start (a recorder failed)
    int status = 0;
    const pid_t pid = ::waitpid(-1, &status, 0);
    if (pid < 0) break;
    auto r = running.find(pid);
    if (r == running.end()) continue;
    const Cell& c = *r->second;
    running.erase(r);
    const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    if (!ok) failed.push_back(c.name);
    std::fprintf(stderr, "hermes_bench_system: %s %s\n", c.name.c_str(), ok ? "finished" : "FAILED");
    if (!c.record_robot.empty()) {
      --recorders_left[c.tracking_dir];
      if (!ok) broken.insert(c.tracking_dir);  // its cells would record it all at once: not started
    }
  }
  for (const Cell* c : waiting) failed.push_back(c->name + " (not started)");
  return failed;
}

}  // namespace hermes::system::bench
