// Link traces: CSV `time_s,rate_mbitps,latency_ms,loss`; each row holds from its
// time until the next; rate 0 is an outage; loss is a fraction in [0, 1].
#pragma once

#include <string>
#include <vector>

#include "hermes/core/status.h"

namespace hermes {

struct LinkState {
  double rate_mbitps = 0;  ///< [Mbit/s], 0 = outage
  double latency_ms = 0;   ///< one-way [ms]
  double loss = 0;         ///< message loss probability
};

class LinkTrace {
 public:
  struct Row {
    double time_s;
    LinkState state;
  };
  /// A constant link (`--bandwidth`); rate <= 0 or infinity means unlimited.
  static LinkTrace constant(double rate_mbitps, double latency_ms = 0.0, double loss = 0.0);
  static Expected<LinkTrace> fromCsv(const std::string& path);
  static Expected<LinkTrace> fromString(const std::string& text, const std::string& origin);

  /// State in force at time t (the first row also covers t < its time).
  LinkState at(double t) const;
  /// Time of the next change strictly after t, or +inf.
  double nextChange(double t) const;
  bool unlimited() const { return unlimited_; }
  const std::vector<Row>& rows() const { return rows_; }

 private:
  std::vector<Row> rows_;
  bool unlimited_ = false;
};

}  // namespace hermes
