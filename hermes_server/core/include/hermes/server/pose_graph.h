// SE(3) pose graph over keyframes of all agents (DESIGN.md §5 "Pose graph"):
// Ceres, quaternion (EigenQuaternionManifold) + translation per node, odometry and
// loop edges as whitened 6-dof relative-pose residuals, a robust loss on loop
// edges (and optionally on odometry edges: an odometry jump the agent did not
// notice then gives way to the loops on both sides), SPARSE_NORMAL_CHOLESKY
// (SuiteSparse). The gauge is fixed by holding chosen nodes constant (the anchor
// agent's first keyframe). After a solve, residuals() tells per edge how far
// it is from its measurement and how much the robust loss weighs it.
#pragma once

#include <map>
#include <string>
#include <vector>

#include <ceres/ceres.h>

#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {
namespace server {

struct PoseGraphParams {
  std::string loop_loss = "cauchy";  ///< none | huber | cauchy (loop edges)
  double loop_loss_scale = 1.0;      ///< loss scale on the whitened residual norm [sigma]
  std::string odometry_loss = "cauchy";  ///< none | huber | cauchy (odometry edges)
  double odometry_loss_scale = 3.0;    ///< [sigma]
  /// Odometry that disagrees with the loops more than the rest: after a solve,
  /// each odometry edge gets the mean chi2 per degree of freedom of a group of
  /// edges around it (scope "trajectory": all edges of its robot's trajectory,
  /// a variance-component estimate per robot; "local": the edges within
  /// +-window of it; "both": the larger); its covariance is scaled by that over
  /// the median of the +-window values of all edges (at least 1, at most
  /// reweight_max; the median floored at reweight_floor), and the graph solved
  /// again; up to this many rounds (0 = off). Least squares alone splits a drift among every robot the loops tie
  /// together (the common frame bends); where one robot drifts and the others
  /// agree with each other, its edges carry more of the disagreement, and the
  /// rounds put all of it there. "trajectory" spreads a robot's correction
  /// along its path as its noise model says; "local" concentrates it where the
  /// residuals are largest (a feedback over rounds that also concentrates a
  /// smooth drift into a few edges); "both" takes the larger, so that a robot
  /// drifting all along and a stretch drifting within a sound robot are both
  /// caught. Replayed (bench pose_graph) on whole MH_01-05: all-robot ATE 4.17
  /// (local, first typical level) -> 3.53 (trajectory) / 3.69 (both); the
  /// 30-s meeting clip with a 3 % drift: the sound robot 1.58 (trajectory) /
  /// 1.40 cm (both; 0.90 clean).
  int odometry_reweight_rounds = 5;
  std::string odometry_reweight_scope = "local";  ///< trajectory | local | both
  int odometry_reweight_window = 5;    ///< [edges] each side (scope local)
  double odometry_reweight_max = 100;  ///< largest covariance scale
  double odometry_reweight_floor = 0.01;  ///< [chi2 per dof] floor of the median
  /// A loop's rigs place the neighbours of both keyframes with their robots'
  /// odometry, so where that odometry is re-weighted (found wrong) the loop is
  /// biased too: its covariance is scaled by the mean re-weighting scale of the
  /// odometry edges within +-loop_rig_edges of each end, the larger of the two
  /// (0 = off). Meeting clip, 3 % silent drift, map-based candidates on
  /// (replays): the sound robot 2.18 -> 1.22 cm, the drifting one 2.39 ->
  /// 1.38 cm (ground-truth loops: 0.62 / 0.63); clean 0.99 -> 0.93 cm.
  int loop_rig_edges = 2;
  /// Continuation on the robust loss: solve with scales loop_loss_scale *
  /// anneal_factor^(anneal_steps-1), ..., loop_loss_scale. Without it, loops far
  /// from a drifted initial guess all look like outliers and are ignored.
  int anneal_steps = 4;
  double anneal_factor = 4.0;
  int max_iterations = 100;
  double function_tolerance = 1e-8;
  int num_threads = 1;
  /// Incremental solves (the server's MapManager): after a first full solve,
  /// only the nodes within this many edges (odometry or loop) of what changed
  /// (new keyframes, loops accepted or dropped, robots anchored) are free, the
  /// rest held at their last solution; 0 = every solve full.
  int incremental_hops = 8;
  /// A full solve after this many incremental ones (what the held parts would
  /// still gain from the changes reaches them there).
  int full_every = 5;
  /// An incremental solve frees at most this many nodes (0 = no cap): the
  /// changed ones and then the nearest, breadth first. Where hundreds of loops tie
  /// every robot's map, `incremental_hops` edges reach the whole graph (the one-hour
  /// soak: 3378 keyframes, 6566 loops, an incremental solve p95 16 s).
  int incremental_max_free = 400;
  /// The full solve runs between merges, not inside the one that falls due: when
  /// no submap waits (Server::process, after the queue drains) or, in the threaded
  /// server, on a thread of its own while merges go on (ServerWorker); merges only
  /// solve incrementally. false = inside the merge, as before.
  bool full_between_merges = true;

  Status read(const Config& config, const std::string& prefix);
  void write(ConfigWriter* writer, const std::string& prefix) const;
  Status validate() const;
};

/// Relative-pose residual between nodes a and b (poses T_W_a, T_W_b stored as
/// quaternion [x y z w] + translation). With the error transform
///   T_err = T_a_b_meas^-1 * T_W_a^-1 * T_W_b,
/// e = [t_err; 2 vec(q_err)] (sign chosen so that w >= 0), which equals the SE(3)
/// log [rho; phi] to first order, and residual = sqrt_information * e with
/// sqrt_informationᵀ sqrt_information = information.
struct RelativePoseError {
  RelativePoseError(const SE3& T_a_b, const Mat6& sqrt_information)
      : T_a_b_(T_a_b), sqrt_information_(sqrt_information) {}

  template <typename T>
  bool operator()(const T* q_a, const T* t_a, const T* q_b, const T* t_b, T* residual) const {
    using Q = Eigen::Quaternion<T>;
    using V = Eigen::Matrix<T, 3, 1>;
    const Q qa(q_a[3], q_a[0], q_a[1], q_a[2]);
    const Q qb(q_b[3], q_b[0], q_b[1], q_b[2]);
    const V ta(t_a[0], t_a[1], t_a[2]);
    const V tb(t_b[0], t_b[1], t_b[2]);
    // Estimated relative pose T_a_b = T_W_a^-1 T_W_b.
    const Q qa_inv = qa.conjugate();
    const Q q_ab = qa_inv * qb;
    const V t_ab = qa_inv * (tb - ta);
    // Error against the measurement.
    const Q qm_inv = T_a_b_.quat().conjugate().template cast<T>();
    const Q q_err = qm_inv * q_ab;
    const V t_err = qm_inv * (t_ab - T_a_b_.translation().template cast<T>());
    const T sign = q_err.w() < T(0) ? T(-1) : T(1);
    Eigen::Matrix<T, 6, 1> e;
    e.template head<3>() = t_err;
    e.template tail<3>() = T(2) * sign * q_err.vec();
    Eigen::Map<Eigen::Matrix<T, 6, 1>> r(residual);
    r = sqrt_information_.template cast<T>() * e;
    return true;
  }

  /// Cost function with blocks (q_a 4, t_a 3, q_b 4, t_b 3).
  static ceres::CostFunction* create(const SE3& T_a_b, const Mat6& sqrt_information);

 private:
  SE3 T_a_b_;
  Mat6 sqrt_information_;
};

/// Upper-triangular square root L of a symmetric positive definite information
/// (Lᵀ L = information); an error when it is not positive definite or not finite.
Expected<Mat6> sqrtInformation(const Mat6& information);

struct PoseGraphResult {
  double initial_cost = 0;
  double final_cost = 0;
  int iterations = 0;             ///< summed over the annealing stages
  double time_ms = 0;
  bool converged = false;         ///< the last stage ended by a convergence criterion
  int reweight_rounds = 0;        ///< odometry re-weighting rounds done
  std::string termination;        ///< Ceres termination of the last stage
  std::string report;  ///< Ceres brief report
};

/// One edge after a solve.
struct EdgeResidual {
  KeyframeKey a, b;
  bool loop = false;
  double error_m = 0;      ///< translation of T_meas^-1 T_a^-1 T_b [m]
  double error_rad = 0;    ///< its rotation angle [rad]
  double chi2 = 0;         ///< squared whitened error (under the edge's own information)
  /// Weight the solve gave it relative to its own information: robust weight
  /// rho' at the final scale, for odometry divided by its re-weighting scale (1 = fully trusted).
  double weight = 1;
};

class PoseGraph {
 public:
  explicit PoseGraph(const PoseGraphParams& params = PoseGraphParams());

  /// Adds a node with its initial world pose. For a non-anchor agent pass
  /// T_W_A (the current estimate of its frame) * T_A_K.
  Status addNode(const KeyframeKey& key, const SE3& T_W_K);
  /// Convenience: every keyframe pose T_A_K of one agent, placed with T_W_A.
  Status addAgentNodes(const std::vector<std::pair<KeyframeKey, SE3>>& T_A_K, const SE3& T_W_A);
  Status addOdometryEdge(const KeyframeKey& from, const KeyframeKey& to, const SE3& T_from_to,
                         const Mat6& information);
  Status addLoopEdge(const KeyframeKey& a, const KeyframeKey& b, const SE3& T_a_b,
                     const Mat6& information);
  /// Drops every loop edge (e.g. before re-adding the set PCM accepts now).
  void clearLoopEdges() { loops_.clear(); }
  /// Holds a node constant (gauge).
  Status setFixed(const KeyframeKey& key);
  /// Holds the first (smallest key) node of `agent` constant.
  Status fixFirstPoseOf(std::uint32_t agent);
  /// For an incremental solve: holds constant every node more than `hops`
  /// edges (odometry or loop) from all `seeds` (keys not in the graph are
  /// ignored); edges between two held (or fixed) nodes leave the problem.
  /// Returns how many nodes stay free. Call after adding every edge.
  /// At most `max_free` nodes stay free (0 = no cap): every seed, then breadth
  /// first in edge order (deterministic).
  std::size_t holdBeyond(const std::vector<KeyframeKey>& seeds, int hops, std::size_t max_free = 0);
  /// Nodes the solve may move (not fixed, not held).
  std::size_t numFree() const;

  /// Optimises all nodes connected by edges. Without any fixed node the
  /// smallest key is fixed. Errors name an unusable problem (no edges).
  Expected<PoseGraphResult> optimize();

  bool hasNode(const KeyframeKey& key) const { return nodes_.count(key) > 0; }
  Expected<SE3> pose(const KeyframeKey& key) const;
  std::map<KeyframeKey, SE3> poses() const;
  std::size_t numNodes() const { return nodes_.size(); }
  std::size_t numOdometryEdges() const { return odometry_.size(); }
  std::size_t numLoopEdges() const { return loops_.size(); }
  /// Every edge's residual at the current poses (odometry first, then loops).
  std::vector<EdgeResidual> residuals() const;
  /// Every edge as given (odometry first, then loops), for writing the graph out.
  struct EdgeMeasurement {
    KeyframeKey a, b;
    SE3 T_a_b;
    Mat6 information;
    bool loop = false;
  };
  std::vector<EdgeMeasurement> measurements() const;
  /// Nodes held constant.
  std::vector<KeyframeKey> fixedNodes() const;

 private:
  struct Node {
    std::array<double, 4> q;  // x y z w
    std::array<double, 3> t;
    bool fixed = false;
    bool held = false;  ///< constant in an incremental solve (holdBeyond)
  };
  struct Edge {
    KeyframeKey a, b;
    SE3 T_a_b;
    Mat6 sqrt_information;
  };
  bool robust() const;  ///< some edge kind has a robust loss (annealing applies)
  /// The edge is in the problem: some end may move.
  bool active(const Edge& e) const;
  /// One solve (annealed robust losses when `anneal`) at the current odometry scales.
  Expected<PoseGraphResult> solve(bool anneal);
  /// Sets odometry_scale_ from the residuals; true when some scale changed by > 10 %.
  bool reweightOdometry();
  /// Odometry edges of each trajectory (agent, session), in key order.
  using TrajectoryEdges =
      std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<std::pair<KeyframeKey, std::size_t>>>;
  Status addEdge(const KeyframeKey& a, const KeyframeKey& b, const SE3& T_a_b,
                 const Mat6& information, const char* kind, std::vector<Edge>* edges);
  double edgeChi2(const Edge& e) const;
  static SE3 nodePose(const Node& n) {
    return SE3(Quat(n.q[3], n.q[0], n.q[1], n.q[2]), Vec3(n.t[0], n.t[1], n.t[2]));
  }

  PoseGraphParams params_;
  std::map<KeyframeKey, Node> nodes_;
  std::vector<Edge> odometry_;
  std::vector<Edge> loops_;
  std::vector<double> odometry_scale_;  ///< per odometry edge, covariance scale of the re-weighting
  std::vector<double> loop_scale_;      ///< per loop edge, covariance scale from its rigs' odometry
};

}  // namespace server
}  // namespace hermes
