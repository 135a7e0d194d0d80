// Merging of submaps into the global map (DESIGN.md §5): store keyframes and
// landmarks under (agent, session, id), keep per-trajectory odometry chains,
// BoW place recognition per new keyframe, rig-based 17-point loop closure for
// the candidates, PCM over all loops, anchoring of agents tied to the world by
// accepted loops, world selection, pose-graph optimisation. Anchoring is per
// trajectory (robot, session): the world trajectory is chosen once, every
// other one (also a later session of the world robot) needs min_world_loops
// accepted loops to anchored trajectories (bookkeeper.h: re-localisation).
//
// One merge (merge()) runs the stages in order, each in its own source file:
// store (map_manager_store.cc: keyframes, landmarks, odometry, keyframe
// extensions), detect_loops (map_manager_loops.cc: place and spatial
// candidates, closure budget, 17-point verification), pcm and anchoring
// (map_manager_anchoring.cc), optimize (map_manager_optimize.cc: incremental
// and full pose-graph solves); checkpoints in map_manager_io.cc.
#pragma once

#include <deque>
#include <map>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/metrics.h"
#include "hermes/core/odometry_noise.h"
#include "hermes/server/bookkeeper.h"
#include "hermes/server/global_map.h"
#include "hermes/server/group_bridge.h"
#include "hermes/server/loop_closure.h"
#include "hermes/server/pcm.h"
#include "hermes/server/place_recognition.h"
#include "hermes/server/pose_graph.h"

namespace hermes {
namespace server {

class ByteReader;
class ByteWriter;

struct MapManagerParams {
  PlaceRecognitionParams place_recognition;  ///< server.place_recognition.*
  LoopClosureParams loop_closure;            ///< server.loop_closure.*
  PcmParams pcm;                             ///< server.pcm.*
  PoseGraphParams pose_graph;                ///< server.pose_graph.*
  // server.map.*
  /// Inlier keypoint pairs kept per accepted loop (evenly spaced, saved with
  /// the map) for the map-consistency measure (map_consistency.h); 0 = none.
  int ties_per_loop = 200;
  int rig_neighbours = 2;              ///< m neighbours per rig side
  int max_candidates_per_keyframe = 3; ///< place candidates verified per keyframe
  /// Map-based candidates: once its robot is anchored, a new keyframe is also
  /// tried against up to this many stored keyframes near its estimated world
  /// pose (nearest first, not next to a place candidate already tried, the
  /// place recognition's own-recent exclusions apply). Bag-of-words misses
  /// revisits where texture repeats or light is poor: on whole MH_04 + MH_05 its
  /// top islands were wrong places for 50 s while the two robots flew the same
  /// path 0.3-1.5 m apart (whole MH_04 + MH_05: loops 237 -> 479, merged ATE
  /// 4.22 -> 1.55 cm). Under a silent drift these extra right loops used to
  /// split PCM (fixed by its drift allowance) and, their rigs being placed by
  /// the drifting odometry, bend the sound robot (fixed by the pose graph's
  /// loop_rig_edges).
  int spatial_candidates = 1;
  double spatial_radius_m = 1.0;       ///< [m] camera centres at most this far apart
  double spatial_max_angle_deg = 30;   ///< [deg] optical axes at most this far apart
  int optimize_every_submaps = 10;     ///< also optimise after this many merges (0 = only on new loops)
  /// odometry.* (shared with the agents): bridges between windows, where no
  /// edge was sent, get the model's information for their relative pose.
  OdometryNoiseParams odometry;
  int min_world_loops = 3;             ///< accepted loops needed to anchor an agent
  /// Threads verifying the loops of one merge (17-point closures of every new
  /// keyframe's candidates, and loops closed again after keyframe extensions):
  /// the candidates are chosen first, verified side by side, and taken in the
  /// order chosen, so the loops (and their ids) are the same for any count.
  /// 1 = in the merging thread (synchronous).
  int loop_threads = 2;
  /// Near-duplicate closures: two closures of one merge whose query keyframes
  /// are at most this many stored keyframes apart on one trajectory and whose
  /// candidates are too (their rigs share keyframes: adjacent query keyframes
  /// propose nearly the same place). The first in order is verified; the later
  /// ones only when none of the first ones they duplicate gave a loop (two
  /// rounds, so the loops are the same for any loop_threads). 0 = verify all.
  int duplicate_neighbours = 2;
  /// Near-duplicates are skipped only once the first round of the merge found at
  /// least this many loops between the same two trajectories (sparse ties keep
  /// every loop; the dense ones of robots not yet placed are thinned). 0 = always.
  int duplicate_min_pair_loops = 6;
  /// At most this many closures verified per merge (closure_budget.h): round
  /// robin over the trajectory pairs, pairs with fewer accepted loops first; the
  /// others are deferred (closeDeferred()), and so are all the loops a merge's
  /// keyframe extensions would measure again. 0 = verify all in the merge, or
  /// the swarm's share below.
  int closure_budget = 0;
  /// With closure_budget 0 and at least closure_budget_min_robots robots active
  /// (a submap merged in the last active_robot_s, the merging one included): the
  /// closures the server verifies per submap window across the swarm; each merge
  /// gets ceil(this / robots active) and defers the rest (Server::process,
  /// setClosureBudget()). 0 = off.
  int closure_budget_swarm = 160;
  /// Fewer robots active: every closure verified in the merge. A budget costs
  /// accuracy where the server could verify everything (whole MH, 5 robots:
  /// 0.64 -> 0.67 cm at 32 per merge) and is needed where it cannot (20 robots:
  /// a submap's merge 7.5 -> 0.8 s at p95 with 8).
  int closure_budget_min_robots = 9;
  /// [s] a robot counts as active for closure_budget_swarm this long after its
  /// last merged submap.
  double active_robot_s = 15;
  /// Stage timings (the map manager's and the server's) keep the last this many
  /// samples per stage for median / p95 (0 = all: a day-long mission would grow
  /// them, and the checkpoints that hold them, with every merge).
  int timing_window = 10000;
  /// Closures over the budget wait here (oldest dropped beyond this many) and
  /// are verified by closeDeferred() while no submap waits.
  int deferred_closures = 1024;
  /// Sparse ties: a closure between two trajectories with fewer than
  /// sparse_pair_loops accepted loops between them is accepted up to this
  /// translation sigma (the others up to loop_closure.max_translation_sigma_m);
  /// its information says how loose it is, and PCM judges it as any other.
  /// Whole MH at 2 Mbit/s shared: the easy robots (MH_01-03) and the fast ones
  /// (MH_04/05) were tied by 10 loops while 62 right closures between them
  /// (150-430 inliers) failed the 3-cm gate, and the loosely tied groups bent
  /// the common frame (easy robots above their odometry). 0 = off.
  int sparse_pair_loops = 20;
  double sparse_pair_sigma_m = 0.05;   ///< [m]

  MapManagerParams() { pcm.min_clique_size = 3; }
  Status read(const Config& config, const std::string& prefix = "server.");
  Status validate() const;
  void write(ConfigWriter& out, const std::string& prefix = "server.") const;
};

struct MergeStats {
  int keyframes = 0, landmarks = 0;
  int keyframes_extended = 0;  ///< stored keyframes that keyframe extensions added keypoints to
  int extensions_unknown = 0;  ///< keyframe extensions of keyframes this map does not hold
  int loops_reverified = 0;    ///< loops closed again after keyframe extensions
  int loops_replaced = 0;      ///< of those, measurements replaced (not fewer inliers)
  int place_candidates = 0;
  int loops_attempted = 0, loops_geometric = 0;
  int loops_skipped_duplicate = 0;  ///< closures not verified: near-duplicates of a loop (duplicate_neighbours)
  int loops_skipped_budget = 0;     ///< closures deferred: over the merge's closure_budget
  int loops_reverify_deferred = 0;  ///< re-verifications after keyframe extensions deferred (budget on)
  bool optimized = false;
  /// Wall time of this merge per stage [ms]: store, extend, detect_loops (place
  /// recognition + closures), pcm, anchoring, optimize, total.
  std::map<std::string, double> stage_ms;
};

/// What the last pose-graph solve did (diagnostics: where the merged map departs
/// from its measurements, which edges the robust losses gave up on).
struct GraphDiagnostics {
  PoseGraphResult result;
  std::vector<EdgeResidual> edges;
  int solves = 0;          ///< solves so far
  int not_converged = 0;   ///< of those, ended without a convergence criterion
  int incremental = 0;     ///< of those, incremental (pose_graph.incremental_hops)
  bool last_incremental = false;
  std::size_t last_free_nodes = 0, last_nodes = 0;  ///< the last solve's free / all nodes
};

/// A full pose-graph solve taken out of the merges (pose_graph.full_between_merges):
/// the graph as it stood when prepared and its poses then; run() solves it on any
/// thread (it touches nothing else), MapManager::applyFullSolve() brings the result
/// into the map on the merging thread, also after merges that came meanwhile.
struct FullSolve {
  PoseGraph graph;
  std::map<KeyframeKey, SE3> snapshot;
  std::optional<Expected<PoseGraphResult>> result;  ///< set by run()
  double ms = 0;                                     ///< run()'s wall time
  void run();  ///< never throws: an exception becomes an error result
};

/// One loop-closure attempt (diagnostics): a new keyframe's place query and,
/// per candidate tried, what geometric verification said. A query without any
/// candidate is reported once with `candidate` empty.
struct LoopAttempt {
  KeyframeKey query;
  std::optional<PlaceCandidate> candidate;
  bool spatial = false;  ///< a map-based candidate (near the estimated pose), not a place one
  LoopStatus status = LoopStatus::kBadInput;
  std::string reason;  ///< empty when accepted or without a candidate
  int matches = 0, inliers = 0;
  int prefiltered = 0;          ///< matches left by the per-pair pre-filter
  int ransac_iterations = 0;
  int ransac_enough_at = -1;    ///< 17-point iteration that first had the inliers needed (-1 = none)
  double ms = 0;                ///< matching + geometry [ms]
  double prefilter_ms = 0, ransac_ms = 0, refine_ms = 0;  ///< parts of ms
};

class MapManager {
 public:
  /// Test hooks: rewrite place candidates, or a loop result before PCM.
  using CandidateHook = std::function<void(const KeyframeKey& query, std::vector<PlaceCandidate>*)>;
  using LoopHook = std::function<void(const KeyframeKey& a, const KeyframeKey& b, SE3* T_a_b)>;
  /// Diagnostics: told every loop-closure attempt of new keyframes.
  using AttemptHook = std::function<void(const LoopAttempt&)>;

  MapManager(std::shared_ptr<const Vocabulary> vocabulary, MapManagerParams params,
             Bookkeeper* bookkeeper);

  /// Merges one accepted submap of `robot`. Errors name the submap; the map is
  /// left consistent (keyframes already stored stay).
  Expected<MergeStats> merge(RobotId robot, const Submap& submap,
                             const std::function<double(RobotId)>& credibility = nullptr);

  /// Verifies up to `max_closures` of the closures deferred by the budget
  /// (closure_budget; chosen as in a merge, pairs with fewer loops first), then
  /// PCM, anchoring and, once none is left, the pose graph. Returns how many were
  /// verified (0: none waiting).
  Expected<int> closeDeferred(int max_closures, const std::function<double(RobotId)>& credibility = nullptr,
                              MergeStats* stats = nullptr);
  /// Closures waiting for closeDeferred(), and those dropped because more waited
  /// than deferred_closures.
  std::size_t deferredClosures() const { return deferred_.size(); }
  /// The closure budget of the merges from now on (closure_budget.h; 0 = verify
  /// all in the merge). Starts at params.closure_budget; the server sets it per
  /// merge from closure_budget_swarm.
  void setClosureBudget(int budget) { closure_budget_ = budget; }
  int closureBudget() const { return closure_budget_; }
  std::size_t deferredDropped() const { return deferred_dropped_; }

  /// Optimises the pose graph of the anchored trajectories now: incrementally
  /// (only around what changed since the last solve, pose_graph.incremental_hops)
  /// unless `full`, incremental_hops is 0, no solve was done yet or full_every
  /// incremental solves were.
  Status optimize(bool full = false);
  /// A full solve is due and merges leave it to the caller (full_between_merges):
  /// prepareFullSolve(), FullSolve::run(), applyFullSolve().
  bool fullSolveDue() const;
  Expected<FullSolve> prepareFullSolve() const;
  Status applyFullSolve(const FullSolve& job);
  /// After a failed one: due again only after full_every more incremental solves.
  void postponeFullSolve() { incremental_since_full_ = 0; }
  /// The pose graph optimize() would solve, at the current poses.
  Expected<PoseGraph> buildPoseGraph() const;
  /// Writes that graph as g2o text (pose_graph_io.h).
  Status writePoseGraph(const std::string& path) const;

  const GlobalMap& map() const { return map_; }
  const TimingStats& timings() const { return timings_; }
  const GraphDiagnostics& graphDiagnostics() const { return graph_diag_; }
  /// The loop rig's other keyframes around stored keyframe `key` (rig_neighbours,
  /// earlier ones first, never across a loss of tracking); `cams` gets the
  /// cameras of key and then of each neighbour.
  std::vector<const Keyframe*> neighbours(const KeyframeKey& key, std::vector<PinholeIntrinsics>* cams) const;
  std::size_t loopsAccepted() const;
  std::size_t loopsRejected() const;
  /// Of the accepted, those bridging tie groups (group_bridge.h; latest PCM run).
  int loopsBridged() const { return loops_bridged_; }
  bool hasLoops(RobotId robot) const;
  /// Agents (current sessions) anchored in the world frame, not counting a
  /// prior map's (reads the bookkeeper: with a bookkeeper lock, call with it held).
  int agentsMerged() const;
  /// Agents of the prior map the server started on (Bookkeeper::isPrior).
  int priorAgents() const;
  /// The trajectories' agent uuids after Bookkeeper::sealAsPrior (old -> new).
  void renameAgents(const std::map<Uuid, Uuid>& renamed);
  /// Checkpoint (server_checkpoint.h): map, odometry chain, place database
  /// order, loop ids, world trajectory, solve counters, timings. The PCM cache
  /// is not kept (rebuilt on the next run, same verdicts).
  void save(ByteWriter* w) const;
  /// Into a manager that merged nothing yet; the error names what is damaged.
  Status load(ByteReader* r);

  void setCandidateHook(CandidateHook h) { candidate_hook_ = std::move(h); }
  void setLoopHook(LoopHook h) { loop_hook_ = std::move(h); }
  void setAttemptHook(AttemptHook h) { attempt_hook_ = std::move(h); }
  /// The bookkeeper is shared with a thread that receives frames and changes
  /// it under `lock` (Server, server_worker.h): merge() holds `lock` while it
  /// anchors agents (world selection, markAnchored; credibility is called
  /// there, under it), the only time a merge touches the bookkeeper. Short:
  /// loops over trajectories and loops, no solve. nullptr: not shared.
  void setBookkeeperLock(std::mutex* lock) { bookkeeper_lock_ = lock; }

 private:
  /// Stores the window's new keyframes (`added`) and landmarks; keyframe
  /// extensions append their keypoints to stored keyframes (`extended`).
  void storeSubmap(RobotId robot, const Submap& submap, std::vector<KeyframeKey>* added,
                   std::vector<KeyframeKey>* extended, MergeStats* stats);
  /// One loop to verify: a new keyframe and one of its candidates; without a
  /// candidate, the keyframe's report that place recognition found none.
  struct LoopJob {
    KeyframeKey query;
    std::optional<PlaceCandidate> candidate;
    bool spatial = false;
    /// Set: not a new closure but loop `reverify` measured again (its rig
    /// gained keypoints from keyframe extensions); query / candidate = its ends.
    std::optional<std::uint64_t> reverify;
  };
  /// Position of a stored keyframe in its trajectory (-1 if not stored).
  int positionOf(const KeyframeKey& key) const;
  /// For each job, the earlier first-round jobs it is a near-duplicate of
  /// (duplicate_neighbours); empty = verified in the first round.
  std::vector<std::vector<std::size_t>> nearDuplicates(const std::vector<LoopJob>& jobs) const;
  /// Per job, whether the merge's closure budget (closure_budget) lets it be
  /// verified: the first-round jobs by chooseWithinBudget(), a near-duplicate
  /// only with one of the jobs it duplicates.
  std::vector<char> closuresWithinBudget(const std::vector<LoopJob>& jobs,
                                         const std::vector<std::vector<std::size_t>>& dups) const;
  /// A verified (or skipped) closure reported to the attempt hook and, when it
  /// is geometrically sound, stored as a loop for PCM.
  void takeClosure(const LoopJob& job, const LoopClosureResult& r, MergeStats* stats);
  /// Keeps a closure over the budget for closeDeferred() (oldest dropped when full).
  void defer(const LoopJob& job);
  /// The loop with this id measured again: the new measurement replaces it
  /// unless it has fewer inliers (or the closure failed).
  void takeReverification(std::uint64_t loop_id, const LoopClosureResult& r, MergeStats* stats);
  /// Place recognition for the newly stored keyframes (in order), then loop
  /// closure of all their candidates on loop_threads threads.
  void detectLoops(const std::vector<KeyframeKey>& added, MergeStats* stats);
  /// The 17-point verification of each (query, candidate) pair, side by side
  /// (loop_threads); results in the pairs' order, timings recorded.
  std::vector<LoopClosureResult> verifyPairs(const std::vector<std::pair<KeyframeKey, KeyframeKey>>& pairs);
  /// The rigs of two stored keyframes verified (thread-safe: reads the map only).
  /// `sparse`: the two trajectories are tied by few loops (sparse_pair_*).
  LoopClosureResult verifyPair(const KeyframeKey& query, const KeyframeKey& candidate, bool sparse) const;
  /// The loop edge (no id yet) of a verified pair; the loop hook applies.
  std::optional<LoopEdge> loopEdge(const KeyframeKey& query, const KeyframeKey& candidate,
                                   const LoopClosureResult& r) const;
  /// Stored keyframes near `key`'s estimated world pose to try as loop
  /// candidates (spatial_candidates; `tried` are the place candidates).
  std::vector<KeyframeKey> spatialCandidates(const KeyframeKey& key, double stamp,
                                             const std::vector<KeyframeKey>& tried) const;
  /// After keyframe extensions: their BoW entries are renewed and every loop
  /// whose rig holds one is closed again; the new measurement replaces the old
  /// one (same id, PCM decides again) unless it has fewer inliers.
  void extendKeyframes(const std::vector<KeyframeKey>& extended, MergeStats* stats);
  void runPcm();
  bool updateAnchoring(const std::function<double(RobotId)>& credibility);
  /// Anchors a trajectory and tells the bookkeeper how (`by`).
  void anchorTrajectory(TrajectoryMap* t, const SE3& T_W_A, SessionAnchor by);
  /// Information of the bridge between two keyframes of one trajectory that
  /// no odometry edge joins (consecutive windows, or across trimmed ones).
  Mat6 bridgeInformation(const Keyframe& from, const Keyframe& to) const;

  std::shared_ptr<const Vocabulary> vocabulary_;
  MapManagerParams params_;
  Bookkeeper* bookkeeper_;
  std::mutex* bookkeeper_lock_ = nullptr;
  PlaceRecognizer recognizer_;
  LoopCloser closer_;
  LoopCloser sparse_closer_;  ///< closer_ with the sparse_pair_sigma_m gate
  OdometryChain chain_;
  PcmCache pcm_cache_;
  std::uint64_t pcm_chain_revision_ = 0;  ///< chain_.revision() the cache holds
  GlobalMap map_;
  TimingStats timings_;
  GraphDiagnostics graph_diag_;
  std::uint64_t next_loop_id_ = 0;
  int merges_since_optimize_ = 0;
  bool graph_dirty_ = false;
  std::set<std::uint64_t> accepted_;
  std::deque<LoopJob> deferred_;  ///< closures over the budget (closure_budget.h)
  int closure_budget_ = 0;        ///< this merge's budget (setClosureBudget())
  std::size_t deferred_dropped_ = 0;
  int loops_bridged_ = 0;  ///< of accepted_, by bridging tie groups (latest PCM run)
  /// Graph nodes changed since the last solve: new keyframes, ends of loops
  /// accepted / dropped / re-measured, keyframes of newly anchored robots.
  std::set<KeyframeKey> touched_;
  int incremental_since_full_ = 0;
  void noteSolve(const PoseGraph& graph, const PoseGraphResult& r, bool incremental, double ms);
  std::optional<TrajectoryId> world_traj_;
  CandidateHook candidate_hook_;
  LoopHook loop_hook_;
  AttemptHook attempt_hook_;
};

}  // namespace server
}  // namespace hermes
