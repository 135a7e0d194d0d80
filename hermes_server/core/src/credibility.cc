// Credibility scores and the aging priority queue of pending submaps.
#include "hermes/server/credibility.h"

#include "hermes/server/byte_codec.h"

#include <algorithm>
#include <cmath>

namespace hermes {

Status CredibilityParams::read(const Config& c, const std::string& p) {
  std::string csa = enabled ? "on" : "off";
  if (auto s = c.getChoice(p + "csa", {"on", "off"}, &csa); !s) return s;
  enabled = csa == "on";
  const std::string q = p + "credibility.";
  for (auto s : {c.get(q + "w_ts", &w_ts), c.get(q + "w_mc", &w_mc),
                 c.get(q + "aging_per_s", &aging_per_s), c.get(q + "history", &history)})
    if (!s) return s;
  return validate();
}

void CredibilityParams::write(ConfigWriter& w, const std::string& p) const {
  w.set(p + "csa", std::string(enabled ? "on" : "off"));
  w.set(p + "credibility.w_ts", w_ts);
  w.set(p + "credibility.w_mc", w_mc);
  w.set(p + "credibility.aging_per_s", aging_per_s);
  w.set(p + "credibility.history", history);
}

Status CredibilityParams::validate() const {
  if (!(w_ts >= 0 && w_mc >= 0 && w_ts + w_mc > 0))
    return Error{"server.credibility.w_ts and w_mc must be >= 0 and not both 0, got w_ts=" + std::to_string(w_ts) +
                 ", w_mc=" + std::to_string(w_mc)};
  if (!(aging_per_s >= 0 && std::isfinite(aging_per_s)))
    return Error{"server.credibility.aging_per_s must be >= 0, got " + std::to_string(aging_per_s)};
  if (history < 0) return Error{"server.credibility.history must be >= 0"};
  return Status::Ok();
}

AgentEvidence AgentEvidence::from(const AgentStats& s, bool has_loops) {
  AgentEvidence e;
  e.success_rate = s.successRate();
  e.bytes_per_s = s.bytesPerSecond();
  e.obs_per_landmark = s.observationsPerLandmark();
  e.has_loops = has_loops;
  return e;
}

CredibilityAssessor::CredibilityAssessor(CredibilityParams params) : params_(std::move(params)) {
  Status s = params_.validate();
  HERMES_CHECK(s.ok(), s.error());
}

void CredibilityAssessor::setEvidence(RobotId agent, const AgentEvidence& e) {
  AgentEvidence clean = e;
  auto finite_or_zero = [](double v) { return std::isfinite(v) && v > 0 ? v : 0.0; };
  clean.success_rate = std::clamp(finite_or_zero(e.success_rate), 0.0, 1.0);
  clean.bytes_per_s = finite_or_zero(e.bytes_per_s);
  clean.obs_per_landmark = finite_or_zero(e.obs_per_landmark);
  evidence_[agent] = clean;
}

void CredibilityAssessor::updateFrom(const Bookkeeper& bk,
                                     const std::function<bool(RobotId)>& has_loops) {
  for (RobotId r : bk.robots())
    setEvidence(r, AgentEvidence::from(*bk.stats(r), has_loops ? has_loops(r) : false));
}

std::map<RobotId, CredibilityScore> CredibilityAssessor::scores() const {
  double max_bw = 0, max_opl = 0;
  for (const auto& [r, e] : evidence_) {
    max_bw = std::max(max_bw, e.bytes_per_s);
    max_opl = std::max(max_opl, e.obs_per_landmark);
  }
  std::map<RobotId, CredibilityScore> out;
  for (const auto& [r, e] : evidence_) {
    CredibilityScore s;
    s.ts = e.success_rate * (max_bw > 0 ? e.bytes_per_s / max_bw : 0.0);
    s.mc = e.has_loops ? 1.0 : (max_opl > 0 ? e.obs_per_landmark / max_opl : 0.0);
    s.c = params_.w_ts * s.ts + params_.w_mc * s.mc;
    out[r] = s;
  }
  return out;
}

CredibilityScore CredibilityAssessor::score(RobotId agent) const {
  auto all = scores();
  auto it = all.find(agent);
  return it == all.end() ? CredibilityScore{} : it->second;
}

void CredibilityAssessor::push(const PendingSubmap& item) {
  queues_[item.agent].push_back(Queued{item, pushes_++});
  ++size_;
}

std::optional<PopRecord> CredibilityAssessor::pop(double now) {
  if (size_ == 0) return std::nullopt;
  const auto all = scores();
  std::deque<Queued>* best_q = nullptr;
  double best_p = 0;
  CredibilityScore best_s;
  for (auto& [agent, q] : queues_) {
    if (q.empty()) continue;
    const Queued& head = q.front();
    auto it = all.find(agent);
    const CredibilityScore s = it == all.end() ? CredibilityScore{} : it->second;
    const double p = params_.enabled
                         ? s.c + params_.aging_per_s * (now - head.item.arrival)
                         : -static_cast<double>(head.push_order);
    const bool better = !best_q || p > best_p ||
                        (p == best_p && head.push_order < best_q->front().push_order);
    if (better) {
      best_q = &q;
      best_p = p;
      best_s = s;
    }
  }
  PopRecord rec;
  rec.item = best_q->front().item;
  rec.order = pops_++;
  rec.popped_at = now;
  rec.waited_s = now - rec.item.arrival;
  rec.score = best_s;
  rec.priority = best_p;
  rec.queue_size = size_;
  best_q->pop_front();
  --size_;
  if (params_.history > 0) {
    history_.push_back(rec);
    while (history_.size() > static_cast<std::size_t>(params_.history)) history_.pop_front();
  }
  if (logger_) logger_(rec);
  return rec;
}

namespace {

void saveItem(server::ByteWriter* w, const PendingSubmap& p) {
  w->pod(p.agent);
  w->pod(p.session);
  w->pod(p.seq);
  w->pod(p.arrival);
  w->pod(p.handle);
}

bool loadItem(server::ByteReader* r, PendingSubmap* p) {
  return r->pod(&p->agent) && r->pod(&p->session) && r->pod(&p->seq) && r->pod(&p->arrival) &&
         std::isfinite(p->arrival) && r->pod(&p->handle);
}

}  // namespace

std::vector<PendingSubmap> CredibilityAssessor::pending() const {
  std::vector<PendingSubmap> out;
  for (const auto& [agent, q] : queues_)
    for (const Queued& e : q) out.push_back(e.item);
  return out;
}

void CredibilityAssessor::save(server::ByteWriter* w) const {
  w->pod(pushes_);
  w->pod(pops_);
  w->count(size_);
  for (const auto& [agent, q] : queues_)
    for (const Queued& e : q) {
      saveItem(w, e.item);
      w->pod(e.push_order);
    }
  w->count(history_.size());
  for (const PopRecord& h : history_) {
    saveItem(w, h.item);
    w->pod(h.order);
    for (double v : {h.popped_at, h.waited_s, h.score.ts, h.score.mc, h.score.c, h.priority}) w->pod(v);
    w->count(h.queue_size);
  }
}

bool CredibilityAssessor::load(server::ByteReader* r) {
  std::uint64_t n = 0;
  if (size_ != 0 || !history_.empty() || !r->pod(&pushes_) || !r->pod(&pops_) || !r->count(&n, 40))
    return false;
  for (std::uint64_t i = 0; i < n; ++i) {
    Queued e;
    if (!loadItem(r, &e.item) || !r->pod(&e.push_order) || e.push_order >= pushes_) return false;
    auto& q = queues_[e.item.agent];
    if (!q.empty() && q.back().push_order >= e.push_order) return false;  // arrival order
    q.push_back(e);
    ++size_;
  }
  if (!r->count(&n, 96)) return false;
  for (std::uint64_t i = 0; i < n; ++i) {
    PopRecord h;
    std::uint64_t queue_size = 0;
    if (!loadItem(r, &h.item) || !r->pod(&h.order) || !r->pod(&h.popped_at) ||
        !r->pod(&h.waited_s) || !r->pod(&h.score.ts) || !r->pod(&h.score.mc) ||
        !r->pod(&h.score.c) || !r->pod(&h.priority) || !r->pod(&queue_size))
      return false;
    h.queue_size = static_cast<std::size_t>(queue_size);
    history_.push_back(h);
  }
  return true;
}

}  // namespace hermes
