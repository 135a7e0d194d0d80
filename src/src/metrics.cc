#include "hermes/core/metrics.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>

namespace hermes {

using nlohmann::json;

// ---------------------------------------------------------------- timings

void TimingStats::add(const std::string& stage, double ms) {
  samples_[stage].push_back(ms);
  trim(stage);
}

void TimingStats::trim(const std::string& stage) {
  // Amortised O(1): the oldest are dropped in one go once 2 W samples are held.
  auto& v = samples_[stage];
  if (window_ == 0 || v.size() < 2 * window_) return;
  const size_t drop = v.size() - window_;
  v.erase(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(drop));
  dropped_[stage] += drop;
}

void TimingStats::merge(const TimingStats& other) {
  for (const auto& [stage, v] : other.samples_) {
    auto& dst = samples_[stage];
    dst.insert(dst.end(), v.begin(), v.end());
    trim(stage);
  }
  for (const auto& [stage, n] : other.dropped_) dropped_[stage] += n;
}

size_t TimingStats::count(const std::string& stage) const {
  auto it = samples_.find(stage);
  if (it == samples_.end()) return 0;
  auto d = dropped_.find(stage);
  return it->second.size() + (d == dropped_.end() ? 0 : d->second);
}

double timing::percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const double pos = std::clamp(q, 0.0, 100.0) / 100.0 * double(v.size() - 1);
  const size_t lo = size_t(std::floor(pos));
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - double(lo)) * (v[hi] - v[lo]);
}

std::map<std::string, StageTiming> TimingStats::summary() const {
  std::map<std::string, StageTiming> out;
  for (const auto& [stage, v] : samples_) {
    if (v.empty()) continue;
    const size_t keep = window_ == 0 ? v.size() : std::min(v.size(), window_);
    const std::vector<double> recent(v.end() - static_cast<std::ptrdiff_t>(keep), v.end());
    out[stage] = {timing::percentile(recent, 50), timing::percentile(recent, 95),
                  int64_t(count(stage))};
  }
  return out;
}

// ---------------------------------------------------------------- writing

namespace {

template <class T>
json orNull(const std::optional<T>& v) {
  return v ? json(*v) : json(nullptr);
}

json statsJson(const AccuracyStats& s) {
  return {{"rmse", s.rmse}, {"mean", s.mean}, {"median", s.median}, {"max", s.max},
          {"std", s.std}};
}

}  // namespace

void to_json(json& j, const AgentMetrics& m) {
  j = json::object();
  j["agent"] = m.agent;
  j["ate_rmse_m"] = orNull(m.ate_rmse_m);
  j["lost_rate"] = orNull(m.lost_rate);
  j["keyframes"] = orNull(m.keyframes);
  j["landmarks"] = orNull(m.landmarks);
  j["bytes"] = orNull(m.bytes);
  j["submaps_sent"] = orNull(m.submaps_sent);
  j["submaps_applied"] = orNull(m.submaps_applied);
  j["submaps_deferred"] = orNull(m.submaps_deferred);
  if (m.ate_m) j["ate_m"] = statsJson(*m.ate_m);
  if (m.merged_ate_rmse_m) j["merged_ate_rmse_m"] = *m.merged_ate_rmse_m;
  if (m.raw_ate_rmse_m) j["raw_ate_rmse_m"] = *m.raw_ate_rmse_m;
  if (m.rpe_trans_rmse_m) j["rpe_trans_rmse_m"] = *m.rpe_trans_rmse_m;
  if (m.rpe_rot_rmse_deg) j["rpe_rot_rmse_deg"] = *m.rpe_rot_rmse_deg;
  if (m.matched_poses) j["matched_poses"] = *m.matched_poses;
  if (m.unmatched_poses) j["unmatched_poses"] = *m.unmatched_poses;
  if (m.scale) j["scale"] = *m.scale;
  if (m.held_submaps) j["held_submaps"] = *m.held_submaps;
  if (m.held_bytes) j["held_bytes"] = *m.held_bytes;
  if (m.held_bytes_peak) j["held_bytes_peak"] = *m.held_bytes_peak;
  if (m.weak_frames) j["weak_frames"] = *m.weak_frames;
  if (m.trouble_windows) j["trouble_windows"] = *m.trouble_windows;
  if (m.global_pose_rmse_m) j["global_pose_rmse_m"] = *m.global_pose_rmse_m;
  if (m.global_pose_final_m) j["global_pose_final_m"] = *m.global_pose_final_m;
  if (m.global_pose_updates) j["global_pose_updates"] = *m.global_pose_updates;
  if (m.sessions) j["sessions"] = *m.sessions;
  if (m.relocalised) j["relocalised"] = *m.relocalised;
  if (m.reported_new) j["reported_new"] = *m.reported_new;
  if (m.frames_skipped) j["frames_skipped"] = *m.frames_skipped;
  if (m.new_maps) j["new_maps"] = *m.new_maps;
  if (m.borrowed_relocalisations) j["borrowed_relocalisations"] = *m.borrowed_relocalisations;
  if (m.borrowed_landmarks) j["borrowed_landmarks"] = *m.borrowed_landmarks;
  if (m.borrowed_memory_bytes) j["borrowed_memory_bytes"] = *m.borrowed_memory_bytes;
  if (m.downlink_bytes) j["downlink_bytes"] = *m.downlink_bytes;
  if (!m.frames_skipped_causes.empty()) j["frames_skipped_causes"] = m.frames_skipped_causes;
}

void to_json(json& j, const RunMetrics& m) {
  j = json::object();
  j["ate_rmse_m"] = orNull(m.ate_rmse_m);
  j["per_agent"] = json::array();
  for (const AgentMetrics& a : m.per_agent) j["per_agent"].push_back(a);
  j["bytes_total"] = orNull(m.bytes_total);
  j["kBps_mean"] = orNull(m.kBps_mean);
  j["kBps_peak"] = orNull(m.kBps_peak);
  j["loops_accepted"] = orNull(m.loops_accepted);
  j["loops_rejected"] = orNull(m.loops_rejected);
  j["agents_merged"] = orNull(m.agents_merged);
  j["timings_ms"] = json::object();
  for (const auto& [stage, t] : m.timings_ms)
    j["timings_ms"][stage] = {{"median", t.median}, {"p95", t.p95}, {"count", t.count}};
  if (m.alignment) {
    json a = {{"mode", *m.alignment}};
    if (m.T_gt_est) {
      const Vec3& t = m.T_gt_est->translation();
      const Quat& q = m.T_gt_est->quat();
      a["t_xyz"] = {t.x(), t.y(), t.z()};
      a["q_xyzw"] = {q.x(), q.y(), q.z(), q.w()};
    }
    if (m.scale) a["scale"] = *m.scale;
    j["alignment"] = a;
  }
  if (m.ate_m) j["ate_m"] = statsJson(*m.ate_m);
  if (m.matched_poses) j["matched_poses"] = *m.matched_poses;
  if (m.unmatched_poses) j["unmatched_poses"] = *m.unmatched_poses;
  if (m.max_dt_s) j["max_dt_s"] = *m.max_dt_s;
  if (m.rpe_delta) j["rpe_delta"] = *m.rpe_delta;
  if (m.rpe_delta_unit) j["rpe_delta_unit"] = *m.rpe_delta_unit;
  if (!m.frames_refused.empty()) j["frames_refused"] = m.frames_refused;
  if (m.relocalised) j["relocalised"] = *m.relocalised;
  if (m.robots_new) j["robots_new"] = *m.robots_new;
  if (m.loops_bridged) j["loops_bridged"] = *m.loops_bridged;
  if (m.incomplete) j["incomplete"] = *m.incomplete;
  if (m.stopped_because) j["stopped_because"] = *m.stopped_because;
}

// ---------------------------------------------------------------- reading

namespace {

struct FieldError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

const char* typeName(const json& v) { return v.type_name(); }

/// Reads members of one JSON object; `where` is the dotted path of the object.
class ObjectReader {
 public:
  ObjectReader(const json& obj, std::string where) : obj_(obj), where_(std::move(where)) {
    if (!obj_.is_object())
      throw FieldError("'" + (where_.empty() ? std::string("<root>") : where_) +
                       "' must be an object, got " + typeName(obj_));
  }

  std::string field(const std::string& key) const {
    return where_.empty() ? key : where_ + "." + key;
  }
  /// nullptr when absent; throws when required and absent.
  const json* get(const std::string& key, bool required) const {
    auto it = obj_.find(key);
    if (it == obj_.end()) {
      if (required) throw FieldError("missing field '" + field(key) + "'");
      return nullptr;
    }
    return &*it;
  }

  std::optional<double> number(const std::string& key, bool required) const {
    const json* v = get(key, required);
    if (!v || v->is_null()) return std::nullopt;
    if (!v->is_number())
      throw FieldError("field '" + field(key) + "' must be a number or null, got " +
                       typeName(*v));
    return v->get<double>();
  }
  std::optional<int64_t> integer(const std::string& key, bool required) const {
    const json* v = get(key, required);
    if (!v || v->is_null()) return std::nullopt;
    if (v->is_number_integer()) return v->get<int64_t>();
    if (v->is_number_float()) {
      const double d = v->get<double>();
      if (std::isfinite(d) && d == std::floor(d) && std::abs(d) < 9e15) return int64_t(d);
    }
    throw FieldError("field '" + field(key) + "' must be an integer or null, got " +
                     (v->is_number() ? v->dump() : std::string(typeName(*v))));
  }
  std::optional<bool> boolean(const std::string& key, bool required) const {
    const json* v = get(key, required);
    if (!v || v->is_null()) return std::nullopt;
    if (!v->is_boolean())
      throw FieldError("field '" + field(key) + "' must be true or false, got " + typeName(*v));
    return v->get<bool>();
  }
  /// An object of integer counts ({"cause": n}); empty when absent.
  std::map<std::string, int64_t> counts(const std::string& key) const {
    std::map<std::string, int64_t> out;
    const json* v = get(key, false);
    if (!v || v->is_null()) return out;
    ObjectReader r(*v, field(key));
    for (const auto& [name, n] : v->items()) {
      auto c = r.integer(name, true);
      if (!c) throw FieldError("field '" + r.field(name) + "' must be an integer, got null");
      out[name] = *c;
    }
    return out;
  }
  std::optional<std::string> string(const std::string& key, bool required) const {
    const json* v = get(key, required);
    if (!v || v->is_null()) return std::nullopt;
    if (!v->is_string())
      throw FieldError("field '" + field(key) + "' must be a string, got " + typeName(*v));
    return v->get<std::string>();
  }
  std::vector<double> numbers(const std::string& key, size_t n) const {
    const json* v = get(key, true);
    if (!v->is_array() || v->size() != n)
      throw FieldError("field '" + field(key) + "' must be an array of " + std::to_string(n) +
                       " numbers");
    std::vector<double> out;
    for (const json& e : *v) {
      if (!e.is_number()) throw FieldError("field '" + field(key) + "' holds a non-number");
      out.push_back(e.get<double>());
    }
    return out;
  }
  std::optional<AccuracyStats> stats(const std::string& key) const {
    const json* v = get(key, false);
    if (!v || v->is_null()) return std::nullopt;
    ObjectReader r(*v, field(key));
    AccuracyStats s;
    s.rmse = *r.numberRequired("rmse");
    s.mean = *r.numberRequired("mean");
    s.median = *r.numberRequired("median");
    s.max = *r.numberRequired("max");
    s.std = *r.numberRequired("std");
    return s;
  }
  std::optional<double> numberRequired(const std::string& key) const {
    auto v = number(key, true);
    if (!v) throw FieldError("field '" + field(key) + "' must be a number, got null");
    return v;
  }

 private:
  const json& obj_;
  std::string where_;
};

AgentMetrics parseAgent(const json& j, const std::string& where) {
  ObjectReader r(j, where);
  AgentMetrics a;
  auto name = r.string("agent", true);
  if (!name) throw FieldError("field '" + r.field("agent") + "' must be a string, got null");
  a.agent = *name;
  a.ate_rmse_m = r.number("ate_rmse_m", true);
  a.lost_rate = r.number("lost_rate", true);
  a.keyframes = r.integer("keyframes", true);
  a.landmarks = r.integer("landmarks", true);
  a.bytes = r.integer("bytes", true);
  a.submaps_sent = r.integer("submaps_sent", true);
  a.submaps_applied = r.integer("submaps_applied", true);
  a.submaps_deferred = r.integer("submaps_deferred", true);
  a.ate_m = r.stats("ate_m");
  a.merged_ate_rmse_m = r.number("merged_ate_rmse_m", false);
  a.raw_ate_rmse_m = r.number("raw_ate_rmse_m", false);
  a.rpe_trans_rmse_m = r.number("rpe_trans_rmse_m", false);
  a.rpe_rot_rmse_deg = r.number("rpe_rot_rmse_deg", false);
  a.matched_poses = r.integer("matched_poses", false);
  a.unmatched_poses = r.integer("unmatched_poses", false);
  a.scale = r.number("scale", false);
  a.held_submaps = r.integer("held_submaps", false);
  a.held_bytes = r.integer("held_bytes", false);
  a.held_bytes_peak = r.integer("held_bytes_peak", false);
  a.weak_frames = r.integer("weak_frames", false);
  a.trouble_windows = r.integer("trouble_windows", false);
  a.global_pose_rmse_m = r.number("global_pose_rmse_m", false);
  a.global_pose_final_m = r.number("global_pose_final_m", false);
  a.global_pose_updates = r.integer("global_pose_updates", false);
  a.sessions = r.integer("sessions", false);
  a.relocalised = r.integer("relocalised", false);
  a.reported_new = r.integer("reported_new", false);
  a.frames_skipped = r.integer("frames_skipped", false);
  a.new_maps = r.integer("new_maps", false);
  a.borrowed_relocalisations = r.integer("borrowed_relocalisations", false);
  a.borrowed_landmarks = r.integer("borrowed_landmarks", false);
  a.borrowed_memory_bytes = r.integer("borrowed_memory_bytes", false);
  a.downlink_bytes = r.integer("downlink_bytes", false);
  a.frames_skipped_causes = r.counts("frames_skipped_causes");
  return a;
}

RunMetrics parseRun(const json& j) {
  ObjectReader r(j, "");
  RunMetrics m;
  m.ate_rmse_m = r.number("ate_rmse_m", true);
  const json* agents = r.get("per_agent", true);
  if (!agents->is_array())
    throw FieldError(std::string("field 'per_agent' must be a list, got ") + typeName(*agents));
  for (size_t i = 0; i < agents->size(); ++i)
    m.per_agent.push_back(parseAgent((*agents)[i], "per_agent[" + std::to_string(i) + "]"));
  m.bytes_total = r.integer("bytes_total", true);
  m.kBps_mean = r.number("kBps_mean", true);
  m.kBps_peak = r.number("kBps_peak", true);
  m.loops_accepted = r.integer("loops_accepted", true);
  m.loops_rejected = r.integer("loops_rejected", true);
  m.agents_merged = r.integer("agents_merged", true);
  m.relocalised = r.integer("relocalised", false);
  m.robots_new = r.integer("robots_new", false);
  m.loops_bridged = r.integer("loops_bridged", false);
  const json* timings = r.get("timings_ms", true);
  ObjectReader tr(*timings, "timings_ms");
  for (const auto& [stage, v] : timings->items()) {
    ObjectReader sr(v, "timings_ms." + stage);
    StageTiming t;
    t.median = *sr.numberRequired("median");
    t.p95 = *sr.numberRequired("p95");
    t.count = sr.integer("count", false).value_or(0);
    m.timings_ms[stage] = t;
  }
  if (const json* a = r.get("alignment", false); a && !a->is_null()) {
    ObjectReader ar(*a, "alignment");
    m.alignment = ar.string("mode", true);
    if (ar.get("t_xyz", false) || ar.get("q_xyzw", false)) {
      const auto t = ar.numbers("t_xyz", 3);
      const auto q = ar.numbers("q_xyzw", 4);
      const Quat quat(q[3], q[0], q[1], q[2]);
      if (!(quat.norm() > 1e-6)) throw FieldError("field 'alignment.q_xyzw' is not a rotation");
      m.T_gt_est = SE3(quat, Vec3(t[0], t[1], t[2]));
    }
    m.scale = ar.number("scale", false);
  }
  m.ate_m = r.stats("ate_m");
  m.matched_poses = r.integer("matched_poses", false);
  m.unmatched_poses = r.integer("unmatched_poses", false);
  m.max_dt_s = r.number("max_dt_s", false);
  m.rpe_delta = r.number("rpe_delta", false);
  m.rpe_delta_unit = r.string("rpe_delta_unit", false);
  m.frames_refused = r.counts("frames_refused");
  m.incomplete = r.boolean("incomplete", false);
  m.stopped_because = r.string("stopped_because", false);
  return m;
}

AccuracyStats toAccuracy(const eval::ErrorStats& s) {
  return {s.rmse, s.mean, s.median, s.max, s.std};
}

}  // namespace

void from_json(const json& j, RunMetrics& m) {
  try {
    m = parseRun(j);
  } catch (const FieldError& e) {
    throw std::invalid_argument(std::string("metrics JSON: ") + e.what());
  }
}

Expected<RunMetrics> metricsFromJson(const json& j, const std::string& source) {
  try {
    return parseRun(j);
  } catch (const FieldError& e) {
    return Error{source + ": " + e.what()};
  } catch (const json::exception& e) {
    return Error{source + ": " + e.what()};
  }
}

std::string metricsToJsonString(const RunMetrics& m, int indent) {
  return json(m).dump(indent);
}

Status writeMetricsJson(const std::string& path, const RunMetrics& m) {
  std::ofstream out(path);
  if (!out) return Error{"cannot write metrics file '" + path + "'"};
  out << metricsToJsonString(m) << "\n";
  out.close();
  if (!out) return Error{"error while writing metrics file '" + path + "'"};
  return Status::Ok();
}

Expected<RunMetrics> readMetricsJson(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{"metrics file '" + path + "' cannot be opened"};
  json j = json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return Error{"metrics file '" + path + "' is not valid JSON"};
  return metricsFromJson(j, path);
}

namespace {
AgentMetrics& agentEntry(RunMetrics* m, const std::string& name) {
  auto it = std::find_if(m->per_agent.begin(), m->per_agent.end(),
                         [&](const AgentMetrics& x) { return x.agent == name; });
  if (it != m->per_agent.end()) return *it;
  m->per_agent.push_back(AgentMetrics{});
  m->per_agent.back().agent = name;
  return m->per_agent.back();
}
}  // namespace

void fillAccuracy(const eval::MultiAgentEval& ev, const eval::EvalParams& params,
                  RunMetrics* m) {
  m->ate_rmse_m = ev.merged_ate.trans_m.rmse;
  m->ate_m = toAccuracy(ev.merged_ate.trans_m);
  m->alignment = eval::toString(ev.merged_alignment.mode);
  m->T_gt_est = ev.merged_alignment.T_gt_est;
  if (ev.merged_alignment.mode == eval::AlignMode::kSim3) m->scale = ev.merged_alignment.scale;
  m->matched_poses = int64_t(ev.matched);
  m->unmatched_poses = int64_t(ev.unmatched);
  m->max_dt_s = params.max_dt;
  m->rpe_delta = params.rpe_delta_frames > 0 ? double(params.rpe_delta_frames)
                                             : params.rpe_delta_s;
  m->rpe_delta_unit = params.rpe_delta_frames > 0 ? "frames" : "s";
  for (size_t i = 0; i < ev.agents.size(); ++i) {
    const eval::TrajectoryEval& a = ev.agents[i];
    AgentMetrics* it = &agentEntry(m, a.name);
    it->ate_rmse_m = a.ate.trans_m.rmse;
    it->ate_m = toAccuracy(a.ate.trans_m);
    if (i < ev.merged_per_agent_m.size()) it->merged_ate_rmse_m = ev.merged_per_agent_m[i].rmse;
    if (a.rpe.pairs > 0) {
      it->rpe_trans_rmse_m = a.rpe.trans_m.rmse;
      it->rpe_rot_rmse_deg = a.rpe.rot_deg.rmse;
    }
    it->matched_poses = int64_t(a.assoc.matched());
    it->unmatched_poses = int64_t(a.assoc.unmatched);
    if (a.ate.alignment.mode == eval::AlignMode::kSim3) it->scale = a.ate.alignment.scale;
  }
  for (const eval::AgentFailure& f : ev.failed) {  // listed, accuracy stays null
    AgentMetrics& e = agentEntry(m, f.name);
    e.ate_rmse_m.reset();
    e.matched_poses = 0;
  }
}

}  // namespace hermes
