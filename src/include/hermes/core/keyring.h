// The server's keyring: which robots may send frames, and with which key.
// Loaded from a key directory holding one `<robot>.key` per robot
// (frame_auth.h; created by `./hermes keys add ROBOT --dir DIR`); a robot's
// frames carry uuid agentUuid(<robot>), which is how a frame finds its key.
#pragma once

#include <map>
#include <string>

#include "hermes/core/frame_auth.h"
#include "hermes/core/map_types.h"

namespace hermes {

class Keyring {
 public:
  struct Entry {
    std::string robot;  ///< the key file's name without ".key"
    FrameKey key;
  };

  /// Every `*.key` file in `dir` (other files are ignored). Errors: the folder
  /// cannot be read, a key file is unreadable, malformed or not private, two
  /// robot names give one uuid, or no key at all (a server that accepts nobody
  /// is a configuration mistake). Names the file in every message.
  static Expected<Keyring> loadDir(const std::string& dir);

  /// Adds (or replaces) a robot's key under its uuid.
  void add(const Uuid& uuid, const std::string& robot, const FrameKey& key);
  /// The entry of a uuid, nullptr for an unknown robot.
  const Entry* find(const Uuid& uuid) const;
  std::size_t size() const { return entries_.size(); }

 private:
  std::map<Uuid, Entry> entries_;
};

/// `path` with a leading "~/" replaced by $HOME/ (config values are written
/// like "~/.config/hermes/keys"); other paths unchanged.
std::string expandHome(const std::string& path);

}  // namespace hermes
