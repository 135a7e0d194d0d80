// hermes_eval: trajectory accuracy (ATE / RPE) against ground truth for one or
// several agents, and the metrics JSON (DESIGN §7, §8).
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "hermes/core/eval_io.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/metrics.h"
#include "hermes_help/hermes_eval.h"  // tools/help/hermes_eval.txt

using namespace hermes;

namespace {

const char* const kUsage = hermes_help::kText;

[[noreturn]] void fail(const std::string& reason) {
  std::fprintf(stderr, "hermes_eval: %s\n", reason.c_str());
  std::exit(2);
}

std::string stem(const std::string& path) {
  std::string p = path;
  while (p.size() > 1 && p.back() == '/') p.pop_back();
  const auto slash = p.find_last_of('/');
  std::string base = slash == std::string::npos ? p : p.substr(slash + 1);
  const auto dot = base.find_last_of('.');
  if (dot != std::string::npos && dot > 0) base = base.substr(0, dot);
  if (base == "data") {  // .../state_groundtruth_estimate0/data.csv: use the dataset name
    const auto mav = p.find("/mav0/");
    if (mav != std::string::npos) return stem(p.substr(0, mav));
  }
  return base;
}

double parseNumber(const std::string& opt, const char* text) {
  char* end = nullptr;
  const double v = std::strtod(text, &end);
  if (end == text || *end != '\0') fail(opt + " expects a number, got '" + text + "'");
  return v;
}

void printStats(FILE* out, const char* label, const eval::ErrorStats& s, const char* unit) {
  std::fprintf(out, "  %-22s rmse %9.4f  mean %9.4f  median %9.4f  max %9.4f  std %9.4f %s\n",
               label, s.rmse, s.mean, s.median, s.max, s.std, unit);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> gts, ests, names;
  std::string pending_name, json_out, est_cam;
  eval::EvalParams params;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> const char* {
      if (i + 1 >= argc) fail("option " + a + " needs a value");
      return argv[++i];
    };
    if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--gt") {
      gts.push_back(value());
    } else if (a == "--est") {
      ests.push_back(value());
      names.push_back(pending_name);
      pending_name.clear();
    } else if (a == "--name") {
      pending_name = value();
    } else if (a == "--align") {
      auto m = eval::parseAlignMode(value());
      if (!m) fail(m.error());
      params.align = *m;
    } else if (a == "--max-dt") {
      params.max_dt = parseNumber(a, value());
    } else if (a == "--rpe-delta") {
      params.rpe_delta_s = parseNumber(a, value());
    } else if (a == "--rpe-frames") {
      const double f = parseNumber(a, value());
      if (f != int(f)) fail("--rpe-frames expects an integer");
      params.rpe_delta_frames = int(f);
    } else if (a == "--rpe-tolerance") {
      params.rpe_tolerance = parseNumber(a, value());
    } else if (a == "--est-cam") {
      est_cam = value();
    } else if (a == "--json") {
      json_out = value();
    } else {
      fail("unknown option '" + a + "' (see --help)");
    }
  }
  if (gts.empty() && ests.empty()) fail("needs at least one --gt GT --est EST pair (see --help)");
  if (gts.size() != ests.size())
    fail("got " + std::to_string(gts.size()) + " --gt but " + std::to_string(ests.size()) +
         " --est (they pair up in order)");
  if (!pending_name.empty()) fail("--name must come before the --est it names");
  if (Status s = params.validate(); !s) fail(s.error());

  SE3 T_C_B;  // identity unless --est-cam
  if (!est_cam.empty()) {
    auto T_B_C = eval::readEurocSensorExtrinsic(est_cam);
    if (!T_B_C) fail(T_B_C.error());
    T_C_B = T_B_C->inverse();
  }
  std::vector<eval::AgentTrajectories> agents;
  for (size_t k = 0; k < gts.size(); ++k) {
    eval::AgentTrajectories at;
    at.name = names[k].empty() ? stem(ests[k]) : names[k];
    for (const auto& other : agents)
      if (other.name == at.name) at.name += "_" + std::to_string(k);
    auto gt = eval::readTrajectoryForEval(gts[k]);
    if (!gt) fail(gt.error());
    auto est = eval::readTrajectoryForEval(ests[k]);
    if (!est) fail(est.error());
    if (gt->size() + est->size() > 20000)
      std::fprintf(stderr, "[hermes_eval] read %s: %zu gt poses, %zu estimate poses\n",
                   at.name.c_str(), gt->size(), est->size());
    at.gt = std::move(*gt);
    at.est = est_cam.empty() ? std::move(*est) : transformTrajectory(*est, T_C_B);
    agents.push_back(std::move(at));
  }

  auto ev = eval::evaluateAgents(agents, params);
  if (!ev) fail(ev.error());

  RunMetrics metrics;
  fillAccuracy(*ev, params, &metrics);

  FILE* out = json_out == "-" ? stderr : stdout;
  std::fprintf(out, "alignment %s, max_dt %.4g s, RPE over %g %s\n",
               eval::toString(params.align), params.max_dt,
               params.rpe_delta_frames > 0 ? double(params.rpe_delta_frames) : params.rpe_delta_s,
               params.rpe_delta_frames > 0 ? "frames" : "s");
  for (const auto& a : ev->agents) {
    std::fprintf(out, "%s: %zu of %zu estimate poses matched\n", a.name.c_str(),
                 a.assoc.matched(), a.est_poses);
    printStats(out, "ATE translation", a.ate.trans_m, "m");
    printStats(out, "ATE rotation", a.ate.rot_deg, "deg");
    if (a.rpe.pairs > 0) {
      printStats(out, "RPE translation", a.rpe.trans_m, "m");
      printStats(out, "RPE rotation", a.rpe.rot_deg, "deg");
    } else {
      std::fprintf(out, "  RPE: no pose pairs at this spacing\n");
    }
    if (a.ate.alignment.mode == eval::AlignMode::kSim3)
      std::fprintf(out, "  scale %.6f\n", a.ate.alignment.scale);
  }
  if (ev->agents.size() > 1) {
    std::fprintf(out, "merged (%zu agents, one common alignment): %zu poses\n",
                 ev->agents.size(), ev->matched);
    printStats(out, "ATE translation", ev->merged_ate.trans_m, "m");
    for (size_t k = 0; k < ev->agents.size(); ++k)
      std::fprintf(out, "  %-22s rmse %9.4f m under the common alignment\n",
                   ev->agents[k].name.c_str(), ev->merged_per_agent_m[k].rmse);
  }
  std::fprintf(out, "ate_rmse_m %.6f\n", ev->merged_ate.trans_m.rmse);

  if (json_out == "-") {
    std::printf("%s\n", metricsToJsonString(metrics).c_str());
  } else if (!json_out.empty()) {
    if (Status s = writeMetricsJson(json_out, metrics); !s) {
      std::fprintf(stderr, "hermes_eval: %s\n", s.error().c_str());
      return 1;
    }
  }
  return 0;
}
