// hermes_bench_pose_graph (`./hermes bench pose_graph RUN_DIR`): solves the last
// pose graph of a finished run (RUN_DIR/pose_graph.g2o + pose_graph_nodes.csv,
// written by `./hermes run`) again, with the run's pose-graph parameters or
// others (--set server.pose_graph.KEY=VALUE), and judges the result against
// ground truth: ATE of the keyframe (camera) positions under ONE common rigid
// alignment, per agent and over all, beside the same numbers for the poses the
// run itself ended with and for each agent's odometry chain placed by that
// alignment. A loop of minutes over one parameter instead of a 30-minute run.
//   --init odometry (default): every trajectory re-chained from its first node
//          through its odometry edges (a cold start, as a new solve sees it);
//   --init file: start from the run's own final poses.
// Prints JSON on stdout (or --json FILE) and a table on stderr.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "hermes/core/config.h"
#include "hermes/core/evaluation.h"
#include "hermes/server/pose_graph.h"
#include "hermes/server/pose_graph_io.h"
#include "hermes_help/hermes_bench_pose_graph.h"  // tools/help/hermes_bench_pose_graph.txt

using namespace hermes;
namespace fs = std::filesystem;

namespace {

const char* const kUsage = hermes_help::kText;

struct NodeInfo {
  std::string agent;
  double stamp = 0;
  bool has_gt = false;
  SE3 T_W_C_gt;
};

Expected<std::vector<NodeInfo>> readNodes(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{"cannot open " + path};
  std::string line;
  std::getline(in, line);  // header
  std::vector<NodeInfo> out;
  for (int n = 2; std::getline(in, line); ++n) {
    std::vector<std::string> f;
    std::stringstream ls(line);
    for (std::string c; std::getline(ls, c, ',');) f.push_back(c);
    if (line.back() == ',') f.push_back("");
    if (f.size() != 13) return Error{path + ":" + std::to_string(n) + ": expected 13 columns"};
    NodeInfo i;
    i.agent = f[1];
    i.stamp = std::stod(f[5]);
    if (!f[6].empty()) {
      double v[7];
      for (int k = 0; k < 7; ++k) v[k] = std::stod(f[6 + k]);
      i.T_W_C_gt = SE3(Quat(v[6], v[3], v[4], v[5]).normalized(), Vec3(v[0], v[1], v[2]));
      i.has_gt = true;
    }
    out.push_back(i);
  }
  return out;
}

/// Re-chains every trajectory (agent, session) from its first node through its
/// odometry edges; nodes an odometry edge does not reach keep their pose.
void chainOdometry(server::PoseGraphFile* f) {
  std::map<KeyframeKey, SE3> pose(f->nodes.begin(), f->nodes.end());
  std::map<KeyframeKey, const server::PoseGraph::EdgeMeasurement*> next;
  for (const auto& e : f->edges)
    if (!e.loop) next[e.a] = &e;
  for (auto it = pose.begin(); it != pose.end(); ++it) {
    const bool first = it == pose.begin() || std::prev(it)->first.agent != it->first.agent ||
                       std::prev(it)->first.session != it->first.session;
    if (!first) continue;
    for (KeyframeKey k = it->first; next.count(k);) {
      const auto* e = next.at(k);
      pose[e->b] = pose.at(k) * e->T_a_b;
      k = e->b;
    }
  }
  for (auto& [key, T] : f->nodes) T = pose.at(key);
}

struct Judged {
  std::map<std::string, double> per_agent;
  std::map<std::string, double> rpe_per_agent;  ///< local shape: RPE over kRpeDeltaS
  double all = 0;
  eval::Alignment alignment;  ///< the common one
};

constexpr double kRpeDeltaS = 10.0;

/// ATE of the poses against ground truth under one rigid alignment over all
/// (taken from the agents in `align_on` only, when it is not empty).
Expected<Judged> judge(const std::vector<std::pair<KeyframeKey, SE3>>& nodes,
                       const std::vector<NodeInfo>& info, const std::set<std::string>& align_on = {}) {
  eval::Association all, fit;  // fit: the nodes the alignment is taken from
  std::map<std::string, eval::Association> per;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    if (!info[i].has_gt) continue;
    const bool fits = align_on.empty() || align_on.count(info[i].agent);
    for (eval::Association* a : {&all, &fit, &per[info[i].agent]}) {
      if (a == &fit && !fits) continue;
      a->t.push_back(info[i].stamp);
      a->gt.push_back(info[i].T_W_C_gt);
      a->est.push_back(nodes[i].second);
    }
  }
  if (fit.matched() < 3) return Error{"fewer than 3 nodes with ground truth"};
  Expected<eval::AteResult> common = eval::computeAte(fit, eval::AlignMode::kSE3);
  if (!common) return Error{common.error()};
  Judged j;
  j.alignment = common->alignment;
  j.all = align_on.empty() ? common->trans_m.rmse : eval::ateWithAlignment(all, j.alignment).trans_m.rmse;
  eval::EvalParams rpe;
  rpe.rpe_delta_s = kRpeDeltaS;
  rpe.rpe_tolerance = 0.5;
  for (const auto& [name, a] : per) {
    j.per_agent[name] = eval::ateWithAlignment(a, common->alignment).trans_m.rmse;
    j.rpe_per_agent[name] = eval::computeRpe(a, eval::Alignment{}, rpe).trans_m.rmse;
  }
  return j;
}

nlohmann::json toJson(const Judged& j) {
  nlohmann::json o;
  o["ate_rmse_m"] = j.all;
  for (const auto& [name, v] : j.per_agent) o["per_agent"][name] = v;
  for (const auto& [name, v] : j.rpe_per_agent) o["rpe_10s_per_agent"][name] = v;
  return o;
}

}  // namespace

int main(int argc, char** argv) {
  std::string run_dir, init = "odometry", json_out;
  double loop_scale = 1, odometry_scale = 1;
  bool gt_loops = false;
  std::string poses_out, edges_out;
  std::vector<std::string> sets;
  std::set<std::string> align_on;
  std::string around;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](std::string* out) {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "hermes_bench_pose_graph: %s needs a value\n%s", a.c_str(), kUsage);
        std::exit(2);
      }
      *out = argv[++i];
    };
    if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--init") {
      value(&init);
    } else if (a == "--set") {
      std::string v;
      value(&v);
      sets.push_back(v);
    } else if (a == "--loop-information-scale" || a == "--odometry-information-scale") {
      std::string v;
      value(&v);
      char* end = nullptr;
      const double x = std::strtod(v.c_str(), &end);
      if (end == v.c_str() || *end != '\0' || !(x > 0) || !std::isfinite(x)) {
        std::fprintf(stderr, "hermes_bench_pose_graph: %s needs a positive number\n", a.c_str());
        return 2;
      }
      (a[2] == 'l' ? loop_scale : odometry_scale) = x;
    } else if (a == "--poses") {
      value(&poses_out);
    } else if (a == "--edges") {
      value(&edges_out);
    } else if (a == "--align-on") {
      std::string v;
      value(&v);
      std::stringstream ls(v);
      for (std::string name; std::getline(ls, name, ',');)
        if (!name.empty()) align_on.insert(name);
    } else if (a == "--incremental-around") {
      value(&around);
    } else if (a == "--ground-truth-loops") {
      gt_loops = true;
    } else if (a == "--json") {
      value(&json_out);
    } else if (!a.empty() && a[0] != '-' && run_dir.empty()) {
      run_dir = a;
    } else {
      std::fprintf(stderr, "hermes_bench_pose_graph: unknown argument '%s'\n%s", a.c_str(), kUsage);
      return 2;
    }
  }
  auto fail = [](const std::string& m, int code) {
    std::fprintf(stderr, "hermes_bench_pose_graph: %s\n", m.c_str());
    return code;
  };
  if (run_dir.empty()) return fail(std::string("missing RUN_DIR\n") + kUsage, 2);
  if (init != "odometry" && init != "file") return fail("--init must be odometry or file", 2);
  const fs::path dir(run_dir);
  if (!fs::is_regular_file(dir / "pose_graph.g2o"))
    return fail("'" + run_dir + "' is not a finished run: no pose_graph.g2o in it (./hermes run --out DIR writes one)", 2);
  Expected<Config> config = Config::fromFile((dir / "config_used.yaml").string());
  if (!config) return fail(config.error(), 2);
  for (const std::string& s : sets)
    if (Status st = config->applyOverride(s); !st) return fail(st.error(), 2);
  server::PoseGraphParams params;
  if (Status s = params.read(*config, "server.pose_graph"); !s) return fail(s.error(), 2);
  Expected<server::PoseGraphFile> file = server::readPoseGraphG2o((dir / "pose_graph.g2o").string());
  if (!file) return fail(file.error(), 2);
  Expected<std::vector<NodeInfo>> info = readNodes((dir / "pose_graph_nodes.csv").string());
  if (!info) return fail(info.error(), 2);
  if (info->size() != file->nodes.size())
    return fail("pose_graph_nodes.csv has " + std::to_string(info->size()) + " rows, the graph " +
                    std::to_string(file->nodes.size()) + " nodes",
                2);

  std::map<KeyframeKey, std::size_t> index;
  for (std::size_t i = 0; i < file->nodes.size(); ++i) index[file->nodes[i].first] = i;
  for (auto& e : file->edges) {
    e.information *= e.loop ? loop_scale : odometry_scale;
    const NodeInfo &a = (*info)[index.at(e.a)], &b = (*info)[index.at(e.b)];
    if (gt_loops && e.loop && a.has_gt && b.has_gt) e.T_a_b = a.T_W_C_gt.inverse() * b.T_W_C_gt;
  }
  for (const std::string& name : align_on)
    if (std::none_of(info->begin(), info->end(), [&](const NodeInfo& n) { return n.agent == name; }))
      return fail("--align-on: no agent '" + name + "' in " + (dir / "pose_graph_nodes.csv").string(), 2);
  Expected<Judged> as_run = judge(file->nodes, *info, align_on);
  if (!as_run) return fail(as_run.error(), 1);
  server::PoseGraphFile chained = *file;
  chainOdometry(&chained);
  Expected<Judged> odometry = judge(chained.nodes, *info);
  if (!odometry) return fail(odometry.error(), 1);
  // Odometry chains are each in their own frame: judge each on its own alignment.
  Judged odometry_own;
  for (const auto& [name, v] : odometry->per_agent) {
    std::vector<std::pair<KeyframeKey, SE3>> n;
    std::vector<NodeInfo> i;
    for (std::size_t k = 0; k < chained.nodes.size(); ++k)
      if ((*info)[k].agent == name) n.push_back(chained.nodes[k]), i.push_back((*info)[k]);
    if (Expected<Judged> j = judge(n, i)) {
      odometry_own.per_agent[name] = j->all;
      odometry_own.rpe_per_agent[name] = j->rpe_per_agent.at(name);
    }
  }

  Expected<server::PoseGraph> graph = (init == "file" ? *file : chained).build(params);
  if (!graph) return fail(graph.error(), 2);
  if (!around.empty()) {
    const auto colon = around.rfind(':');
    const int n = colon == std::string::npos ? 0 : std::atoi(around.c_str() + colon + 1);
    const std::string agent = colon == std::string::npos ? "" : around.substr(0, colon);
    std::vector<KeyframeKey> seeds;
    for (std::size_t i = 0; i < file->nodes.size(); ++i)
      if ((*info)[i].agent == agent) seeds.push_back(file->nodes[i].first);
    if (n <= 0 || seeds.empty()) return fail("--incremental-around needs AGENT:N with a known agent, N > 0", 2);
    seeds.erase(seeds.begin(), seeds.end() - std::min<std::ptrdiff_t>(n, static_cast<std::ptrdiff_t>(seeds.size())));
    graph->holdBeyond(seeds, params.incremental_hops, static_cast<std::size_t>(params.incremental_max_free));
    std::fprintf(stderr, "incremental: %zu of %zu nodes free around the last %zu of %s\n", graph->numFree(),
                 graph->numNodes(), seeds.size(), agent.c_str());
  }
  std::fprintf(stderr, "solving %zu nodes, %zu odometry + %zu loop edges ...\n", graph->numNodes(),
               graph->numOdometryEdges(), graph->numLoopEdges());
  Expected<server::PoseGraphResult> r = graph->optimize();
  if (!r) return fail(r.error(), 1);
  std::vector<std::pair<KeyframeKey, SE3>> solved;
  for (const auto& [key, T] : file->nodes) solved.emplace_back(key, *graph->pose(key));
  Expected<Judged> now = judge(solved, *info, align_on);
  if (!now) return fail(now.error(), 1);
  if (!poses_out.empty()) {
    std::ofstream o(poses_out);
    o.precision(10);
    o << "agent,stamp,x,y,z,gt_x,gt_y,gt_z,error_m\n";
    for (std::size_t i = 0; i < solved.size(); ++i) {
      const NodeInfo& n = (*info)[i];
      if (!n.has_gt) continue;
      const Vec3 p = now->alignment.applyToPoint(solved[i].second.translation());
      const Vec3 g = n.T_W_C_gt.translation();
      o << n.agent << ',' << n.stamp << ',' << p.x() << ',' << p.y() << ',' << p.z() << ',' << g.x()
        << ',' << g.y() << ',' << g.z() << ',' << (p - g).norm() << '\n';
    }
    if (!o) return fail("cannot write " + poses_out, 1);
  }
  if (!edges_out.empty()) {
    std::ofstream o(edges_out);
    o.precision(15);  // stamps are ~1.4e9 s
    o << "kind,agent_a,stamp_a,agent_b,stamp_b,residual_m,chi2,weight\n";
    for (const server::EdgeResidual& e : graph->residuals()) {
      const NodeInfo &a = (*info)[index.at(e.a)], &b = (*info)[index.at(e.b)];
      o << (e.loop ? "loop" : "odometry") << ',' << a.agent << ',' << a.stamp << ',' << b.agent << ','
        << b.stamp << ',' << e.error_m << ',' << e.chi2 << ',' << e.weight << '\n';
    }
    if (!o) return fail("cannot write " + edges_out, 1);
  }

  nlohmann::json j;
  j["run"] = run_dir;
  j["init"] = init;
  j["overrides"] = sets;
  j["loop_information_scale"] = loop_scale;
  j["odometry_information_scale"] = odometry_scale;
  j["ground_truth_loops"] = gt_loops;
  if (!align_on.empty()) j["align_on"] = std::vector<std::string>(align_on.begin(), align_on.end());
  j["nodes"] = graph->numNodes();
  j["free_nodes"] = graph->numFree();
  j["odometry_edges"] = graph->numOdometryEdges();
  j["loop_edges"] = graph->numLoopEdges();
  j["solve"] = {{"time_ms", r->time_ms}, {"iterations", r->iterations}, {"converged", r->converged},
                {"termination", r->termination}, {"reweight_rounds", r->reweight_rounds}};
  j["solved"] = toJson(*now);
  j["as_run"] = toJson(*as_run);
  j["odometry_own_alignment"] = toJson(odometry_own);
  std::fprintf(stderr, "%-18s %30s   %s\n", "", "ATE [cm]", "RPE over 10 s [cm]");
  std::fprintf(stderr, "%-18s %10s %10s %10s %10s %10s %10s\n", "agent", "solved", "as run", "odometry",
               "solved", "as run", "odometry");
  for (const auto& [name, v] : now->per_agent)
    std::fprintf(stderr, "%-18s %10.2f %10.2f %10.2f %10.2f %10.2f %10.2f\n", name.c_str(), 100 * v,
                 100 * as_run->per_agent.at(name), 100 * odometry_own.per_agent[name],
                 100 * now->rpe_per_agent.at(name), 100 * as_run->rpe_per_agent.at(name),
                 100 * odometry_own.rpe_per_agent[name]);
  std::fprintf(stderr, "%-18s %10.2f %10.2f\n", "all (one alignment)", 100 * now->all, 100 * as_run->all);
  std::fprintf(stderr, "solve %.0f ms, %d iterations, %s, %d re-weighting rounds\n", r->time_ms,
               r->iterations, r->termination.c_str(), r->reweight_rounds);
  if (json_out.empty()) {
    std::cout << j.dump(2) << '\n';
  } else {
    std::ofstream o(json_out);
    o << j.dump(2) << '\n';
    if (!o) return fail("cannot write " + json_out, 1);
  }
  return 0;
}
