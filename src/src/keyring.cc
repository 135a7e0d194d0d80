#include "hermes/core/keyring.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <vector>

namespace hermes {

Expected<Keyring> Keyring::loadDir(const std::string& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    return Error{"auth: key directory " + dir +
                 " does not exist (create keys with ./hermes keys add ROBOT --dir " + dir + ")"};
  std::vector<fs::path> files;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->path().extension() == ".key") files.push_back(it->path());
  if (ec) return Error{"auth: cannot list key directory " + dir + ": " + ec.message()};
  std::sort(files.begin(), files.end());
  Keyring ring;
  for (const fs::path& file : files) {
    const std::string robot = file.stem().string();
    auto key = readKeyFile(file.string());
    if (!key) return Error{key.error()};
    const Uuid uuid = agentUuid(robot);
    if (const Entry* clash = ring.find(uuid))
      return Error{"auth: robots " + clash->robot + " and " + robot + " in " + dir +
                   " have the same uuid " + toString(uuid)};
    ring.add(uuid, robot, *key);
  }
  if (ring.size() == 0)
    return Error{"auth: key directory " + dir +
                 " holds no <robot>.key file (create one with ./hermes keys add ROBOT --dir " +
                 dir + ")"};
  return ring;
}

void Keyring::add(const Uuid& uuid, const std::string& robot, const FrameKey& key) {
  entries_[uuid] = Entry{robot, key};
}

const Keyring::Entry* Keyring::find(const Uuid& uuid) const {
  auto it = entries_.find(uuid);
  return it == entries_.end() ? nullptr : &it->second;
}

std::string expandHome(const std::string& path) {
  if (path.rfind("~/", 0) != 0) return path;
  const char* home = std::getenv("HOME");
  return std::string(home ? home : "") + path.substr(1);
}

}  // namespace hermes
