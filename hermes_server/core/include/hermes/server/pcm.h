// Pairwise consistent measurement set maximisation (PCM, DESIGN.md §5): loops
// between the same two trajectories (agent, session) — or within one — are
// pairwise consistent when the cycle
//   T_ai_aj (odometry of a) * T_aj_bj (loop j) * T_bj_bi (odometry of b) * T_bi_ai (loop i)
// is near identity: the Mahalanobis distance of its SE(3) log under the
// first-order propagated covariance is below the chi-square quantile (6 dof).
// The largest set of mutually consistent loops (maximum clique of the
// consistency graph) is accepted: exact branch and bound with a greedy-colouring
// bound up to `exact_max_loops` loops per group, beyond that a greedy heuristic
// (grow a clique from each vertex by repeatedly adding the candidate with the
// most neighbours among the remaining candidates; keep the largest).
//
// Segments: loops are judged through the odometry between them, so an odometry
// jump the agent did not notice (or a drift beyond its noise model) splits the
// right loops into groups that are consistent within, not across. After the
// largest clique, further cliques of the remaining loops are accepted (largest
// first, at most `max_segments` in all) when each holds at least
// max(min_clique_size, min_segment_size) loops and lies on a stretch of one of the two trajectories that no accepted clique
// overlaps (keyframe-id ranges disjoint): an odometry break between them
// explains the inconsistency, and the pose graph's robust odometry loss lets
// that break give way.
//
// Drift allowance: the odometry noise model is a random walk (variance linear
// in the distance), right for the odometry's noise but not for a systematic
// drift (a scale error, a textureless stretch), whose error grows linearly with
// the distance. Under such a drift right loops far apart along the chain look
// inconsistent and the clique splits them (a silent 3 % drift: half of the
// right loops rejected). The chain covariance of each cycle therefore gets
// diag((drift_fraction·d)² I₃, (drift_rad_per_m·d)² I₃), d the path length
// of the odometry between the two loops. Loops close together along the
// chain are still judged on the tight random-walk model, so a wrong loop
// stays inconsistent with its right neighbours.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/geometry.h"
#include "hermes/core/map_types.h"
#include "hermes/core/status.h"

namespace hermes {
namespace server {

class ByteReader;
class ByteWriter;

struct PcmParams {
  double chi2_probability = 0.99;  ///< consistency gate: chi2 quantile of this probability
  int exact_max_loops = 40;        ///< exact maximum clique up to this many loops per group (<= 64)
  int min_clique_size = 1;         ///< a group's clique smaller than this is rejected
  int max_segments = 4;            ///< cliques accepted per group at most (1 = the classic PCM)
  int min_segment_size = 3;        ///< loops a clique beyond the first needs at least
  double drift_fraction = 0.01;    ///< [m/m] translation drift allowed per metre of odometry (0 = none)
  double drift_rad_per_m = 0.001;  ///< [rad/m] rotation drift allowed per metre of odometry
  /// Loops between two groups of tied trajectories accepted together when at
  /// least this many are consistent through the groups' ties, over at least two
  /// trajectory pairs (group_bridge.h); 0 = off.
  int bridge_min_loops = 3;

  Status read(const Config& config, const std::string& prefix);
  void write(ConfigWriter* writer, const std::string& prefix) const;
  Status validate() const;
};

/// A loop between keyframe a and keyframe b (T_a_b: b in a), with the covariance
/// of its right perturbation T_a_b * exp(xi), xi = [rho; phi].
struct LoopCandidate {
  std::uint64_t id = 0;
  KeyframeKey a, b;
  SE3 T_a_b;
  Mat6 covariance = Mat6::Identity();
};

struct RelativePose {
  SE3 T;                        ///< T_from_to
  Mat6 covariance = Mat6::Zero();  ///< right perturbation
  double path_length_m = 0;     ///< distance travelled between the two keyframes
};

/// Odometry between two keyframes of one trajectory (same agent and session).
using OdometryQuery =
    std::function<Expected<RelativePose>(const KeyframeKey& from, const KeyframeKey& to)>;

/// Keyframe poses T_A_K and odometry edge covariances of each trajectory;
/// answers OdometryQuery by composing the edges between the two keyframes.
class OdometryChain {
 public:
  Status addKeyframe(const KeyframeKey& key, const SE3& T_A_K);
  /// Edge between consecutive keyframes (by id) of one trajectory.
  Status addEdge(const KeyframeKey& from, const KeyframeKey& to, const Mat6& information);
  Expected<RelativePose> relative(const KeyframeKey& from, const KeyframeKey& to) const;
  OdometryQuery query() const;
  /// Grows whenever the odometry between two existing keyframes may have
  /// changed (a keyframe inserted between others); appending does not.
  std::uint64_t revision() const { return revision_; }

  /// Checkpoint (server_checkpoint.h): the whole chain, revision included.
  void save(ByteWriter* w) const;
  /// Into an empty chain; false on damaged input.
  bool load(ByteReader* r);

 private:
  struct Entry {
    SE3 T_A_K;
    bool has_edge_to_next = false;
    Mat6 covariance_to_next = Mat6::Zero();  ///< of T_k_next (right perturbation)
  };
  using Trajectory = std::map<KeyframeId, Entry>;
  std::map<std::pair<std::uint32_t, std::uint32_t>, Trajectory> trajectories_;
  std::uint64_t revision_ = 0;
};

/// Verdicts of loop pairs from earlier runs, so that a run computes only the
/// pairs with a new or re-measured loop (a whole mission's PCM was quadratic in
/// its loops on every merge). A verdict depends on the two loop measurements and
/// the odometry between them: forget() a loop whose measurement changed, clear()
/// when odometry between existing keyframes changed (OdometryChain::revision())
/// or the parameters did. Pairs whose odometry is unavailable are not stored.
/// Storage: per trajectory pair, one byte per loop pair.
class PcmCache {
 public:
  using Group = std::pair<std::pair<std::uint32_t, std::uint32_t>, std::pair<std::uint32_t, std::uint32_t>>;
  /// 1 consistent, 0 inconsistent, -1 not known.
  int verdict(const Group& group, std::uint64_t i, std::uint64_t j) const;
  void store(const Group& group, std::uint64_t i, std::uint64_t j, bool consistent);
  void forget(std::uint64_t loop);
  void clear();
  std::size_t bytes() const;

 private:
  struct Table {
    std::map<std::uint64_t, int> index;       ///< loop id -> row
    std::vector<std::vector<signed char>> rows;  ///< row r: verdicts with rows < r
  };
  int row(Table* t, std::uint64_t id);
  std::map<Group, Table> tables_;
};

struct PcmResult {
  std::vector<std::uint64_t> accepted;
  std::vector<std::uint64_t> rejected;
  int groups = 0;               ///< trajectory pairs seen
  bool all_exact = true;        ///< false when some group used the greedy heuristic
  int segment_cliques = 0;      ///< cliques accepted beyond the first (odometry breaks)
  int odometry_failures = 0;    ///< loop pairs whose odometry was unavailable (counted inconsistent)
  long pairs_computed = 0;      ///< cycle distances computed in this run
  long pairs_cached = 0;        ///< verdicts taken from the cache
  double time_ms = 0;
};

/// Runs PCM over all candidates (grouped by trajectory pair). With a cache,
/// known pair verdicts are reused and new ones stored (same result as without).
PcmResult selectConsistentLoops(const std::vector<LoopCandidate>& loops,
                                const OdometryQuery& odometry, const PcmParams& params,
                                PcmCache* cache = nullptr);

/// Squared Mahalanobis distance of the cycle formed by loops i and j (both
/// oriented from trajectory A to trajectory B), the odometry's covariance
/// widened by the drift allowance of `params`. Errors come from the odometry.
Expected<double> cycleMahalanobis2(const LoopCandidate& i, const LoopCandidate& j,
                                   const OdometryQuery& odometry, const PcmParams& params);

/// The drift allowance added to the covariance of odometry over `path_length_m`.
Mat6 driftAllowance(double path_length_m, const PcmParams& params);

/// The loop seen from b: T_b_a with the covariance of its right perturbation.
LoopCandidate reversedLoop(const LoopCandidate& loop);

/// Quantile of the chi-square distribution (probability p, dof degrees of freedom).
double chi2Quantile(double p, int dof);

/// Maximum clique of an undirected graph (adjacency[i][j] symmetric). Exact for
/// n <= exact_max (<= 64), greedy beyond; *exact tells which was used.
std::vector<int> maximumClique(const std::vector<std::vector<char>>& adjacency, int exact_max,
                               bool* exact);

}  // namespace server
}  // namespace hermes
