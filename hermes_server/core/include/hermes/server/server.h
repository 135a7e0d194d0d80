// The ROS-free edge server pipeline (DESIGN.md §5): one door for frames
// (decode, dedup, bookkeeping via SubmapReceiver), a credibility-ordered queue
// of accepted submaps, and the MapManager that merges them.
//
// Durability (DESIGN.md §9, server.checkpoint_dir set; checkpoint_store.h):
// an accepted submap is written to the journal before onFrame() says to
// acknowledge it (a failed write: not acknowledged, the agent resends), and
// after merges (at most every checkpoint_period_s) the whole state is written
// as a checkpoint, which makes the journal entries it covers redundant. create()
// resumes from the newest readable checkpoint (a damaged or other-version one is
// refused with a reason and the previous one used; none usable is an error,
// never a silent empty start), then queues again what the journal holds beyond
// it. Agents resend what was never acknowledged; the restored bookkeeper drops
// what it had already accepted: nothing lost, nothing applied twice.
//
// Prior map (server.prior_map, an earlier mission's checkpoint directory): a
// server that has no checkpoint of its own yet starts on the newest usable
// checkpoint there (read only), its agents renamed "prior/<name>"
// (Bookkeeper::sealAsPrior): this mission's robots register anew and loops
// place them in the prior's world frame. The prior's keyframes stay in the pose
// graph with their odometry and loops (not frozen: a new loop may still move
// them as far as their own edges allow; the gauge stays the world's first
// keyframe). A prior that cannot be read is an error naming the files and why,
// or with server.prior_map_optional a problem in resumeReport() and an empty start.
//
// Threads (server_worker.h runs process() on a thread of its own): onFrame()
// may be called from one receiving thread while one other thread runs
// process(). They share the intake state - bookkeeper, credibility queue,
// pending submaps, per-robot quotas, receiver stats, journal, durability
// stats - guarded by one mutex (intake): onFrame() holds it throughout (decode,
// auth, admission, journal write, queueing); process() holds it only to take
// the next submap out of the queue, to mark it applied, while the map manager
// anchors agents (MapManager::setBookkeeperLock) and while a checkpoint copies
// the intake state (the map is encoded and the file written outside it). The
// merge itself (loops, PCM, pose graph) runs without it. The map manager,
// counters() and timings() belong to the thread running process(): read them
// there or while none runs. The intake accessors (bookkeeper(), credibility(),
// receiverStats(), heldLoad()) from a third thread need lockIntake() held.
// Without a second thread the mutex is never contended: results are the same.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "hermes/core/config.h"
#include "hermes/core/keyring.h"
#include "hermes/core/metrics.h"
#include "hermes/server/admission.h"
#include "hermes/server/bookkeeper.h"
#include "hermes/server/checkpoint_store.h"
#include "hermes/server/credibility.h"
#include "hermes/server/downlink.h"
#include "hermes/server/map_manager.h"
#include "hermes/server/submap_receiver.h"

namespace hermes {
namespace server {

struct ServerParams {
  BookkeeperParams bookkeeper;    ///< server.bookkeeper.*, server.relocalisation_timeout_s
  CredibilityParams credibility;  ///< server.csa, server.w_ts, ...
  MapManagerParams map;           ///< server.place_recognition.*, server.loop_closure.*, ...
  AuthParams auth;                ///< server.auth.*
  QueueParams queue;              ///< server.queue.*
  CheckpointParams checkpoint;    ///< server.checkpoint_dir, server.checkpoint_period_s, ...
  DownlinkParams downlink;        ///< server.downlink.* (used by the caller's Downlink)
  Status read(const Config& config, const std::string& prefix = "server.");
  Status validate() const;
  void write(ConfigWriter& out, const std::string& prefix = "server.") const;
};

struct ServerCounters {
  std::size_t merged = 0;
  std::size_t merge_errors = 0;
  std::size_t keyframes_extended = 0;  ///< stored keyframes keyframe extensions added keypoints to
  std::size_t extensions_unknown = 0;  ///< extensions naming a keyframe the map does not hold
  std::size_t loops_reverified = 0;    ///< loops closed again after extensions
  std::size_t loops_reverify_deferred = 0;  ///< of those, deferred by the closure budget first
  std::string last_error;
};

/// Checkpoints and restarts, accumulated over the server's whole life (kept in
/// the checkpoint).
struct DurabilityStats {
  std::size_t checkpoints = 0, checkpoint_errors = 0;
  std::size_t last_checkpoint_bytes = 0;
  std::size_t journal_errors = 0;    ///< accepted frames not acknowledged: journal write failed
  std::size_t resumes = 0;           ///< starts from a checkpoint and/or journal
  std::size_t journal_replayed = 0;  ///< submaps queued again from the journal on resume
  std::size_t refused_files = 0;     ///< checkpoint / journal files refused on resume
  std::string last_error;
};

/// What the last create() resumed from.
struct ResumeReport {
  bool resumed = false;              ///< a checkpoint or journal entries were loaded
  std::string checkpoint;            ///< file used (empty: none, journal only or fresh)
  std::vector<std::string> problems; ///< refused files, each with its reason
  double load_ms = 0;                ///< wall time of reading and restoring [ms]
  std::size_t journal_replayed = 0, journal_covered = 0;
  std::string prior_map;             ///< prior-map checkpoint the server started on (empty: none)
};

class Server {
 public:
  /// Loads the vocabulary (relative paths resolved against base_dir) and, with
  /// params.auth.enabled, the keyring: `keyring` when given, else the key
  /// directory params.auth.key_dir ("~/" expanded). With a checkpoint
  /// directory, resumes from it (see the top of this file).
  static Expected<std::unique_ptr<Server>> create(const ServerParams& params,
                                                  const std::string& base_dir,
                                                  std::optional<Keyring> keyring = std::nullopt);
  /// `keyring` is required exactly when params.auth.enabled (checked).
  Server(const ServerParams& params, std::shared_ptr<const Vocabulary> vocabulary,
         std::optional<Keyring> keyring = std::nullopt);
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  /// One received frame (claimed: routing header from the transport, may be null).
  ReceiveResult onFrame(const std::uint8_t* data, std::size_t size, const SubmapHeader* claimed,
                        double now);
  /// Pops up to max_submaps (< 0: all) in credibility order and merges them,
  /// then reports as new robots the later sessions no loop tied within
  /// server.relocalisation_timeout_s (Bookkeeper::checkRelocalisation). Returns
  /// how many were merged.
  int process(double now, int max_submaps = -1);

  /// Submaps accepted and not merged yet (any thread).
  std::size_t pending() const;
  /// Loop closures deferred by the merges' budget (server.map.closure_budget),
  /// verified by process() while no submap waits (the merging thread).
  std::size_t deferredClosures() const { return map_.deferredClosures(); }
  /// Full pose-graph solves due between merges (server.pose_graph.full_between_merges):
  /// process() runs one while no submap waits, unless the caller takes them over
  /// (the threaded worker solves on a thread of its own: fullSolveDue(),
  /// MapManager::prepareFullSolve(), FullSolve::run(), applyFullSolve()).
  void leaveFullSolvesToCaller(bool caller) { full_solves_external_ = caller; }
  bool fullSolveDue() const { return map_.fullSolveDue(); }
  /// The graph to solve now (merging thread); a failure is counted as a merge
  /// error (last_error) and the solve postponed, as is a failed applyFullSolve().
  Expected<FullSolve> prepareFullSolve();
  void applyFullSolve(const FullSolve& job);
  /// Holds the intake state still for a reader on another thread than the
  /// receiving one (briefly: onFrame() waits meanwhile). Never while calling
  /// onFrame(), process() or checkpoint() on the same thread.
  std::unique_lock<std::mutex> lockIntake() const { return std::unique_lock<std::mutex>(intake_mu_); }
  const Bookkeeper& bookkeeper() const { return bookkeeper_; }
  const CredibilityAssessor& credibility() const { return queue_; }
  const MapManager& mapManager() const { return map_; }
  MapManager& mapManager() { return map_; }
  const GlobalMap& map() const { return map_.map(); }
  const ReceiverStats& receiverStats() const { return receiver_.stats(); }
  /// What the server holds for a robot awaiting merge (nullptr: nothing ever).
  const HeldLoad* heldLoad(RobotId robot) const { return quotas_.load(robot); }
  const ServerCounters& counters() const { return counters_; }
  /// Map-manager stages plus "submap" (whole merge incl. queue handling) and
  /// "checkpoint" (state encoded and written) [ms].
  TimingStats timings() const;
  /// One merge's wall time per stage (MergeStats::stage_ms), kept for the
  /// slowest merges: what a long p95 of "submap" is made of.
  struct MergeBreakdown {
    double now = 0;  ///< process() time [s]
    RobotId robot = 0;
    std::uint64_t seq = 0;
    int keyframes = 0, loops_attempted = 0;
    std::map<std::string, double> stage_ms;
  };
  /// The kSlowestMerges slowest merges so far, slowest first.
  const std::vector<MergeBreakdown>& slowestMerges() const { return slowest_; }
  static constexpr std::size_t kSlowestMerges = 5;
  const ServerParams& params() const { return params_; }

  /// Writes a checkpoint now (clean shutdown; process() does it after merges).
  /// Without a checkpoint directory: Ok, nothing written.
  Status checkpoint(double now);
  const DurabilityStats& durability() const { return durability_; }
  const ResumeReport& resumeReport() const { return resume_; }
  /// The whole state as a checkpoint body, and back (into a server that has
  /// seen nothing; all or nothing: on error the server must be discarded).
  std::vector<std::uint8_t> saveState() const;
  Status loadState(const std::vector<std::uint8_t>& body);

 private:
  void solveFullInline();
  void fullSolveFailed(const std::string& error);
  bool full_solves_external_ = false;
  struct Pending {
    ReceivedSubmap submap;
    std::vector<std::uint8_t> frame;  ///< as received (for checkpoints; empty if not via onFrame)
  };
  /// A new server on params.checkpoint.prior_map (empty without one); its
  /// problems go to `report`.
  static Expected<std::unique_ptr<Server>> startOnPrior(const ServerParams& params,
                                                        std::shared_ptr<const Vocabulary> vocabulary,
                                                        const std::optional<Keyring>& keyring,
                                                        ResumeReport* report);
  /// The loaded state becomes the prior (see the top of this file).
  void sealPrior();
  /// create() with a checkpoint directory.
  static Expected<std::unique_ptr<Server>> resume(const ServerParams& params,
                                                  std::shared_ptr<const Vocabulary> vocabulary,
                                                  const std::optional<Keyring>& keyring);
  ReceiveResult receiveJournaled(const std::uint8_t* data, std::size_t size,
                                 const SubmapHeader* claimed, double now);
  /// Under the intake lock: false when the queue is empty; else true with the
  /// next submap in credibility order taken out of it (empty if it was lost).
  bool takeNext(double now, std::optional<ReceivedSubmap>* next);
  /// The checkpoint body: the intake state copied under the intake lock (with
  /// `covers`, the journal entries it covers are moved there at the same
  /// moment), the map encoded outside it.
  std::vector<std::uint8_t> encodeState(std::vector<SubmapHeader>* covers);
  /// The intake state's parts of the body, before and after the map.
  void saveIntake(ByteWriter* head, ByteWriter* tail) const;
  /// The closure budget of a merge of `robot` at `now` (map.closure_budget, or
  /// the swarm's share, map.closure_budget_swarm, among the robots active).
  int closureBudget(RobotId robot, double now) const;
  /// Keeps m among slowest_ when it is one of the kSlowestMerges slowest.
  void noteSlowMerge(MergeBreakdown m);
  /// head + the map (read by the merging thread, no lock) + tail.
  std::vector<std::uint8_t> withMap(ByteWriter head, const ByteWriter& tail) const;

  ServerParams params_;
  std::optional<Keyring> keyring_;
  RobotQuotas quotas_;
  Bookkeeper bookkeeper_;
  CredibilityAssessor queue_;
  MapManager map_;
  SubmapReceiver receiver_;
  std::map<std::uint64_t, Pending> stored_;
  std::uint64_t next_handle_ = 0;
  ServerCounters counters_;
  TimingStats timings_;
  std::vector<MergeBreakdown> slowest_;
  std::map<RobotId, double> last_merge_s_;  ///< per robot, when its last submap was merged (closureBudget())
  std::optional<CheckpointStore> store_;
  std::vector<SubmapHeader> journaled_;  ///< journal entries no checkpoint covers yet
  std::deque<std::vector<SubmapHeader>> covered_;  ///< entries first covered by each newer checkpoint
  const std::uint8_t* receiving_ = nullptr;  ///< frame inside onFrame (for the sink)
  std::size_t receiving_size_ = 0;
  double last_checkpoint_ = -1e300;
  DurabilityStats durability_;
  ResumeReport resume_;
  mutable std::mutex intake_mu_;  ///< the intake state (top of this file)
};

}  // namespace server
}  // namespace hermes
