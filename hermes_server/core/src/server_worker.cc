#include "hermes/server/server_worker.h"

#include <chrono>

namespace hermes {
namespace server {

Status ServerWorkerParams::validate() const {
  if (latency_window < 1) return Error{"server worker: latency_window must be >= 1"};
  if (!(tend_period_s > 0)) return Error{"server worker: tend_period_s must be > 0"};
  return Status::Ok();
}

ServerWorker::ServerWorker(std::unique_ptr<Server> server, ServerWorkerParams params, Clock clock,
                           Merged on_merged, Tend tend)
    : server_(std::move(server)),
      params_(params),
      clock_(std::move(clock)),
      on_merged_(std::move(on_merged)),
      tend_(std::move(tend)),
      acks_(params.latency_window) {
  HERMES_CHECK(server_ != nullptr, "server worker: no server");
  HERMES_CHECK(static_cast<bool>(clock_), "server worker: no clock");
  const Status valid = params_.validate();
  HERMES_CHECK(static_cast<bool>(valid), valid.error());
  auto first = std::make_shared<MergedView>(mergedView(*server_));  // a resumed server holds a map
  first->version = 1;
  view_ = std::move(first);
  const ServerCounters& c = server_->counters();
  attempts_seen_ = c.merged + c.merge_errors;
  if (!params_.parallel) return;
  server_->leaveFullSolvesToCaller(true);
  work_ = server_->pending() > 0;  // resumed with submaps queued
  running_ = true;
  thread_ = std::thread([this] { loop(); });
}

ServerWorker::~ServerWorker() { stop(); }

ReceiveResult ServerWorker::onFrame(const std::uint8_t* data, std::size_t size,
                                    const SubmapHeader* claimed, double now) {
  ReceiveResult r = server_->onFrame(data, size, claimed, now);
  if (r.verdict == ArrivalVerdict::kAccept && params_.parallel) {
    {
      std::lock_guard<std::mutex> l(mu_);
      work_ = true;
    }
    wake_.notify_one();
  }
  return r;
}

void ServerWorker::recordAckLatency(double ms) {
  std::lock_guard<std::mutex> l(mu_);
  acks_.add("ack_latency", ms);
}

int ServerWorker::process(double now, int max_submaps) {
  HERMES_CHECK(!running_, "server worker: process() while the merge thread runs");
  const int merged = server_->process(now, max_submaps);
  publish();
  return merged;
}

void ServerWorker::loop() {
  std::unique_lock<std::mutex> l(mu_);
  while (true) {
    const auto woken = [this] { return stopping_ || work_; };
    if (tend_)
      wake_.wait_for(l, std::chrono::duration<double>(params_.tend_period_s), woken);
    else
      wake_.wait(l, woken);
    if (stopping_) break;
    work_ = false;
    merging_ = true;
    l.unlock();
    tend(false);
    // One submap per call: a stop request is seen between merges, and every
    // merge gets its own view.
    // Then the deferred loop closures, a budget at a time, each after any
    // submap that came meanwhile; beside both, the full pose-graph solve.
    while (!stopping_) {
      const bool solving = tendFullSolve();
      if (server_->pending() > 0 || server_->deferredClosures() > 0) {
        server_->process(clock_(), 1);
        publish();
      } else if (solving) {
        full_solve_done_.wait_for(std::chrono::milliseconds(20));
      } else {
        break;
      }
    }
    l.lock();
    merging_ = false;
    if (!work_) idle_.notify_all();
  }
  merging_ = false;
  idle_.notify_all();
}

bool ServerWorker::tendFullSolve() {
  if (full_solve_ && full_solve_done_.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    full_solve_done_.get();
    server_->applyFullSolve(*full_solve_);
    full_solve_.reset();
    publish(/*force=*/true);
  }
  if (!full_solve_ && !stopping_ && server_->fullSolveDue()) {
    Expected<FullSolve> job = server_->prepareFullSolve();
    if (!job) return false;  // counted by the server
    full_solve_ = std::make_shared<FullSolve>(std::move(*job));
    std::shared_ptr<FullSolve> solve = full_solve_;
    full_solve_done_ = std::async(std::launch::async, [solve] { solve->run(); });
  }
  return full_solve_ != nullptr;
}

void ServerWorker::publish(bool force) {
  const ServerCounters& c = server_->counters();
  const std::size_t attempts = c.merged + c.merge_errors;
  if (attempts == attempts_seen_ && !force) return;
  attempts_seen_ = attempts;
  auto v = std::make_shared<MergedView>(mergedView(*server_));
  {
    std::lock_guard<std::mutex> l(mu_);
    v->version = view_->version + 1;
    view_ = v;
  }
  if (on_merged_) on_merged_(*v);
  tend(true);
}

void ServerWorker::tend(bool force) {
  if (!tend_) return;
  const double now = clock_();
  if (!force && now - last_tend_ < params_.tend_period_s) return;
  last_tend_ = now;
  tend_(*server_, now);
}

void ServerWorker::waitIdle() {
  std::unique_lock<std::mutex> l(mu_);
  idle_.wait(l, [this] { return !running_ || (!work_ && !merging_); });
}

void ServerWorker::requestStop() {
  {
    std::lock_guard<std::mutex> l(mu_);
    stopping_ = true;
  }
  wake_.notify_one();
}

void ServerWorker::stop() {
  requestStop();
  if (thread_.joinable()) thread_.join();
  {
    std::lock_guard<std::mutex> l(mu_);
    running_ = false;
  }
  idle_.notify_all();
}

std::shared_ptr<const MergedView> ServerWorker::view() const {
  std::lock_guard<std::mutex> l(mu_);
  return view_;
}

RunMetrics ServerWorker::metrics() const {
  RunMetrics m;
  if (running_) {
    m = view()->metrics;
    const auto lock = server_->lockIntake();
    addIntakeMetrics(*server_, &m);
  } else {
    m = serverMetrics(*server_);
  }
  std::lock_guard<std::mutex> l(mu_);
  for (const auto& [name, t] : acks_.summary()) m.timings_ms[name] = t;
  return m;
}

Server& ServerWorker::server() {
  HERMES_CHECK(!running_, "server worker: the server is the merge thread's while it runs");
  return *server_;
}

const Server& ServerWorker::server() const {
  HERMES_CHECK(!running_, "server worker: the server is the merge thread's while it runs");
  return *server_;
}

}  // namespace server
}  // namespace hermes
