#include "hermes/server/pcm.h"

#include "hermes/server/byte_codec.h"

#include <algorithm>
#include <chrono>

#include <Eigen/Cholesky>

#include "hermes/core/odometry_noise.h"

namespace hermes {
namespace server {

namespace {

std::string keyText(const KeyframeKey& k) {
  return "(agent " + std::to_string(k.agent) + ", session " + std::to_string(k.session) +
         ", keyframe " + std::to_string(k.id) + ")";
}

using TrajectoryId = std::pair<std::uint32_t, std::uint32_t>;
TrajectoryId trajectoryOf(const KeyframeKey& k) { return {k.agent, k.session}; }

/// Keyframe ids a clique's loops span on one trajectory.
struct IdRange {
  KeyframeId lo = kInvalidId, hi = 0;
  void add(KeyframeId id) { lo = std::min(lo, id), hi = std::max(hi, id); }
  bool overlaps(const IdRange& o) const { return lo <= o.hi && o.lo <= hi; }
};

}  // namespace

LoopCandidate reversedLoop(const LoopCandidate& l) {
  LoopCandidate r = l;
  r.a = l.b;
  r.b = l.a;
  r.T_a_b = l.T_a_b.inverse();
  const Mat6 Ad = l.T_a_b.adjoint();  // (T exp(x))^-1 = T^-1 exp(-Ad_T x)
  r.covariance = Ad * l.covariance * Ad.transpose();
  return r;
}

Status PcmParams::read(const Config& config, const std::string& prefix) {
  const std::string p = prefix + ".";
  for (Status s : {config.get(p + "chi2_probability", &chi2_probability),
                   config.get(p + "exact_max_loops", &exact_max_loops),
                   config.get(p + "min_clique_size", &min_clique_size),
                   config.get(p + "max_segments", &max_segments),
                   config.get(p + "min_segment_size", &min_segment_size),
                   config.get(p + "drift_fraction", &drift_fraction),
                   config.get(p + "drift_rad_per_m", &drift_rad_per_m),
                   config.get(p + "bridge_min_loops", &bridge_min_loops)}) {
    if (!s) return s;
  }
  if (Status s = validate(); !s) return Error{prefix + ": " + s.error()};
  return Status::Ok();
}

void PcmParams::write(ConfigWriter* w, const std::string& prefix) const {
  w->set(prefix + ".chi2_probability", chi2_probability);
  w->set(prefix + ".exact_max_loops", exact_max_loops);
  w->set(prefix + ".min_clique_size", min_clique_size);
  w->set(prefix + ".max_segments", max_segments);
  w->set(prefix + ".min_segment_size", min_segment_size);
  w->set(prefix + ".drift_fraction", drift_fraction);
  w->set(prefix + ".drift_rad_per_m", drift_rad_per_m);
  w->set(prefix + ".bridge_min_loops", bridge_min_loops);
}

Status PcmParams::validate() const {
  if (!(chi2_probability > 0 && chi2_probability < 1)) return Error{"chi2_probability must be in (0, 1)"};
  if (exact_max_loops < 0 || exact_max_loops > 64) return Error{"exact_max_loops must be in [0, 64]"};
  if (min_clique_size < 1) return Error{"min_clique_size must be >= 1"};
  if (max_segments < 1) return Error{"max_segments must be >= 1"};
  if (min_segment_size < 1) return Error{"min_segment_size must be >= 1"};
  if (!(drift_fraction >= 0 && drift_fraction < 1)) return Error{"drift_fraction must be in [0, 1)"};
  if (!(drift_rad_per_m >= 0 && drift_rad_per_m < 1)) return Error{"drift_rad_per_m must be in [0, 1)"};
  if (bridge_min_loops < 0) return Error{"bridge_min_loops must be >= 0 (0 = off)"};
  return Status::Ok();
}

Status OdometryChain::addKeyframe(const KeyframeKey& key, const SE3& T_A_K) {
  Trajectory& traj = trajectories_[trajectoryOf(key)];
  if (traj.count(key.id)) return Error{"odometry chain: keyframe " + keyText(key) + " added twice"};
  if (!traj.empty() && key.id < traj.rbegin()->first) ++revision_;
  traj[key.id].T_A_K = T_A_K;
  return Status::Ok();
}

Status OdometryChain::addEdge(const KeyframeKey& from, const KeyframeKey& to,
                              const Mat6& information) {
  const std::string what = "odometry chain: edge " + keyText(from) + " -> " + keyText(to);
  if (trajectoryOf(from) != trajectoryOf(to)) return Error{what + " joins two trajectories"};
  auto tit = trajectories_.find(trajectoryOf(from));
  if (tit == trajectories_.end()) return Error{what + ": unknown trajectory"};
  Trajectory& traj = tit->second;
  auto it = traj.find(from.id);
  if (it == traj.end() || !traj.count(to.id)) return Error{what + ": unknown keyframe"};
  auto next = std::next(it);
  if (next == traj.end() || next->first != to.id) {
    return Error{what + ": keyframes are not consecutive"};
  }
  Eigen::LDLT<Mat6> ldlt(0.5 * (information + information.transpose()));
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive() || !information.allFinite()) {
    return Error{what + ": information is not positive definite"};
  }
  it->second.has_edge_to_next = true;
  it->second.covariance_to_next = ldlt.solve(Mat6::Identity());
  return Status::Ok();
}

Expected<RelativePose> OdometryChain::relative(const KeyframeKey& from, const KeyframeKey& to) const {
  const std::string what = "odometry " + keyText(from) + " -> " + keyText(to);
  if (trajectoryOf(from) != trajectoryOf(to)) return Error{what + ": different trajectories"};
  auto tit = trajectories_.find(trajectoryOf(from));
  if (tit == trajectories_.end()) return Error{what + ": unknown trajectory"};
  const Trajectory& traj = tit->second;
  const bool forward = from.id <= to.id;
  const KeyframeId lo = forward ? from.id : to.id, hi = forward ? to.id : from.id;
  auto it_lo = traj.find(lo), it_hi = traj.find(hi);
  if (it_lo == traj.end() || it_hi == traj.end()) return Error{what + ": unknown keyframe"};
  std::vector<RelativePoseCov> edges;
  double path = 0;
  for (auto it = it_lo; it != it_hi; ++it) {
    if (!it->second.has_edge_to_next) {
      return Error{what + ": missing odometry edge after keyframe " + std::to_string(it->first)};
    }
    edges.push_back({it->second.T_A_K.inverse() * std::next(it)->second.T_A_K,
                     it->second.covariance_to_next});
    path += edges.back().T.translation().norm();
  }
  const RelativePoseCov c = composeEdges(edges);
  RelativePose out;
  out.T = forward ? c.T : c.T.inverse();
  out.covariance = forward ? c.covariance : invertedCovariance(c.T, c.covariance);
  out.path_length_m = path;
  return out;
}

void OdometryChain::save(ByteWriter* w) const {
  w->pod(revision_);
  w->count(trajectories_.size());
  for (const auto& [tid, traj] : trajectories_) {
    w->pod(tid.first);
    w->pod(tid.second);
    w->count(traj.size());
    for (const auto& [id, e] : traj) {
      w->pod(id);
      w->pose(e.T_A_K);
      w->flag(e.has_edge_to_next);
      w->mat6(e.covariance_to_next);
    }
  }
}

bool OdometryChain::load(ByteReader* r) {
  std::uint64_t trajectories = 0;
  if (!trajectories_.empty() || !r->pod(&revision_) || !r->count(&trajectories, 16)) return false;
  for (std::uint64_t i = 0; i < trajectories; ++i) {
    std::pair<std::uint32_t, std::uint32_t> tid;
    std::uint64_t n = 0;
    if (!r->pod(&tid.first) || !r->pod(&tid.second) || !r->count(&n, 8 + 56 + 1 + 288)) return false;
    Trajectory& traj = trajectories_[tid];
    if (!traj.empty()) return false;  // the same trajectory twice
    for (std::uint64_t k = 0; k < n; ++k) {
      KeyframeId id = 0;
      Entry e;
      if (!r->pod(&id) || !r->pose(&e.T_A_K) || !r->flag(&e.has_edge_to_next) ||
          !r->mat6(&e.covariance_to_next) || !traj.emplace(id, e).second)
        return false;
    }
  }
  return true;
}

OdometryQuery OdometryChain::query() const {
  return [this](const KeyframeKey& from, const KeyframeKey& to) { return relative(from, to); };
}

Mat6 driftAllowance(double path_length_m, const PcmParams& params) {
  const double st = params.drift_fraction * path_length_m, sr = params.drift_rad_per_m * path_length_m;
  Vec6 d;
  d << Vec3::Constant(st * st), Vec3::Constant(sr * sr);
  return d.asDiagonal();
}

Expected<double> cycleMahalanobis2(const LoopCandidate& i, const LoopCandidate& j,
                                   const OdometryQuery& odometry, const PcmParams& params) {
  Expected<RelativePose> oa = odometry(i.a, j.a);  // T_ai_aj
  if (!oa) return Error{oa.error()};
  Expected<RelativePose> ob = odometry(j.b, i.b);  // T_bj_bi
  if (!ob) return Error{ob.error()};
  // C = X1 X2 X3 X4 with X1 = T_ai_aj, X2 = T_aj_bj, X3 = T_bj_bi, X4 = T_bi_ai.
  const SE3 X4 = i.T_a_b.inverse();
  const SE3 X34 = ob->T * X4;
  const SE3 X234 = j.T_a_b * X34;
  const SE3 C = oa->T * X234;
  const Mat6 A1 = X234.inverse().adjoint(), A2 = X34.inverse().adjoint(), A3 = X4.inverse().adjoint();
  const Mat6 A4 = i.T_a_b.adjoint();  // (Z exp(x))^-1 = Z^-1 exp(-Ad_Z x)
  const Mat6 cov_a = oa->covariance + driftAllowance(oa->path_length_m, params);
  const Mat6 cov_b = ob->covariance + driftAllowance(ob->path_length_m, params);
  const Mat6 cov = A1 * cov_a * A1.transpose() + A2 * j.covariance * A2.transpose() +
                   A3 * cov_b * A3.transpose() + A4 * i.covariance * A4.transpose();
  const Vec6 e = C.log();
  Eigen::LDLT<Mat6> ldlt(cov);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
    return Error{"cycle covariance of loops " + std::to_string(i.id) + " and " +
                 std::to_string(j.id) + " is not positive definite"};
  }
  return e.dot(ldlt.solve(e));
}

PcmResult selectConsistentLoops(const std::vector<LoopCandidate>& loops,
                                const OdometryQuery& odometry, const PcmParams& params,
                                PcmCache* cache) {
  const auto t0 = std::chrono::steady_clock::now();
  PcmResult res;
  const double gate = chi2Quantile(params.chi2_probability, 6);
  // Group by unordered trajectory pair; orient every loop from the smaller trajectory.
  std::map<std::pair<TrajectoryId, TrajectoryId>, std::vector<LoopCandidate>> groups;
  for (const LoopCandidate& l : loops) {
    const LoopCandidate o = trajectoryOf(l.b) < trajectoryOf(l.a) ? reversedLoop(l) : l;
    groups[{trajectoryOf(o.a), trajectoryOf(o.b)}].push_back(o);
  }
  res.groups = static_cast<int>(groups.size());
  for (const auto& [pair, group] : groups) {
    const int n = static_cast<int>(group.size());
    std::vector<std::vector<char>> adj(n, std::vector<char>(n, 0));
    for (int i = 0; i < n; ++i) {
      for (int j = i + 1; j < n; ++j) {
        const int known = cache ? cache->verdict(pair, group[i].id, group[j].id) : -1;
        if (known >= 0) {
          ++res.pairs_cached;
          adj[i][j] = adj[j][i] = static_cast<char>(known);
          continue;
        }
        ++res.pairs_computed;
        Expected<double> d2 = cycleMahalanobis2(group[i], group[j], odometry, params);
        if (!d2) {
          ++res.odometry_failures;
          continue;
        }
        adj[i][j] = adj[j][i] = *d2 < gate;
        if (cache) cache->store(pair, group[i].id, group[j].id, adj[i][j]);
      }
    }
    std::vector<char> in(n, 0);
    std::vector<IdRange> ranges_a, ranges_b;  // of the accepted cliques
    std::vector<int> rest(n);
    for (int i = 0; i < n; ++i) rest[i] = i;
    for (int segment = 0; segment < params.max_segments && !rest.empty(); ++segment) {
      const int m = static_cast<int>(rest.size());
      std::vector<std::vector<char>> sub(m, std::vector<char>(m, 0));
      for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) sub[i][j] = adj[rest[i]][rest[j]];
      bool exact = true;
      std::vector<int> clique = maximumClique(sub, params.exact_max_loops, &exact);
      res.all_exact = res.all_exact && exact;
      const int needed = segment == 0 ? params.min_clique_size
                                      : std::max(params.min_clique_size, params.min_segment_size);
      if (static_cast<int>(clique.size()) < needed) break;
      for (int& v : clique) v = rest[v];
      IdRange ra, rb;
      for (int v : clique) ra.add(group[v].a.id), rb.add(group[v].b.id);
      auto apart = [](const IdRange& r, const std::vector<IdRange>& taken) {
        for (const IdRange& t : taken)
          if (r.overlaps(t)) return false;
        return true;
      };
      if (segment > 0 && !apart(ra, ranges_a) && !apart(rb, ranges_b)) break;
      if (segment > 0) ++res.segment_cliques;
      ranges_a.push_back(ra);
      ranges_b.push_back(rb);
      for (int v : clique) in[v] = 1;
      std::vector<int> left;
      for (int v : rest)
        if (!in[v]) left.push_back(v);
      rest = std::move(left);
    }
    for (int i = 0; i < n; ++i) (in[i] ? res.accepted : res.rejected).push_back(group[i].id);
  }
  res.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

}  // namespace server
}  // namespace hermes
