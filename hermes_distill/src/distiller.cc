#include "hermes/distill/distiller.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>
#include <unordered_set>

#include "hermes/core/stopwatch.h"
#include "hermes/distill/keyframe_trimming.h"
#include "hermes/distill/selectors.h"

namespace hermes {
namespace distill {
namespace {

using Clock = std::chrono::steady_clock;
// A selection using this much of its landmark byte budget counts as cut by it.
constexpr double kBudgetBoundFill = 0.95;
// Wire bytes of one keypoint without a landmark: u, v, depth, octave, descriptor
// (zstd takes a little off; the encoded size decides where there is one).
constexpr double kKeypointBytes = 4 + 4 + 4 + 1 + 32;
// Keypoints without a landmark use at most half of S with the rest of the
// window: the other half is slack for losses and resends.
constexpr double kMaxFill = 0.5;
}  // namespace

bool usesTightSelector(const DistillParams& params) {
  return params.coordinator && params.strategy != "none" && params.tight_strategy != "same" &&
         params.tight_strategy != params.strategy;
}

namespace {
// The selector for where the link binds; null when the distiller needs none.
Expected<std::unique_ptr<LandmarkSelector>> makeTightSelector(const DistillParams& params) {
  if (!usesTightSelector(params)) return Expected<std::unique_ptr<LandmarkSelector>>(nullptr);
  auto tight = makeLandmarkSelector(params.tight_strategy, params);
  if (!tight) return Error{"distill.tight_strategy: " + tight.error()};
  return tight;
}
}  // namespace

bool inTrouble(const Submap& window, const TrackingHealth& health, const DistillParams& params) {
  if (!params.trouble_aware) return false;
  if (health.lost > 0 || health.weak >= params.trouble_weak_frames) return true;
  return std::any_of(window.keyframes.begin(), window.keyframes.end(),
                     [&](const Keyframe& kf) { return kf.lost_before && kf.stamp >= window.header.t_start; });
}

Distiller::Distiller(const DistillParams& params, EncodedSizeFn size_fn)
    : params_(params), size_fn_(std::move(size_fn)), model_(params) {
  auto sel = makeLandmarkSelector(params.strategy, params);
  HERMES_CHECK(sel.ok(), sel.error());
  selector_ = std::move(sel.value());
  auto tight = makeTightSelector(params);
  HERMES_CHECK(tight.ok(), tight.error());
  tight_selector_ = std::move(tight.value());
}

Distiller::~Distiller() = default;

Expected<std::unique_ptr<Distiller>> Distiller::create(const DistillParams& params,
                                                       EncodedSizeFn size_fn) {
  Status v = params.validate();
  if (!v) return Error{v.error()};
  auto sel = makeLandmarkSelector(params.strategy, params);
  if (!sel) return Error{sel.error()};
  if (auto tight = makeTightSelector(params); !tight) return Error{tight.error()};
  return Expected<std::unique_ptr<Distiller>>(std::make_unique<Distiller>(params, std::move(size_fn)));
}

DistillResult Distiller::distill(const Submap& window, const MotionHint& hint,
                                 const CoordinatorInput& input) {
  const auto t_start = Clock::now();
  DistillResult res;
  DistillReport& rep = res.report;
  rep.strategy = params_.strategy;
  rep.n_kf_in = static_cast<int>(window.keyframes.size());
  rep.n_lm_in = static_cast<int>(window.landmarks.size());
  std::string problem = window.validate();
  for (const Keyframe& kf : window.keyframes) {
    if (!problem.empty()) break;
    if (!kf.T_A_C.translation().allFinite() || !kf.T_A_C.quat().coeffs().allFinite())
      problem = "keyframe " + std::to_string(kf.id) + " has a non-finite pose";
  }
  if (hint.valid && (!hint.T_A_C.translation().allFinite() ||
                     !hint.T_Cprev_Ccurr.translation().allFinite() ||
                     !hint.T_Cprev_Ccurr.quat().coeffs().allFinite() || !(hint.dt_s > 0)))
    problem = problem.empty() ? "motion hint is not finite or has dt <= 0" : problem;
  if (!problem.empty()) {
    rep.ok = false;
    rep.error = "distill: malformed window (seq " + std::to_string(window.header.seq) + "): " + problem;
    return res;
  }
  const bool budgeted = params_.coordinator && params_.strategy != "none";
  // A window in trouble keeps more keyframes and plans with more of the link
  // (DistillParams::trouble_*); raw streaming keeps everything anyway.
  rep.trouble = params_.strategy != "none" && inTrouble(window, hint.health, params_);
  DistillParams window_params = params_;
  // A window whose view changes fast (it moves far, or its tracker made many
  // keyframes) keeps more keyframes, from the budget's surplus only (planDistillation).
  const int surplus_cap = budgeted ? surplusKeyframeCap(window, params_) : 0;
  CoordinatorInput link = input;
  if (rep.trouble) {
    window_params.max_keyframes = params_.trouble_max_keyframes;
    link.bandwidth_Bps *= params_.trouble_budget_gain;  // the backlog still counts in full
  }
  // Not in the global map yet: more keyframes (places for a loop), same budget.
  rep.unplaced = params_.strategy != "none" && params_.unplaced_aware && !input.placed;
  if (rep.unplaced) window_params.max_keyframes = params_.trouble_max_keyframes;
  const DistillParams& prm = window_params;
  rep.budget_bytes = prm.coordinator ? budgetBytes(prm, link)
                                     : std::numeric_limits<double>::infinity();
  auto measure = [&](const Submap& s) {
    const auto t0 = Clock::now();
    const double pred = model_.predict(static_cast<double>(s.keyframes.size()),
                                       static_cast<double>(s.observationCount()),
                                       static_cast<double>(s.landmarks.size()));
    rep.bytes_predicted = pred;
    if (size_fn_) {
      rep.bytes_actual = size_fn_(s);
      model_.addSample(static_cast<double>(s.keyframes.size()),
                       static_cast<double>(s.observationCount()),
                       static_cast<double>(s.landmarks.size()),
                       static_cast<double>(rep.bytes_actual));
    }
    rep.time_encode_ms += msSince(t0);
    return size_fn_ ? static_cast<double>(rep.bytes_actual) : pred;
  };
  auto finish = [&](Submap s) {
    rep.n_kf = static_cast<int>(s.keyframes.size());
    rep.n_lm = static_cast<int>(s.landmarks.size());
    rep.observations = s.observationCount();
    res.submap = std::move(s);
    rep.time_total_ms = msSince(t_start);
    return res;
  };

  if (window.keyframes.empty()) {
    rep.selection_status = "empty";
    return finish(window);
  }

  // Raw streaming.
  if (params_.strategy == "none") {
    std::vector<int> all(window.keyframes.size());
    std::iota(all.begin(), all.end(), 0);
    Submap raw = applyKeyframeTrim(window, all);
    raw.landmarks = window.landmarks;  // even landmarks without observations
    raw.keyframes = window.keyframes;
    rep.selection_status = toString(SolveStatus::kUnconstrained);
    rep.trim_status = "none";
    rep.rounds = 1;
    const double bytes = measure(raw);
    rep.over_budget = bytes > rep.budget_bytes;
    return finish(std::move(raw));
  }

  // Plan (N_KF, K).
  int n_kf = std::min<int>(prm.max_keyframes, static_cast<int>(window.keyframes.size()));
  int k = prm.fixed_k;
  if (budgeted) {
    const CoordinatorPlan plan = planDistillation(window, rep.budget_bytes, model_, kept_, prm, surplus_cap);
    if (plan.defer) {
      rep.deferred = true;
      rep.defer_reason = plan.reason;
      rep.time_total_ms = msSince(t_start);
      return res;
    }
    n_kf = plan.n_kf;
    k = plan.k;
    rep.bytes_planned = plan.predicted_bytes;
  }

  auto t0 = Clock::now();
  const TrimResult trim = trimKeyframes(window, n_kf, prm);
  const Submap trimmed = applyKeyframeTrim(window, trim.kept);
  rep.trim_status = toString(trim.status);
  rep.time_trim_ms = msSince(t0);
  if (budgeted && !trimmed.keyframes.empty()) {  // K for the keyframes really kept
    const CoordinatorPlan plan = chooseK(trimmed, rep.budget_bytes, model_, kept_, prm);
    k = plan.k;
    rep.bytes_planned = plan.predicted_bytes;
  }

  t0 = Clock::now();
  const LandmarkScores scores = computeScores(trimmed, hint, input.loop_closures, prm);
  rep.alpha = scores.weights.alpha;
  rep.beta = scores.weights.beta;
  rep.time_scores_ms = msSince(t0);

  const double n_kept = static_cast<double>(trimmed.keyframes.size());
  double s_lm = budgeted ? rep.budget_bytes - model_.c0() - model_.cKf() * n_kept
                         : std::numeric_limits<double>::infinity();
  Submap out;
  bool have_fit = false;
  bool floor_hit = false;
  std::vector<int> last_selected;
  double last_bytes = 0;
  Submap fit;
  std::vector<int> fit_selected;
  DistillReport fit_report;
  // The landmarks are all a measured link gets from this window: it has a backlog,
  // or the plan fills more than the share loop keypoints may top up (kMaxFill).
  const bool link_binds = !input.link_unmeasured &&
                          (!input.link_keeps_up || rep.bytes_planned > kMaxFill * rep.budget_bytes);
  for (int round = 1; round <= prm.max_rounds; ++round) {
    rep.rounds = round;
    rep.k = k;
    t0 = Clock::now();
    SelectionProblem prob =
        buildSelectionProblem(trimmed, scores, k, s_lm, model_.cLm(), model_.cObs(), prm);
    // All rounds together get the MILP time limit (each at least 10 ms).
    prob.time_limit_s = std::max(0.01, prm.milp_time_limit_s - rep.time_select_ms * 1e-3);
    // The previous round's selection is a feasible start when K grew (same
    // landmark budget); after a shrink it no longer fits and the MILP ignores it.
    prob.warm_start = last_selected;
    // Where the link binds the tight strategy selects (DistillParams::tight_strategy).
    const bool tight = tight_selector_ && budgeted && (k < prm.k_max || link_binds);
    const SelectionResult sel = (tight ? tight_selector_ : selector_)->select(prob);
    rep.time_select_ms += msSince(t0);
    rep.selection_status = toString(sel.status);
    rep.objective = sel.objective;
    rep.greedy_objective = sel.greedy_objective;
    rep.support_slack = sel.support_slack;
    rep.grid_slack = sel.grid_slack;
    out = keepLandmarks(trimmed, sel.selected, 0);
    last_selected = sel.selected;
    const double bytes = measure(out);
    last_bytes = bytes;
    if (!budgeted) return finish(std::move(out));
    kept_.addSample(trimmed, static_cast<int>(trimmed.keyframes.size()), k,
                    static_cast<double>(out.landmarks.size()),
                    static_cast<double>(out.observationCount()),
                    sel.support_slack > 0.5 || sel.bytes >= kBudgetBoundFill * prob.budget);
    if (bytes <= rep.budget_bytes) {
      have_fit = true;
      fit = std::move(out);
      fit_selected = sel.selected;
      fit_report = rep;
      // Fits. If the byte model was pessimistic and K can grow, try a larger K.
      if (bytes >= prm.fill_accept * rep.budget_bytes || k >= prm.k_max) break;
      k = std::min(prm.k_max,
                   static_cast<int>(std::ceil(k * std::min(2.0, rep.budget_bytes / bytes))));
      continue;
    }
    if (have_fit) break;  // a grown K overshot: keep the last fitting selection
    // Too large: shrink K and the landmark budget by the overshoot ratio.
    const double ratio = rep.budget_bytes / bytes;
    const int next_k = static_cast<int>(std::floor(k * ratio * 0.95));
    // The margin (1 % of S) keeps a budget-bound selection from overshooting by
    // a few bytes again when the refitted byte model barely moves.
    s_lm = s_lm - (bytes - rep.budget_bytes) * 1.05 - 0.01 * rep.budget_bytes;
    if (next_k < prm.k_min || s_lm < 0) {
      floor_hit = true;  // the floor is reached: defer rather than degrade further
      break;
    }
    k = next_k;
  }
  if (have_fit) {
    const int rounds = rep.rounds;
    const double t_sel = rep.time_select_ms, t_enc = rep.time_encode_ms;
    rep = fit_report;
    rep.rounds = rounds;
    rep.time_select_ms = t_sel;
    rep.time_encode_ms = t_enc;
    if (rep.k >= prm.k_max && input.link_keeps_up)
      addLoopKeypoints(trimmed, fit_selected, &fit, &rep);
    else if (rep.k >= prm.k_max && input.link_unmeasured && prm.loop_keypoints > 0)
      res.held_back = heldBackKeypoints(trimmed, fit_selected);
    return finish(std::move(fit));
  }
  // Repair: the rounds missed (byte model off, or CBC cut short). Drop the least
  // valuable kept landmarks, sized by the real bytes per modelled byte, until the
  // encoded size fits; a few encodings at most.
  for (int attempt = 0; attempt < 3 && !floor_hit && !last_selected.empty(); ++attempt) {
    const double predicted = model_.predict(static_cast<double>(out.keyframes.size()),
                                            static_cast<double>(out.observationCount()),
                                            static_cast<double>(out.landmarks.size()));
    const double real_per_model = last_bytes / std::max(predicted, 1.0);
    std::vector<int> order = last_selected;
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
      return scores.value[static_cast<std::size_t>(a)] < scores.value[static_cast<std::size_t>(b)];
    });
    const double need = (last_bytes - rep.budget_bytes) * 1.05;
    double saved = 0;
    std::size_t drop = 0;
    while (drop < order.size() && saved < need) {
      const Landmark& lm = trimmed.landmarks[static_cast<std::size_t>(order[drop])];
      saved += real_per_model *
               (model_.cLm() + model_.cObs() * static_cast<double>(lm.observations.size()));
      ++drop;
    }
    if (drop >= order.size()) break;
    last_selected.assign(order.begin() + static_cast<std::ptrdiff_t>(drop), order.end());
    std::sort(last_selected.begin(), last_selected.end());
    out = keepLandmarks(trimmed, last_selected, 0);
    last_bytes = measure(out);
    if (last_bytes <= rep.budget_bytes) {
      rep.selection_status += "+repaired";
      return finish(std::move(out));
    }
  }
  rep.over_budget = true;
  rep.deferred = true;
  std::ostringstream why;
  why << "encoded size " << (size_fn_ ? static_cast<double>(rep.bytes_actual) : rep.bytes_predicted)
      << " B still exceeds the budget " << rep.budget_bytes << " B after " << rep.rounds
      << " round(s) at the floor K >= " << prm.k_min;
  rep.defer_reason = why.str();
  rep.n_kf = static_cast<int>(out.keyframes.size());
  rep.n_lm = static_cast<int>(out.landmarks.size());
  rep.observations = out.observationCount();
  rep.time_total_ms = msSince(t_start);
  return res;
}

namespace {

std::size_t keypointCount(const Submap& s) {
  std::size_t n = 0;
  for (const Keyframe& kf : s.keyframes) n += kf.keypoints.size();
  return n;
}
}  // namespace

int Distiller::spendSpareOnKeypoints(std::size_t n_kf,
                                     const std::function<Submap(std::size_t)>& build, Submap* fit,
                                     DistillReport* rep) const {
  const double fit_bytes = size_fn_ ? static_cast<double>(rep->bytes_actual) : rep->bytes_predicted;
  const double limit = kMaxFill * rep->budget_bytes;
  const double spare = limit - fit_bytes;
  const double kfs = static_cast<double>(std::max<std::size_t>(1, n_kf));
  double n = std::min<double>(params_.loop_keypoints, std::floor(spare / (kfs * kKeypointBytes)));
  const std::size_t base = keypointCount(*fit);
  // Not through `measure`: the byte model describes landmarks and observations.
  for (int attempt = 0; attempt < 2 && n >= 1; ++attempt, n = std::floor(n / 2)) {
    Submap more = build(static_cast<std::size_t>(n));
    const auto t0 = Clock::now();
    const double extra = static_cast<double>(keypointCount(more) - base);
    const double bytes = size_fn_ ? static_cast<double>(size_fn_(more))
                                  : fit_bytes + kKeypointBytes * extra;
    rep->time_encode_ms += msSince(t0);
    if (bytes > limit) continue;
    *fit = std::move(more);
    if (size_fn_) rep->bytes_actual = static_cast<std::size_t>(bytes);
    else rep->bytes_predicted = bytes;
    return static_cast<int>(n);
  }
  return 0;
}

void Distiller::addLoopKeypoints(const Submap& trimmed, const std::vector<int>& selected,
                                 Submap* fit, DistillReport* rep) const {
  rep->loop_keypoints = spendSpareOnKeypoints(
      fit->keyframes.size(),
      [&](std::size_t n) { return keepLandmarks(trimmed, selected, n); }, fit, rep);
}

void Distiller::extendWithHeldBack(const Submap& held, DistillResult* r) const {
  DistillReport& rep = r->report;
  if (!rep.ok || rep.deferred || params_.loop_keypoints <= 0 || held.keyframes.empty() ||
      r->submap.keyframes.empty())
    return;
  const double window_start = r->submap.header.t_start;
  std::unordered_set<KeyframeId> in_window;
  for (const Keyframe& kf : r->submap.keyframes) in_window.insert(kf.id);
  Submap source;  // only keyframes before this window can extend
  for (const Keyframe& kf : held.keyframes)
    if (kf.stamp < window_start && !in_window.count(kf.id)) source.keyframes.push_back(kf);
  if (source.keyframes.empty()) return;
  const std::size_t before = r->submap.keyframes.size();
  rep.extension_keypoints = spendSpareOnKeypoints(
      source.keyframes.size(),
      [&](std::size_t n) {
        Submap more = r->submap;  // unchanged until a candidate is taken
        std::vector<Keyframe> ext = keyframeExtensions(source, n);
        more.keyframes.insert(more.keyframes.begin(), ext.begin(), ext.end());
        return more;
      },
      &r->submap, &rep);
  if (rep.extension_keypoints > 0)
    rep.extension_keyframes = static_cast<int>(r->submap.keyframes.size() - before);
}

}  // namespace distill
}  // namespace hermes
