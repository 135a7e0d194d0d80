// Results of a long benchmark kept run by run on disk, so that an interrupted
// sweep (`./hermes bench system --full`) resumes where it stopped instead of
// starting over. Layout of a store folder:
//   DIR/setup.json            what every run shares (data, rate, overrides, ...)
//   DIR/<run>/bench_row.json  one finished run's result row
//   DIR/<run>/...             the run's own outputs (metrics, trajectories, CSVs)
// A row is written atomically (temporary file + rename) only once its run has
// finished, so a run killed midway is simply run again. A store made with
// another setup is refused with the first differing key named: rows of two
// different experiments never end up in one table.
#pragma once

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "hermes/core/status.h"

namespace hermes::system {

class BenchStore {
 public:
  /// Opens (creates) `dir`. A fresh folder gets `setup` as its setup.json; an
  /// existing one must hold the same setup. Errors: the folder cannot be made, a
  /// damaged setup.json, a different setup (names the key and both values).
  static Expected<BenchStore> open(const std::string& dir, const nlohmann::json& setup);

  /// The finished run's row, or nothing when the run has not finished (no row,
  /// or a row that does not parse: it is run again, with a warning on stderr).
  std::optional<nlohmann::json> find(const std::string& run) const;
  /// Writes the run's row atomically.
  Status save(const std::string& run, const nlohmann::json& row) const;
  /// The run's own folder (DIR/<run>).
  std::string runDir(const std::string& run) const;
  const std::string& dir() const { return dir_; }

 private:
  std::string dir_;
};

}  // namespace hermes::system
