// Layered YAML configuration. Each module owns one Params struct with
//   Status read(const Config&), void write(ConfigWriter&), Status validate().
// A Config is built from a YAML file plus `--set key=value` overrides; reading
// marks keys as used so that unknown keys (typos) can be reported by name.
#pragma once

#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "hermes/core/status.h"

namespace hermes {

class Config {
 public:
  Config();
  ~Config();
  Config(const Config&);
  Config& operator=(const Config&);

  /// Loads a YAML file; errors name the file and the YAML problem (line).
  static Expected<Config> fromFile(const std::string& path);
  static Expected<Config> fromString(const std::string& yaml, const std::string& origin);

  /// Applies "a.b.c=value" (creates the key; unknown keys are reported by
  /// unusedKeys() after the modules have read the config).
  Status applyOverride(const std::string& assignment);

  /// Typed getters for dotted keys. If the key is missing, *out keeps its
  /// default and Ok is returned; a present key with the wrong type is an error
  /// that names key and origin.
  Status get(const std::string& key, double* out) const;
  Status get(const std::string& key, int* out) const;
  Status get(const std::string& key, bool* out) const;
  Status get(const std::string& key, std::string* out) const;
  Status get(const std::string& key, std::vector<double>* out) const;
  /// String restricted to a set of choices.
  Status getChoice(const std::string& key, const std::vector<std::string>& choices,
                   std::string* out) const;
  bool has(const std::string& key) const;

  /// Leaf keys present in the config (file or overrides) that no get() asked for.
  std::vector<std::string> unusedKeys() const;
  const std::string& origin() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Collects the configuration actually used, written next to every run's results.
class ConfigWriter {
 public:
  void set(const std::string& key, double v);
  void set(const std::string& key, int v);
  void set(const std::string& key, bool v);
  void set(const std::string& key, const std::string& v);
  void set(const std::string& key, const std::vector<double>& v);
  /// Nested YAML text.
  std::string yaml() const;
  /// Every key written, dotted, with its YAML scalar / flow text (sorted by key).
  const std::map<std::string, std::string>& values() const { return values_; }

 private:
  std::map<std::string, std::string> values_;  // dotted key -> YAML scalar/flow text
};

}  // namespace hermes
