#include "hermes/agent/tracker.h"

#include <algorithm>
#include <future>
#include <set>

#include <opencv2/imgproc.hpp>

namespace hermes {

const char* toString(TrackingStatus s) {
  switch (s) {
    case TrackingStatus::kNotInitialised: return "not_initialised";
    case TrackingStatus::kOk: return "ok";
    case TrackingStatus::kLost: return "lost";
  }
  return "?";
}

Status TrackerParams::read(const Config& c) {
  for (Status s : {orb.read(c, "orb"), stereo.read(c, "stereo"), rgbd.read(c, "rgbd"),
                   matching.read(c, "matching"), pose.read(c, "pose"),
                   keyframe.read(c, "keyframe"), mapping.read(c), window.read(c)})
    if (!s) return s;
  for (auto [key, ptr] : {std::pair<const char*, int*>{"init_min_points", &init_min_points},
                          {"min_tracked", &min_tracked},
                          {"weak_tracked", &weak_tracked},
                          {"local_map_keyframes", &local_map_keyframes},
                          {"trusted_observations", &trusted_observations},
                          {"relocalise_keyframes", &relocalise_keyframes}}) {
    Status s = c.get(std::string("tracker.") + key, ptr);
    if (!s) return s;
  }
  Status s = c.get("tracker.relocalise_radius_px", &relocalise_radius_px);
  if (!s) return s;
  s = c.get("tracker.reinit_after_s", &reinit_after_s);
  if (!s) return s;
  s = c.get("tracker.trusted_disagreement_px", &trusted_disagreement_px);
  if (!s) return s;
  return validate();
}

void TrackerParams::write(ConfigWriter* w) const {
  orb.write(w, "orb");
  stereo.write(w, "stereo");
  rgbd.write(w, "rgbd");
  matching.write(w, "matching");
  pose.write(w, "pose");
  keyframe.write(w, "keyframe");
  mapping.write(w);
  window.write(w);
  w->set("tracker.init_min_points", init_min_points);
  w->set("tracker.min_tracked", min_tracked);
  w->set("tracker.weak_tracked", weak_tracked);
  w->set("tracker.local_map_keyframes", local_map_keyframes);
  w->set("tracker.trusted_observations", trusted_observations);
  w->set("tracker.trusted_disagreement_px", trusted_disagreement_px);
  w->set("tracker.relocalise_radius_px", relocalise_radius_px);
  w->set("tracker.relocalise_keyframes", relocalise_keyframes);
  w->set("tracker.reinit_after_s", reinit_after_s);
}

Status TrackerParams::validate() const {
  for (Status s : {orb.validate(), stereo.validate(), rgbd.validate(), matching.validate(),
                   pose.validate(), keyframe.validate(), mapping.validate(), window.validate()})
    if (!s) return s;
  if (init_min_points < 4) return Error{"tracker.init_min_points must be >= 4"};
  if (min_tracked < pose.min_inliers)
    return Error{"tracker.min_tracked must be >= pose.min_inliers"};
  if (weak_tracked < 0) return Error{"tracker.weak_tracked must be >= 0 (0 = never weak)"};
  if (local_map_keyframes < 1) return Error{"tracker.local_map_keyframes must be >= 1"};
  if (trusted_observations < 0)
    return Error{"tracker.trusted_observations must be >= 0 (0 = every landmark)"};
  if (!(trusted_disagreement_px >= 0))
    return Error{"tracker.trusted_disagreement_px must be >= 0 (0 = trusted only)"};
  if (!(relocalise_radius_px > 0)) return Error{"tracker.relocalise_radius_px must be > 0"};
  if (relocalise_keyframes < 0) return Error{"tracker.relocalise_keyframes must be >= 0"};
  if (!(reinit_after_s >= 0)) return Error{"tracker.reinit_after_s must be >= 0 (0 = never)"};
  return Status::Ok();
}

Tracker::Tracker(const TrackerParams& params, const PinholeIntrinsics& K, double baseline)
    : params_(params), K_(K), baseline_(baseline), extractor_(params.orb),
      policy_(params.keyframe), mapping_(params.mapping, K, baseline) {
  Status s = params_.validate();
  HERMES_CHECK(s.ok(), s.error());
  HERMES_CHECK(K.fx > 0 && K.fy > 0 && K.width > 0 && K.height > 0, "tracker: bad intrinsics");
}

Tracker::~Tracker() = default;

void Tracker::setParallelMapping(bool parallel, std::function<void()> before_solve) {
  HERMES_CHECK(keyframes_.empty(), "tracker: set the mapping mode before the first frame");
  mapping_.setParallel(parallel, std::move(before_solve));
}

std::size_t Tracker::mappedKeyframes() const { return mapping_.mappedKeyframes(keyframes_.size()); }

void Tracker::pollMapping() {
  const std::optional<SE3> correction = mapping_.poll({&keyframes_, &landmarks_});
  if (!correction) return;
  // The motion model follows the newest adjusted keyframe, like the keyframes
  // and landmarks created after the cut (LocalMapper::applyBa).
  T_C_W_last_ = T_C_W_last_ * correction->inverse();
  T_C_W_prev_ = T_C_W_prev_ * correction->inverse();
}

void Tracker::finishMapping() {
  while (mapping_.busy()) {
    mapping_.waitIdle();
    pollMapping();
  }
}

Status Tracker::computeFeatures(const CameraFrame& f, FeatureSet* out) const {
  const cv::Size size(K_.width, K_.height);
  if (f.left.empty() || f.left.type() != CV_8UC1 || f.left.size() != size)
    return Error{"tracker: frame at t=" + std::to_string(f.stamp) +
                 ": left image must be 8-bit grey " + std::to_string(K_.width) + "x" +
                 std::to_string(K_.height)};
  const bool stereo = !f.right.empty(), rgbd = !f.depth.empty();
  if (stereo == rgbd)
    return Error{"tracker: frame at t=" + std::to_string(f.stamp) +
                 " needs exactly one of a right image or a depth image"};
  if (stereo) {
    if (f.right.type() != CV_8UC1 || f.right.size() != size)
      return Error{"tracker: frame at t=" + std::to_string(f.stamp) +
                   ": right image must match the left one"};
    if (!(baseline_ > 0)) return Error{"tracker: stereo frame but baseline <= 0"};
  }
  // The two images are independent: the right one is extracted on a second
  // thread while this one does the left (same results, about half the wait).
  std::future<Expected<FeatureSet>> right_job;
  if (stereo)
    right_job = std::async(std::launch::async, [this, &f] { return extractor_.extract(f.right); });
  auto left = extractor_.extract(f.left);
  if (stereo) {
    auto right = right_job.get();
    if (!left.ok()) return Error{left.error()};
    if (!right.ok()) return Error{right.error()};
    *out = std::move(left.value());
    auto st = matchStereo(out, *right, K_, baseline_, params_.stereo);
    if (!st.ok()) return Error{st.error()};
  } else {
    if (!left.ok()) return Error{left.error()};
    *out = std::move(left.value());
    auto n = assignDepthFromImage(f.depth, params_.rgbd, out);
    if (!n.ok()) return Error{n.error()};
  }
  return Status::Ok();
}

void Tracker::insertKeyframe(double stamp, const SE3& T_W_C, const FeatureSet& fs,
                             const std::vector<int>& keypoint_landmark) {
  Keyframe kf;
  kf.id = keyframes_.size();
  kf.stamp = stamp;
  kf.T_A_C = T_W_C;
  kf.keypoints = fs.keypoints;
  kf.descriptors = fs.descriptors;
  kf.keypoint_landmark.assign(fs.size(), kInvalidId);
  int associated = 0;
  for (std::size_t i = 0; i < fs.size(); ++i) {
    const Keypoint& k = fs.keypoints[i];
    LandmarkId id = kInvalidId;
    if (keypoint_landmark[i] >= 0) {
      id = LandmarkId(keypoint_landmark[i]);
    } else if (k.depth > 0) {
      Landmark l;
      l.id = landmarks_.size();
      const Vec3 p_C((k.u - K_.cx) / K_.fx * k.depth, (k.v - K_.cy) / K_.fy * k.depth, k.depth);
      l.p_A = T_W_C * p_C;
      l.descriptor = fs.descriptors[i];
      landmarks_.push_back(l);
      landmark_angle_.push_back(fs.angles[i]);
      landmark_origin_.push_back(kf.id);
      mapping_.mapper().noteCreated(l.id, kf.id);
      id = l.id;
    }
    if (id == kInvalidId) continue;
    landmarks_[id].observations.push_back({kf.id, std::uint32_t(i)});
    kf.keypoint_landmark[i] = id;
    ++associated;
  }
  (void)associated;
  reference_tracked_ = 0;  // set by the next tracked frame
  keyframes_.push_back(std::move(kf));
  lost_before_.push_back(lost_since_keyframe_ ? 1 : 0);
  lost_since_keyframe_ = false;
}

std::vector<std::size_t> Tracker::localMap(int keyframes) const {
  std::set<std::size_t> ids;
  const std::size_t first =
      keyframes_.size() > std::size_t(keyframes) ? keyframes_.size() - keyframes : 0;
  for (std::size_t k = first; k < keyframes_.size(); ++k)
    for (LandmarkId id : keyframes_[k].keypoint_landmark)
      if (id != kInvalidId && !mapping_.mapper().isBad(id)) ids.insert(id);
  return {ids.begin(), ids.end()};
}

std::vector<bool> Tracker::trustedLandmarks(const std::vector<int>& ids) const {
  std::vector<bool> trusted(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i)
    trusted[i] = int(landmarks_[ids[i]].observations.size()) >= params_.trusted_observations;
  return trusted;
}

Expected<PoseEstimate> Tracker::refineFromPrior(const Correspondences& c,
                                                const std::vector<int>& ids,
                                                const SE3& T_C_W_pred) const {
  if (params_.trusted_observations <= 0) return refinePose(c, K_, T_C_W_pred, params_.pose);
  const std::vector<bool> trusted = trustedLandmarks(ids);
  if (std::count(trusted.begin(), trusted.end(), true) < params_.min_tracked)
    return refinePose(c, K_, T_C_W_pred, params_.pose);
  Expected<PoseEstimate> e = refinePose(c, K_, T_C_W_pred, params_.pose, nullptr, &trusted);
  if (!e.ok() || params_.trusted_disagreement_px <= 0) return e;
  Expected<PoseEstimate> all = refinePose(c, K_, T_C_W_pred, params_.pose);
  if (all.ok() && projectionShift(c, K_, all->T_C_W, e->T_C_W) < params_.trusted_disagreement_px)
    return all;
  return e;
}

void Tracker::startNewMap(const SE3& T_W_C) {
  finishMapping();  // nothing of the old map is in flight
  keyframes_.clear();
  landmarks_.clear();
  landmark_angle_.clear();
  landmark_origin_.clear();
  lost_before_.clear();
  lost_since_keyframe_ = false;
  mapping_.reset();
  policy_.reset();
  status_ = TrackingStatus::kNotInitialised;
  have_velocity_ = false;
  reference_tracked_ = 0;
  T_W_C_init_ = T_W_C;
  health_ = {};
}

bool Tracker::initialise(const CameraFrame& frame, FeatureSet& fs, TrackResult* r) {
  int with_depth = 0;
  for (const auto& k : fs.keypoints) with_depth += k.depth > 0;
  if (with_depth < params_.init_min_points) return false;
  insertKeyframe(frame.stamp, T_W_C_init_, fs, std::vector<int>(fs.size(), -1));
  last_stamp_ = frame.stamp;
  status_ = TrackingStatus::kOk;
  T_C_W_last_ = T_W_C_init_.inverse();
  have_velocity_ = false;
  policy_.reset();
  r->status = status_;
  r->T_W_C = T_W_C_init_;
  r->new_keyframe = true;
  r->tracked = with_depth;
  return true;
}

Expected<TrackResult> Tracker::feed(const CameraFrame& frame) {
  FeatureSet fs;
  Status s = computeFeatures(frame, &fs);
  if (!s) return Error{s.error()};
  pollMapping();  // parallel mapping: a finished BA enters the map here
  TrackResult r;
  if (status_ == TrackingStatus::kNotInitialised) {
    if (initialise(frame, fs, &r)) mapping_.startMap(keyframes_.size());
    return r;
  }

  const bool was_ok = status_ == TrackingStatus::kOk;
  const SE3 T_C_W_pred = was_ok && have_velocity_
                             ? (T_C_W_last_ * T_C_W_prev_.inverse()) * T_C_W_last_
                             : T_C_W_last_;
  auto local = localMap(params_.local_map_keyframes);
  auto viewsOf = [&](const std::vector<std::size_t>& ids) {
    std::vector<LandmarkView> v(ids.size());
    for (std::size_t i = 0; i < ids.size(); ++i) {
      v[i].p_W = landmarks_[ids[i]].p_A;
      v[i].descriptor = landmarks_[ids[i]].descriptor;
      v[i].angle = landmark_angle_[ids[i]];
    }
    return v;
  };
  std::vector<LandmarkView> views = viewsOf(local);
  KeypointGrid grid(fs.keypoints, K_.width, K_.height);
  ProjectionMatchParams mp = params_.matching;
  if (!was_ok) mp.radius_px = params_.relocalise_radius_px;
  auto match = matchByProjection(views, T_C_W_pred, K_, fs, grid, mp);
  auto count = [](const std::vector<int>& m) {
    return int(std::count_if(m.begin(), m.end(), [](int j) { return j >= 0; }));
  };
  if (count(match) < params_.min_tracked && was_ok) {  // fast motion: widen the search
    mp.radius_px *= 2;
    match = matchByProjection(views, T_C_W_pred, K_, fs, grid, mp);
  }
  r.matched = count(match);

  Correspondences c;
  std::vector<int> corr_landmark, corr_keypoint;
  auto solve = [&](bool refine_first) {
    c = Correspondences();
    c.baseline = baseline_;
    corr_landmark.clear();
    corr_keypoint.clear();
    for (std::size_t i = 0; i < match.size(); ++i) {
      if (match[i] < 0) continue;
      const Keypoint& k = fs.keypoints[match[i]];
      c.p_W.push_back(views[i].p_W);
      c.uv.push_back(Vec2(k.u, k.v));
      c.sigma_px.push_back(fs.scales[k.octave]);
      // The right image's column, as local BA uses it (none without a baseline).
      if (baseline_ > 0)
        c.u_right.push_back(K_.rightColumn(k.u, k.depth, baseline_));
      corr_landmark.push_back(int(local[i]));
      corr_keypoint.push_back(match[i]);
    }
    Expected<PoseEstimate> e = Error{"no pose"};
    if (int(c.size()) >= params_.pose.min_inliers) {
      if (refine_first) e = refineFromPrior(c, corr_landmark, T_C_W_pred);
      if (!e.ok() || e->num_inliers < params_.min_tracked) e = estimatePose(c, K_, params_.pose);
    }
    return e;
  };
  Expected<PoseEstimate> est = solve(was_ok);
  const bool failed = !est.ok() || est->num_inliers < params_.min_tracked;
  if (failed && params_.relocalise_keyframes > 0) {
    // Relocalisation without a pose prior: the landmarks of the last keyframes
    // matched by descriptor alone, PnP RANSAC.
    local = localMap(params_.relocalise_keyframes);
    views = viewsOf(local);
    match = matchByDescriptor(views, fs, params_.matching);
    r.matched = count(match);
    est = solve(false);
  }
  if (!est.ok() || est->num_inliers < params_.min_tracked) {
    status_ = TrackingStatus::kLost;
    lost_since_keyframe_ = true;
    have_velocity_ = false;
    r.status = status_;
    r.tracked = est.ok() ? est->num_inliers : 0;
    r.keyframe = policy_.decide(frame.left, TrackingState{false, r.tracked, reference_tracked_});
    noteHealth(r);
    return r;
  }

  status_ = TrackingStatus::kOk;
  have_velocity_ = was_ok;
  T_C_W_prev_ = T_C_W_last_;
  T_C_W_last_ = est->T_C_W;
  prev_stamp_ = last_stamp_;
  last_stamp_ = frame.stamp;
  r.status = status_;
  r.T_W_C = est->T_C_W.inverse();
  r.tracked = est->num_inliers;
  std::vector<int> keypoint_landmark(fs.size(), -1);
  for (std::size_t i = 0; i < c.size(); ++i) {
    if (!est->inlier[i]) continue;
    keypoint_landmark[corr_keypoint[i]] = corr_landmark[i];
    landmark_angle_[corr_landmark[i]] = fs.angles[corr_keypoint[i]];
  }
  // Culling statistics: which local landmarks should have been seen, which were.
  {
    std::vector<bool> found(landmarks_.size(), false);
    for (std::size_t i = 0; i < c.size(); ++i)
      if (est->inlier[i]) found[corr_landmark[i]] = true;
    for (std::size_t id : local) {
      const Vec3 pc = est->T_C_W * landmarks_[id].p_A;
      if (pc.z() > 0 && K_.inImage(K_.project(pc))) mapping_.mapper().noteVisible(id, found[id]);
    }
  }
  // The reference count is that of the first frame tracked after the last
  // keyframe (a new keyframe's own landmark count includes points never tracked).
  if (reference_tracked_ == 0) reference_tracked_ = r.tracked;
  r.keyframe = policy_.decide(frame.left, TrackingState{true, r.tracked, reference_tracked_});
  if (r.keyframe.insert) {
    insertKeyframe(frame.stamp, r.T_W_C, fs, keypoint_landmark);
    r.new_keyframe = true;
    runLocalMapping(&r, fs.scales);
    for (const auto& [id, kp] : r.mapping.triangulated) {  // new points from local mapping
      landmark_angle_.resize(landmarks_.size(), 0.f);
      landmark_origin_.resize(landmarks_.size(), keyframes_.back().id);
      landmark_angle_[id] = fs.angles[kp];
    }
  }
  noteHealth(r);
  return r;
}

void Tracker::noteHealth(const TrackResult& r) {
  for (distill::TrackingHealth* h : {&health_, &total_health_}) {
    ++h->frames;
    if (r.status != TrackingStatus::kOk) {
      ++h->lost;
      continue;
    }
    if (r.tracked < params_.weak_tracked) ++h->weak;
    h->min_tracked = h->min_tracked == 0 ? r.tracked : std::min(h->min_tracked, r.tracked);
  }
}

void Tracker::runLocalMapping(TrackResult* r, const std::vector<float>& scales) {
  const SE3 before = keyframes_.back().T_A_C;
  r->mapping = mapping_.insert({&keyframes_, &landmarks_}, scales);
  if (mapping_.parallel()) return;  // the BA's correction arrives with a later poll
  // The newest keyframe is the current frame: carry its correction into the
  // motion model (both poses, so the velocity is kept).
  const SE3 T_W_C = keyframes_.back().T_A_C;
  const SE3 correction = T_W_C * before.inverse();  // W <- W
  T_C_W_last_ = T_W_C.inverse();
  T_C_W_prev_ = T_C_W_prev_ * correction.inverse();
  r->T_W_C = T_W_C;
}

distill::TrackingHealth Tracker::takeWindowHealth() {
  distill::TrackingHealth h = health_;
  health_ = {};
  return h;
}

distill::MotionHint Tracker::motionHint() const {
  distill::MotionHint h;
  if (status_ != TrackingStatus::kOk || !have_velocity_) return h;
  h.valid = true;
  h.T_A_C = T_C_W_last_.inverse();
  h.T_Cprev_Ccurr = T_C_W_prev_ * T_C_W_last_.inverse();
  h.dt_s = last_stamp_ > prev_stamp_ ? last_stamp_ - prev_stamp_ : 0.05;
  h.camera_id = 0;
  return h;
}

}  // namespace hermes
