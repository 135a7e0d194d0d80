#include "hermes/server/pose_graph.h"

#include <chrono>
#include <cmath>
#include <memory>

namespace hermes {
namespace server {

Status PoseGraphParams::read(const Config& config, const std::string& prefix) {
  const std::string p = prefix + ".";
  for (Status s : {config.getChoice(p + "loop_loss", {"none", "huber", "cauchy"}, &loop_loss),
                   config.get(p + "loop_loss_scale", &loop_loss_scale),
                   config.get(p + "anneal_steps", &anneal_steps),
                   config.get(p + "anneal_factor", &anneal_factor),
                   config.get(p + "max_iterations", &max_iterations),
                   config.get(p + "function_tolerance", &function_tolerance),
                   config.get(p + "num_threads", &num_threads)}) {
    if (!s) return s;
  }
  if (Status s = validate(); !s) return Error{prefix + ": " + s.error()};
  return Status::Ok();
}

void PoseGraphParams::write(ConfigWriter* w, const std::string& prefix) const {
  const std::string p = prefix + ".";
  w->set(p + "loop_loss", loop_loss);
  w->set(p + "loop_loss_scale", loop_loss_scale);
  w->set(p + "anneal_steps", anneal_steps);
  w->set(p + "anneal_factor", anneal_factor);
  w->set(p + "max_iterations", max_iterations);
  w->set(p + "function_tolerance", function_tolerance);
  w->set(p + "num_threads", num_threads);
}

Status PoseGraphParams::validate() const {
  if (loop_loss != "none" && loop_loss != "huber" && loop_loss != "cauchy") {
    return Error{"loop_loss must be none, huber or cauchy (got '" + loop_loss + "')"};
  }
  if (!(loop_loss_scale > 0)) return Error{"loop_loss_scale must be > 0"};
  if (anneal_steps < 1) return Error{"anneal_steps must be >= 1"};
  if (!(anneal_factor >= 1)) return Error{"anneal_factor must be >= 1"};
  if (max_iterations < 1) return Error{"max_iterations must be >= 1"};
  if (!(function_tolerance > 0)) return Error{"function_tolerance must be > 0"};
  if (num_threads < 1) return Error{"num_threads must be >= 1"};
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

Expected<PoseGraphResult> PoseGraph::optimize() {
  if (Status s = params_.validate(); !s) return Error{"pose graph: " + s.error()};
  if (odometry_.empty() && loops_.empty()) return Error{"pose graph: no edges to optimise"};
  const auto t0 = std::chrono::steady_clock::now();

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
  auto addResidual = [&](const Edge& e, ceres::LossFunction* loss) {
    Node& a = nodes_.at(e.a);
    Node& b = nodes_.at(e.b);
    addBlocks(a);
    addBlocks(b);
    problem.AddResidualBlock(RelativePoseError::create(e.T_a_b, e.sqrt_information), loss,
                             a.q.data(), a.t.data(), b.q.data(), b.t.data());
  };
  for (const Edge& e : odometry_) addResidual(e, nullptr);
  // One loss shared by all loop edges; its scale is annealed between solves.
  auto makeLoss = [&](double scale) -> ceres::LossFunction* {
    if (params_.loop_loss == "huber") return new ceres::HuberLoss(scale);
    if (params_.loop_loss == "cauchy") return new ceres::CauchyLoss(scale);
    return nullptr;
  };
  const bool robust = params_.loop_loss != "none";
  const int stages = robust ? params_.anneal_steps : 1;
  auto scaleOf = [&](int stage) {
    return params_.loop_loss_scale * std::pow(params_.anneal_factor, stages - 1 - stage);
  };
  ceres::LossFunctionWrapper* loop_loss =
      robust ? new ceres::LossFunctionWrapper(makeLoss(scaleOf(0)), ceres::TAKE_OWNERSHIP) : nullptr;
  for (const Edge& e : loops_) addResidual(e, loop_loss);

  bool any_fixed = false;
  for (auto& [key, node] : nodes_) {
    if (node.fixed && problem.HasParameterBlock(node.q.data())) {
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
    if (loop_loss != nullptr && stage > 0) loop_loss->Reset(makeLoss(scaleOf(stage)), ceres::TAKE_OWNERSHIP);
    ceres::Solve(opt, &problem, &summary);
    if (stage == 0) initial_cost = summary.initial_cost;
    iterations += static_cast<int>(summary.iterations.size());
    if (!summary.IsSolutionUsable()) break;
  }
  if (loops_.empty()) delete loop_loss;  // never handed to the problem

  for (auto& [key, node] : nodes_) {  // keep quaternions normalised for readers
    Eigen::Map<Eigen::Vector4d> q(node.q.data());
    q.normalize();
  }
  PoseGraphResult res;
  res.initial_cost = initial_cost;  // under the first stage's loss scale
  res.final_cost = summary.final_cost;
  res.iterations = iterations;
  res.converged = summary.termination_type == ceres::CONVERGENCE;
  res.report = summary.BriefReport();
  res.time_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  if (!summary.IsSolutionUsable()) return Error{"pose graph: solver failed: " + res.report};
  return res;
}

Expected<SE3> PoseGraph::pose(const KeyframeKey& key) const {
  auto it = nodes_.find(key);
  if (it == nodes_.end()) return Error{"pose graph: unknown node " + toString(key)};
  const Node& n = it->second;
  return SE3(Quat(n.q[3], n.q[0], n.q[1], n.q[2]), Vec3(n.t[0], n.t[1], n.t[2]));
}

std::map<KeyframeKey, SE3> PoseGraph::poses() const {
  std::map<KeyframeKey, SE3> out;
  for (const auto& [key, n] : nodes_) {
    out.emplace(key, SE3(Quat(n.q[3], n.q[0], n.q[1], n.q[2]), Vec3(n.t[0], n.t[1], n.t[2])));
  }
  return out;
}

}  // namespace server
}  // namespace hermes
