#include "hermes/system/bench_store.h"

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace hermes::system {
namespace fs = std::filesystem;

namespace {

Expected<nlohmann::json> readJson(const fs::path& path) {
  std::ifstream f(path);
  if (!f) return Error{"cannot read " + path.string()};
  std::stringstream ss;
  ss << f.rdbuf();
  try {
    return nlohmann::json::parse(ss.str());
  } catch (const std::exception& e) {
    return Error{path.string() + ": not JSON (" + e.what() + ")"};
  }
}

Status writeAtomic(const fs::path& path, const nlohmann::json& j) {
  const fs::path tmp = path.string() + ".tmp";
  {
    std::ofstream f(tmp);
    f << j.dump(2) << "\n";
    if (!f) return Error{"cannot write " + tmp.string()};
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) return Error{"cannot rename " + tmp.string() + " to " + path.string() + ": " + ec.message()};
  return {};
}

}  // namespace

Expected<BenchStore> BenchStore::open(const std::string& dir, const nlohmann::json& setup) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Error{"cannot create " + dir + ": " + ec.message()};
  const fs::path path = fs::path(dir) / "setup.json";
  if (fs::exists(path)) {
    auto held = readJson(path);
    if (!held.ok()) return Error{held.error() + " (remove the folder to start over)"};
    for (const auto& [key, value] : setup.items()) {
      const bool same = held->contains(key) && (*held)[key] == value;
      if (!same)
        return Error{dir + " holds runs made with another setup: " + key + " was " +
                     (held->contains(key) ? (*held)[key].dump() : std::string("(absent)")) + ", now " +
                     value.dump() + " (use another --out, or remove the folder to start over)"};
    }
  } else if (Status s = writeAtomic(path, setup); !s) {
    return Error{s.error()};
  }
  BenchStore store;
  store.dir_ = dir;
  return store;
}

std::optional<nlohmann::json> BenchStore::find(const std::string& run) const {
  const fs::path path = fs::path(runDir(run)) / "bench_row.json";
  if (!fs::exists(path)) return std::nullopt;
  auto row = readJson(path);
  if (!row.ok()) {
    std::fprintf(stderr, "warning: %s; the run is made again\n", row.error().c_str());
    return std::nullopt;
  }
  return *row;
}

Status BenchStore::save(const std::string& run, const nlohmann::json& row) const {
  std::error_code ec;
  fs::create_directories(runDir(run), ec);
  if (ec) return Error{"cannot create " + runDir(run) + ": " + ec.message()};
  return writeAtomic(fs::path(runDir(run)) / "bench_row.json", row);
}

std::string BenchStore::runDir(const std::string& run) const { return (fs::path(dir_) / run).string(); }

}  // namespace hermes::system
