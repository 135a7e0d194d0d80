#include "hermes/server/pose_graph.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <memory>

namespace hermes {
namespace server {

Status PoseGraphParams::read(const Config& config, const std::string& prefix) {
  const std::string p = prefix + ".";
  for (Status s : {config.getChoice(p + "loop_loss", {"none", "huber", "cauchy"}, &loop_loss),
                   config.get(p + "loop_loss_scale", &loop_loss_scale),
                   config.getChoice(p + "odometry_loss", {"none", "huber", "cauchy"}, &odometry_loss),
                   config.get(p + "odometry_loss_scale", &odometry_loss_scale),
                   config.get(p + "odometry_reweight_rounds", &odometry_reweight_rounds),
                   config.getChoice(p + "odometry_reweight_scope", {"trajectory", "local", "both"},
                                    &odometry_reweight_scope),
                   config.get(p + "odometry_reweight_window", &odometry_reweight_window),
                   config.get(p + "odometry_reweight_max", &odometry_reweight_max),
                   config.get(p + "odometry_reweight_floor", &odometry_reweight_floor),
                   config.get(p + "loop_rig_edges", &loop_rig_edges),
                   config.get(p + "anneal_steps", &anneal_steps),
                   config.get(p + "anneal_factor", &anneal_factor),
                   config.get(p + "max_iterations", &max_iterations),
                   config.get(p + "function_tolerance", &function_tolerance),
                   config.get(p + "num_threads", &num_threads),
                   config.get(p + "incremental_hops", &incremental_hops),
                   config.get(p + "full_every", &full_every),
                   config.get(p + "incremental_max_free", &incremental_max_free),
                   config.get(p + "full_between_merges", &full_between_merges)}) {
    if (!s) return s;
  }
  if (Status s = validate(); !s) return Error{prefix + ": " + s.error()};
  return Status::Ok();
}

void PoseGraphParams::write(ConfigWriter* w, const std::string& prefix) const {
  const std::string p = prefix + ".";
  w->set(p + "loop_loss", loop_loss);
  w->set(p + "loop_loss_scale", loop_loss_scale);
  w->set(p + "odometry_loss", odometry_loss);
  w->set(p + "odometry_loss_scale", odometry_loss_scale);
  w->set(p + "odometry_reweight_rounds", odometry_reweight_rounds);
  w->set(p + "odometry_reweight_scope", odometry_reweight_scope);
  w->set(p + "odometry_reweight_window", odometry_reweight_window);
  w->set(p + "odometry_reweight_max", odometry_reweight_max);
  w->set(p + "odometry_reweight_floor", odometry_reweight_floor);
  w->set(p + "loop_rig_edges", loop_rig_edges);
  w->set(p + "anneal_steps", anneal_steps);
  w->set(p + "anneal_factor", anneal_factor);
  w->set(p + "max_iterations", max_iterations);
  w->set(p + "function_tolerance", function_tolerance);
  w->set(p + "num_threads", num_threads);
  w->set(p + "incremental_hops", incremental_hops);
  w->set(p + "full_every", full_every);
  w->set(p + "incremental_max_free", incremental_max_free);
  w->set(p + "full_between_merges", full_between_merges);
}

Status PoseGraphParams::validate() const {
  if (loop_loss != "none" && loop_loss != "huber" && loop_loss != "cauchy") {
    return Error{"loop_loss must be none, huber or cauchy (got '" + loop_loss + "')"};
  }
  if (!(loop_loss_scale > 0)) return Error{"loop_loss_scale must be > 0"};
  if (odometry_loss != "none" && odometry_loss != "huber" && odometry_loss != "cauchy") {
    return Error{"odometry_loss must be none, huber or cauchy (got '" + odometry_loss + "')"};
  }
  if (!(odometry_loss_scale > 0)) return Error{"odometry_loss_scale must be > 0"};
  if (odometry_reweight_rounds < 0) return Error{"odometry_reweight_rounds must be >= 0"};
  if (odometry_reweight_scope != "trajectory" && odometry_reweight_scope != "local" &&
      odometry_reweight_scope != "both")
    return Error{"odometry_reweight_scope must be trajectory, local or both (got '" + odometry_reweight_scope + "')"};
  if (odometry_reweight_window < 0) return Error{"odometry_reweight_window must be >= 0"};
  if (!(odometry_reweight_max >= 1)) return Error{"odometry_reweight_max must be >= 1"};
  if (!(odometry_reweight_floor > 0)) return Error{"odometry_reweight_floor must be > 0"};
  if (loop_rig_edges < 0) return Error{"loop_rig_edges must be >= 0"};
  if (anneal_steps < 1) return Error{"anneal_steps must be >= 1"};
  if (!(anneal_factor >= 1)) return Error{"anneal_factor must be >= 1"};
  if (max_iterations < 1) return Error{"max_iterations must be >= 1"};
  if (!(function_tolerance > 0)) return Error{"function_tolerance must be > 0"};
  if (num_threads < 1) return Error{"num_threads must be >= 1"};
  if (incremental_hops < 0) return Error{"incremental_hops must be >= 0"};
  if (full_every < 1) return Error{"full_every must be >= 1"};
  if (incremental_max_free < 0) return Error{"incremental_max_free must be >= 0"};
  return Status::Ok();
}

ceres::CostFunction* RelativePoseError::create(const SE3& T_a_b, const Mat6& sqrt_information) {
  return new ceres::AutoDiffCostFunction<RelativePoseError, 6, 4, 3, 4, 3>(
      new RelativePoseError(T_a_b, sqrt_information));
}

Expected<Mat6> sqrtInformation(const Mat6& information) {
  if (!information.allFinite()) return Error{"information is not finite"};
  const Mat6 sym = 0.5 * (information + information.transpose());
  Eigen::LLT<Mat6> llt(sym);
  if (llt.info() != Eigen::Success) return Error{"information is not positive definite"};
  return Mat6(llt.matrixU());
}

namespace {
ceres::LossFunction* makeLoss(const std::string& kind, double scale) {
  if (kind == "huber") return new ceres::HuberLoss(scale);
  if (kind == "cauchy") return new ceres::CauchyLoss(scale);
  return nullptr;
}

/// rho'(s) of the loss at squared norm s (scale c): the weight it gives the edge.
double robustWeight(const std::string& kind, double c, double s) {
  if (kind == "huber") return s <= c * c ? 1.0 : c / std::sqrt(s);
  if (kind == "cauchy") return 1.0 / (1.0 + s / (c * c));
  return 1.0;
}

std::string toString(const KeyframeKey& key) {
  return "(agent " + std::to_string(key.agent) + ", session " + std::to_string(key.session) +
         ", keyframe " + std::to_string(key.id) + ")";
}
}  // namespace

PoseGraph::PoseGraph(const PoseGraphParams& params) : params_(params) {}

Status PoseGraph::addNode(const KeyframeKey& key, const SE3& T_W_K) {
  if (nodes_.count(key)) return Error{"pose graph: node " + toString(key) + " already exists"};
  if (!T_W_K.translation().allFinite() || !T_W_K.quat().coeffs().allFinite()) {
    return Error{"pose graph: node " + toString(key) + " has a non-finite pose"};
  }
  Node n;
  const Eigen::Vector4d q = T_W_K.quat().coeffs();
  n.q = {q(0), q(1), q(2), q(3)};
  n.t = {T_W_K.translation().x(), T_W_K.translation().y(), T_W_K.translation().z()};
  nodes_.emplace(key, n);
  return Status::Ok();
}

Status PoseGraph::addAgentNodes(const std::vector<std::pair<KeyframeKey, SE3>>& T_A_K,
                                const SE3& T_W_A) {
  for (const auto& [key, T] : T_A_K) {
    if (Status s = addNode(key, T_W_A * T); !s) return s;
  }
  return Status::Ok();
}

Status PoseGraph::addEdge(const KeyframeKey& a, const KeyframeKey& b, const SE3& T_a_b,
                          const Mat6& information, const char* kind, std::vector<Edge>* edges) {
  const std::string what = std::string("pose graph: ") + kind + " edge " + toString(a) + " -> " + toString(b);
  if (!nodes_.count(a) || !nodes_.count(b)) return Error{what + " references an unknown node"};
  if (a == b) return Error{what + " connects a node to itself"};
  if (!T_a_b.translation().allFinite() || !T_a_b.quat().coeffs().allFinite()) {
    return Error{what + " has a non-finite measurement"};
  }
  Expected<Mat6> L = sqrtInformation(information);
  if (!L) return Error{what + ": " + L.error()};
  edges->push_back(Edge{a, b, T_a_b, *L});
  return Status::Ok();
}

Status PoseGraph::addOdometryEdge(const KeyframeKey& from, const KeyframeKey& to,
                                  const SE3& T_from_to, const Mat6& information) {
  return addEdge(from, to, T_from_to, information, "odometry", &odometry_);
}

Status PoseGraph::addLoopEdge(const KeyframeKey& a, const KeyframeKey& b, const SE3& T_a_b,
                              const Mat6& information) {
  return addEdge(a, b, T_a_b, information, "loop", &loops_);
}

Status PoseGraph::setFixed(const KeyframeKey& key) {
  auto it = nodes_.find(key);
  if (it == nodes_.end()) return Error{"pose graph: cannot fix unknown node " + toString(key)};
  it->second.fixed = true;
  return Status::Ok();
}

Status PoseGraph::fixFirstPoseOf(std::uint32_t agent) {
  for (auto& [key, node] : nodes_) {
    if (key.agent == agent) {
      node.fixed = true;
      return Status::Ok();
    }
  }
  return Error{"pose graph: agent " + std::to_string(agent) + " has no nodes to fix"};
}

std::size_t PoseGraph::holdBeyond(const std::vector<KeyframeKey>& seeds, int hops, std::size_t max_free) {
  std::map<KeyframeKey, std::vector<KeyframeKey>> adjacent;
  for (const std::vector<Edge>* edges : {&odometry_, &loops_})
    for (const Edge& e : *edges) {
      adjacent[e.a].push_back(e.b);
      adjacent[e.b].push_back(e.a);
    }
  // Breadth-first from the seeds, `hops` layers deep.
  std::map<KeyframeKey, int> depth;
  std::vector<KeyframeKey> layer;
  for (const KeyframeKey& k : seeds)
    if (nodes_.count(k) && depth.emplace(k, 0).second) layer.push_back(k);
  const auto full = [&] { return max_free > 0 && depth.size() >= max_free; };
  for (int d = 1; d <= hops && !layer.empty() && !full(); ++d) {
    std::vector<KeyframeKey> next;
    for (const KeyframeKey& k : layer)
      for (const KeyframeKey& n : adjacent[k])
        if (!full() && depth.emplace(n, d).second) next.push_back(n);
    layer = std::move(next);
  }
  for (auto& [key, node] : nodes_) node.held = !depth.count(key);
  return numFree();
}

std::size_t PoseGraph::numFree() const {
  std::size_t n = 0;
  for (const auto& [key, node] : nodes_) n += !node.fixed && !node.held;
  return n;
}

bool PoseGraph::active(const Edge& e) const {
  const Node& a = nodes_.at(e.a);
  const Node& b = nodes_.at(e.b);
  return !(a.fixed || a.held) || !(b.fixed || b.held);
}

Expected<PoseGraphResult> PoseGraph::optimize() {
  if (Status s = params_.validate(); !s) return Error{"pose graph: " + s.error()};
  if (odometry_.empty() && loops_.empty()) return Error{"pose graph: no edges to optimise"};
  const auto t0 = std::chrono::steady_clock::now();
  odometry_scale_.assign(odometry_.size(), 1.0);
  loop_scale_.assign(loops_.size(), 1.0);
  PoseGraphResult res;
  for (int round = 0;; ++round) {
    // The first round anneals the robust losses from large scales; later rounds
    // start from its solution at the final scales.
    Expected<PoseGraphResult> r = solve(round == 0);
    if (!r) return r;
    if (round == 0) res.initial_cost = r->initial_cost;
    res.final_cost = r->final_cost;
    res.iterations += r->iterations;
    res.converged = r->converged;
    res.termination = r->termination;
    res.report = r->report;
    res.reweight_rounds = round;
    if (round >= params_.odometry_reweight_rounds || !reweightOdometry()) break;
  }
  res.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return res;
}

bool PoseGraph::reweightOdometry() {
  // Squared whitened error of every odometry edge under its own information,
  // grouped by trajectory in key order; per edge, the mean chi2 per degree of
  // freedom of the edges within +-window of it (`window`) and of its whole
  // trajectory (`whole`).
  TrajectoryEdges traj;
  for (std::size_t i = 0; i < odometry_.size(); ++i)
    traj[{odometry_[i].a.agent, odometry_[i].a.session}].emplace_back(odometry_[i].a, i);
  if (odometry_.empty()) return false;
  std::vector<double> chi2(odometry_.size()), window(odometry_.size(), 0.0), whole(odometry_.size(), 0.0);
  for (std::size_t i = 0; i < odometry_.size(); ++i) chi2[i] = edgeChi2(odometry_[i]);
  const int w = params_.odometry_reweight_window;
  for (auto& [id, edges] : traj) {
    std::sort(edges.begin(), edges.end());
    const int n = static_cast<int>(edges.size());
    double total = 0;
    for (int k = 0; k < n; ++k) total += chi2[edges[k].second];
    for (int k = 0; k < n; ++k) {
      double sum = 0;
      int count = 0;
      for (int j = std::max(0, k - w); j <= std::min(n - 1, k + w); ++j, ++count) sum += chi2[edges[j].second];
      window[edges[k].second] = sum / (6.0 * count);
      whole[edges[k].second] = total / (6.0 * n);
    }
  }
  // The typical level: most odometry is sound, so the median stretch is (per
  // edge window, which stays meaningful with two robots where a median over
  // trajectories would be one of them). A robot or stretch that disagrees with
  // the loops that much more than the typical stretch is trusted that much less
  // (bounded); sound ones keep their information.
  std::vector<double> sorted = window;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double typical = std::max(sorted[sorted.size() / 2], params_.odometry_reweight_floor);
  const std::string& scope = params_.odometry_reweight_scope;
  bool changed = false;
  for (std::size_t i = 0; i < odometry_.size(); ++i) {
    const double level = scope == "local" ? window[i] : scope == "trajectory" ? whole[i]
                                                                              : std::max(window[i], whole[i]);
    const double scale = std::clamp(level / typical, 1.0, params_.odometry_reweight_max);
    double& current = odometry_scale_[i];
    if (std::abs(scale - current) > 0.1 * current && active(odometry_[i])) changed = true;
    current = scale;
  }
  // Loops whose rigs stand on re-weighted odometry (see loop_rig_edges).
  const int rig = params_.loop_rig_edges;
  auto rigScale = [&](const KeyframeKey& k) {
    if (rig == 0) return 1.0;
    auto it = traj.find({k.agent, k.session});
    if (it == traj.end()) return 1.0;
    const auto& edges = it->second;  // sorted by their first keyframe
    const int n = static_cast<int>(edges.size());
    const int p = static_cast<int>(std::lower_bound(edges.begin(), edges.end(), std::make_pair(k, std::size_t{0})) -
                                   edges.begin());  // the first edge leaving k (or after it)
    double sum = 0;
    int count = 0;
    for (int j = std::max(0, p - rig); j < std::min(n, p + rig); ++j, ++count) sum += odometry_scale_[edges[j].second];
    return count > 0 ? sum / count : 1.0;
  };
  for (std::size_t i = 0; i < loops_.size(); ++i) {
    const double scale = std::max(rigScale(loops_[i].a), rigScale(loops_[i].b));
    if (std::abs(scale - loop_scale_[i]) > 0.1 * loop_scale_[i] && active(loops_[i])) changed = true;
    loop_scale_[i] = scale;
  }
  return changed;
}

double PoseGraph::edgeChi2(const Edge& e) const {
  const Node& a = nodes_.at(e.a);
  const Node& b = nodes_.at(e.b);
  double r[6];
  RelativePoseError(e.T_a_b, e.sqrt_information)(a.q.data(), a.t.data(), b.q.data(), b.t.data(), r);
  return Eigen::Map<const Vec6>(r).squaredNorm();
}

Expected<PoseGraphResult> PoseGraph::solve(bool anneal) {
  ceres::Problem::Options popt;
  popt.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  popt.loss_function_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(popt);
  ceres::EigenQuaternionManifold quaternion_manifold;

  auto addBlocks = [&](Node& n) {
    if (!problem.HasParameterBlock(n.q.data())) {
      problem.AddParameterBlock(n.q.data(), 4, &quaternion_manifold);
      problem.AddParameterBlock(n.t.data(), 3);
    }
  };
  auto addResidual = [&](const Edge& e, double scale, ceres::LossFunction* loss) {
    Node& a = nodes_.at(e.a);
    Node& b = nodes_.at(e.b);
    addBlocks(a);
    addBlocks(b);
    problem.AddResidualBlock(RelativePoseError::create(e.T_a_b, e.sqrt_information / std::sqrt(scale)),
                             loss, a.q.data(), a.t.data(), b.q.data(), b.t.data());
  };
  // One loss per edge kind, shared by its edges; the scales are annealed
  // between solves (continuation: large scales first, the final ones last).
  const int stages = anneal && robust() ? params_.anneal_steps : 1;
  auto annealed = [&](double final_scale, int stage) {
    return final_scale * std::pow(params_.anneal_factor, stages - 1 - stage);
  };
  auto makeWrapper = [&](const std::string& kind, double final_scale) -> ceres::LossFunctionWrapper* {
    if (kind == "none") return nullptr;
    return new ceres::LossFunctionWrapper(makeLoss(kind, annealed(final_scale, 0)), ceres::TAKE_OWNERSHIP);
  };
  ceres::LossFunctionWrapper* odometry_loss = makeWrapper(params_.odometry_loss, params_.odometry_loss_scale);
  ceres::LossFunctionWrapper* loop_loss = makeWrapper(params_.loop_loss, params_.loop_loss_scale);
  // Edges between held (or fixed) nodes are constants of the problem: left out.
  std::size_t odometry_added = 0, loops_added = 0;
  for (std::size_t i = 0; i < odometry_.size(); ++i)
    if (active(odometry_[i])) addResidual(odometry_[i], odometry_scale_[i], odometry_loss), ++odometry_added;
  for (std::size_t i = 0; i < loops_.size(); ++i)
    if (active(loops_[i])) addResidual(loops_[i], loop_scale_[i], loop_loss), ++loops_added;

  bool any_fixed = false;
  for (auto& [key, node] : nodes_) {
    if ((node.fixed || node.held) && problem.HasParameterBlock(node.q.data())) {
      problem.SetParameterBlockConstant(node.q.data());
      problem.SetParameterBlockConstant(node.t.data());
      any_fixed = true;
    }
  }
  if (!any_fixed) {
    for (auto& [key, node] : nodes_) {
      if (problem.HasParameterBlock(node.q.data())) {
        problem.SetParameterBlockConstant(node.q.data());
        problem.SetParameterBlockConstant(node.t.data());
        break;
      }
    }
  }

  ceres::Solver::Options opt;
  opt.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  opt.sparse_linear_algebra_library_type = ceres::SUITE_SPARSE;
  opt.max_num_iterations = params_.max_iterations;
  opt.function_tolerance = params_.function_tolerance;
  opt.num_threads = params_.num_threads;
  opt.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  double initial_cost = 0;
  int iterations = 0;
  for (int stage = 0; stage < stages; ++stage) {
    if (stage > 0) {
      if (odometry_loss)
        odometry_loss->Reset(makeLoss(params_.odometry_loss, annealed(params_.odometry_loss_scale, stage)),
                             ceres::TAKE_OWNERSHIP);
      if (loop_loss)
        loop_loss->Reset(makeLoss(params_.loop_loss, annealed(params_.loop_loss_scale, stage)),
                         ceres::TAKE_OWNERSHIP);
    }
    ceres::Solve(opt, &problem, &summary);
    if (stage == 0) initial_cost = summary.initial_cost;
    iterations += static_cast<int>(summary.iterations.size());
    if (!summary.IsSolutionUsable()) break;
  }
  // A wrapper never handed to the problem is ours to delete.
  if (odometry_added == 0) delete odometry_loss;
  if (loops_added == 0) delete loop_loss;

  for (auto& [key, node] : nodes_) {  // keep quaternions normalised for readers
    Eigen::Map<Eigen::Vector4d> q(node.q.data());
    q.normalize();
  }
  PoseGraphResult res;
  res.initial_cost = initial_cost;  // under the first stage's loss scale
  res.final_cost = summary.final_cost;
  res.iterations = iterations;
  res.converged = summary.termination_type == ceres::CONVERGENCE;
  res.termination = ceres::TerminationTypeToString(summary.termination_type);
  res.report = summary.BriefReport();
  if (!summary.IsSolutionUsable()) return Error{"pose graph: solver failed: " + res.report};
  return res;
}

bool PoseGraph::robust() const {
  return params_.loop_loss != "none" || params_.odometry_loss != "none";
}

std::vector<EdgeResidual> PoseGraph::residuals() const {
  std::vector<EdgeResidual> out;
  auto add = [&](const Edge& e, bool loop, double scale) {
    const SE3 err = e.T_a_b.inverse() * nodePose(nodes_.at(e.a)).inverse() * nodePose(nodes_.at(e.b));
    EdgeResidual x;
    x.a = e.a;
    x.b = e.b;
    x.loop = loop;
    x.error_m = err.translation().norm();
    x.error_rad = rotationAngle(err.rotation());
    x.chi2 = edgeChi2(e);
    x.weight = robustWeight(loop ? params_.loop_loss : params_.odometry_loss,
                            loop ? params_.loop_loss_scale : params_.odometry_loss_scale, x.chi2 / scale) /
               scale;
    out.push_back(x);
  };
  for (std::size_t i = 0; i < odometry_.size(); ++i)
    add(odometry_[i], false, i < odometry_scale_.size() ? odometry_scale_[i] : 1.0);
  for (std::size_t i = 0; i < loops_.size(); ++i) add(loops_[i], true, i < loop_scale_.size() ? loop_scale_[i] : 1.0);
  return out;
}

std::vector<PoseGraph::EdgeMeasurement> PoseGraph::measurements() const {
  std::vector<EdgeMeasurement> out;
  auto add = [&](const Edge& e, bool loop) {
    out.push_back({e.a, e.b, e.T_a_b, e.sqrt_information.transpose() * e.sqrt_information, loop});
  };
  for (const Edge& e : odometry_) add(e, false);
  for (const Edge& e : loops_) add(e, true);
  return out;
}

std::vector<KeyframeKey> PoseGraph::fixedNodes() const {
  std::vector<KeyframeKey> out;
  for (const auto& [key, n] : nodes_)
    if (n.fixed) out.push_back(key);
  return out;
}

Expected<SE3> PoseGraph::pose(const KeyframeKey& key) const {
  auto it = nodes_.find(key);
  if (it == nodes_.end()) return Error{"pose graph: unknown node " + toString(key)};
  return nodePose(it->second);
}

std::map<KeyframeKey, SE3> PoseGraph::poses() const {
  std::map<KeyframeKey, SE3> out;
  for (const auto& [key, n] : nodes_) {
    out.emplace(key, nodePose(n));
  }
  return out;
}

}  // namespace server
}  // namespace hermes
