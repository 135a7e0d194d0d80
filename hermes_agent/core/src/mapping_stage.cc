#include "hermes/agent/mapping_stage.h"

#include <algorithm>
#include <chrono>

namespace hermes {

MappingStage::MappingStage(const LocalMapperParams& params, const PinholeIntrinsics& K, double baseline)
    : params_(params), K_(K), baseline_(baseline), mapper_(params, K, baseline) {}

MappingStage::~MappingStage() {
  if (worker_) worker_->stop();  // the running solve ends; its result is dropped
}

void MappingStage::setParallel(bool parallel, std::function<void()> before_solve) {
  before_solve_ = std::move(before_solve);
  if (!parallel) {
    worker_.reset();
    return;
  }
  // One job at a time (capacity 1, never full: schedule() pushes only when the
  // previous job was applied); keyframes arriving meanwhile wait in
  // waiting_keyframes_ and join the next job.
  worker_ = std::make_unique<agent::StageWorker<LocalBaJob>>(
      true, 1,
      [this](LocalBaJob& job) {
        solveLocalBa(&job);
        std::lock_guard<std::mutex> l(done_mu_);
        done_ = std::move(job);
      },
      nullptr);
}

std::size_t MappingStage::mappedKeyframes(std::size_t keyframes) const {
  return worker_ ? std::min(mapped_keyframes_, keyframes) : keyframes;
}

LocalMappingStats MappingStage::insert(LocalMapRef map, const std::vector<float>& scales) {
  ++stats_.keyframes;
  LocalMappingStats out;
  if (worker_) {  // structure now, the BA on the mapper thread
    const auto t0 = std::chrono::steady_clock::now();
    mapper_.processStructure(map.keyframes, map.landmarks, scales, &out);
    scales_ = scales;  // the same pyramid for every frame
    ++waiting_keyframes_;
    stats_.max_waiting = std::max<std::int64_t>(stats_.max_waiting, waiting_keyframes_);
    schedule(map);
    out.total_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    stats_.structure_ms_total += out.total_ms;
    stats_.structure_ms_max = std::max(stats_.structure_ms_max, out.total_ms);
    return out;
  }
  out = mapper_.process(map.keyframes, map.landmarks, scales);
  if (out.ba_ms > 0) {
    ++stats_.ba_jobs;
    stats_.ba_ms_total += out.ba_ms;
    stats_.ba_ms_max = std::max(stats_.ba_ms_max, out.ba_ms);
  }
  return out;
}

std::optional<SE3> MappingStage::poll(LocalMapRef map) {
  if (!worker_) return std::nullopt;
  std::optional<SE3> correction;
  if (in_flight_) {
    std::optional<LocalBaJob> job;
    {
      std::lock_guard<std::mutex> l(done_mu_);
      job.swap(done_);
    }
    if (job) {
      LocalMappingStats st;
      mapper_.applyBa(*job, map.keyframes, map.landmarks, &st);
      ++stats_.ba_jobs;
      stats_.ba_ms_total += st.ba_ms;
      stats_.ba_ms_max = std::max(stats_.ba_ms_max, st.ba_ms);
      mapped_keyframes_ = std::max(mapped_keyframes_, std::size_t(job->newest) + 1);
      if (job->summary)  // what the newest adjusted keyframe moved by (W <- W)
        correction = (*map.keyframes)[job->newest].T_A_C * job->T_W_newest.inverse();
      in_flight_ = false;
    }
  }
  schedule(map);
  return correction;
}

void MappingStage::waitIdle() {
  if (worker_) worker_->waitIdle();
}

void MappingStage::schedule(LocalMapRef map) {
  if (in_flight_ || waiting_keyframes_ == 0) return;
  std::optional<LocalBaJob> job = mapper_.cutBa(*map.keyframes, *map.landmarks, scales_);
  const int waiting = waiting_keyframes_;
  waiting_keyframes_ = 0;
  if (!job) {  // BA off or too few keyframes: nothing to wait for
    mapped_keyframes_ = map.keyframes->size();
    return;
  }
  // The job frees the newest ba_window keyframes: older waiting ones are skipped.
  const int covered = std::min(waiting, mapper_.params().ba_window);
  stats_.merged += covered - 1;
  stats_.skipped += waiting - covered;
  job->before_solve = before_solve_;
  in_flight_ = true;
  worker_->push(std::move(*job));
}

void MappingStage::reset() {
  mapper_ = LocalMapper(params_, K_, baseline_);
  mapped_keyframes_ = 0;
  waiting_keyframes_ = 0;
}

}  // namespace hermes
