// bench system --full --jobs N: the table's runs ("cells") as child processes of
// the tool, N at a time. Each cell is the same command line narrowed to one
// variant and bandwidth (--variants V --bandwidths B --tracking-dir D --cell);
// it stores its row in the table's folder as a sequential run would, and the
// offline runner is deterministic, so the rows are the ones a sequential table
// gives. A tracking folder is written by the first cell that uses it (the
// recorder: a robot whose recording is missing or does not fit is tracked and
// recorded); the cells that replay it start once that cell has finished.
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
};

/// Runs every cell as `argv` + its narrowing options, at most `jobs` at once.
/// Returns the names of the cells that failed (exit status != 0).
inline std::vector<std::string> runCellsInChildren(const std::vector<Cell>& cells, int jobs,
                                                   const std::vector<std::string>& argv) {
  std::vector<std::string> failed;
  std::set<std::string> recorded;   // tracking folders whose recorder has finished
  std::set<std::string> recording;  // ... whose recorder runs
  std::map<pid_t, const Cell*> running;
  std::vector<const Cell*> waiting;
  for (const Cell& c : cells) waiting.push_back(&c);
  auto launch = [&](const Cell& c) {
    std::vector<std::string> args = argv;
    args.insert(args.end(), {"--variants", c.variant, "--bandwidths", c.bandwidth});
    if (!c.tracking_dir.empty()) args.insert(args.end(), {"--tracking-dir", c.tracking_dir});
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
    // Start what may start: a cell whose tracking folder is recorded, or the first
    // cell of a folder nobody records yet (it becomes the recorder).
    for (auto it = waiting.begin(); it != waiting.end() && static_cast<int>(running.size()) < jobs;) {
      const Cell& c = **it;
      const bool free = c.tracking_dir.empty() || recorded.count(c.tracking_dir);
      const bool recorder = !free && !recording.count(c.tracking_dir);
      if (!free && !recorder) {
        ++it;
        continue;
      }
      if (recorder) recording.insert(c.tracking_dir);
      launch(c);
      it = waiting.erase(it);
    }
    if (running.empty()) break;  // nothing runs and nothing may start: cannot happen
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
    if (recording.count(c.tracking_dir)) {  // its replayers may start (or record themselves)
      recording.erase(c.tracking_dir);
      recorded.insert(c.tracking_dir);
    }
  }
  for (const Cell* c : waiting) failed.push_back(c->name + " (not started)");
  return failed;
}

}  // namespace hermes::system::bench
