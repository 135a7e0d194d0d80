#include "hermes/server/server_outputs.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <sstream>

namespace hermes {
namespace server {

Trajectory agentTrajectory(const GlobalMap& map, std::uint32_t agent,
                           const std::optional<SE3>& T_B_C) {
  Trajectory out;
  const SE3 T_C_B = T_B_C ? T_B_C->inverse() : SE3::identity();
  for (const auto& [tid, t] : map.trajectories) {
    if (t.agent != agent || !t.anchored) continue;
    for (const auto& [id, kf] : t.keyframes) out.push_back({kf.keyframe.stamp, kf.T_W_C * T_C_B});
  }
  std::sort(out.begin(), out.end(),
            [](const StampedPose& a, const StampedPose& b) { return a.t < b.t; });
  // Strictly increasing stamps (a reset session may repeat a stamp): keep the first.
  out.erase(std::unique(out.begin(), out.end(),
                        [](const StampedPose& a, const StampedPose& b) { return a.t == b.t; }),
            out.end());
  return out;
}

std::vector<std::pair<std::uint32_t, GlobalPoseUpdate>> globalPoseUpdates(const GlobalMap& map) {
  std::vector<std::pair<std::uint32_t, GlobalPoseUpdate>> out;
  for (const auto& [tid, t] : map.trajectories) {
    if (!t.anchored || t.keyframes.empty()) continue;
    const StoredKeyframe* newest = nullptr;
    for (const auto& [id, kf] : t.keyframes)
      if (!newest || kf.keyframe.stamp > newest->keyframe.stamp) newest = &kf;
    GlobalPoseUpdate u;
    u.session = t.session;
    u.keyframe_stamp = newest->keyframe.stamp;
    u.keyframes = t.keyframes.size();
    u.T_W_O = newest->T_W_C * newest->keyframe.T_A_C.inverse();
    out.emplace_back(t.agent, u);
  }
  return out;
}

MergedView mergedView(const Server& server) {
  MergedView v;
  const GlobalMap& map = server.map();
  v.landmarks = map.landmarkPositionsWorld(&v.landmark_robots);
  for (const LoopEdge& l : map.loops) {
    const StoredKeyframe* a = map.keyframe(l.a);
    const StoredKeyframe* b = map.keyframe(l.b);
    const TrajectoryMap* ta = map.trajectory(l.a.agent, l.a.session);
    const TrajectoryMap* tb = map.trajectory(l.b.agent, l.b.session);
    if (l.accepted && a && b && ta && tb && ta->anchored && tb->anchored)
      v.loops.emplace_back(a->T_W_C.translation(), b->T_W_C.translation());
  }
  v.metrics = mergeMetrics(server);
  const auto updates = globalPoseUpdates(map);
  std::vector<RobotId> robots;
  {
    const auto lock = server.lockIntake();
    const Bookkeeper& bk = server.bookkeeper();
    for (const auto& [robot, u] : updates) {
      const AgentStats* st = bk.stats(robot);
      if (st && st->current_session == u.session) v.poses.push_back({robot, st->uuid, u});
    }
    robots = bk.robots();
  }
  for (RobotId r : robots) {
    Trajectory t = agentTrajectory(map, r);
    if (!t.empty()) v.paths.emplace(r, std::move(t));
  }
  return v;
}

Expected<std::vector<std::string>> writeAgentTrajectories(const GlobalMap& map,
                                                          const std::string& dir,
                                                          const std::map<std::uint32_t, SE3>& T_B_C) {
  std::vector<std::uint32_t> agents;
  for (const auto& [tid, t] : map.trajectories)
    if (t.anchored && std::find(agents.begin(), agents.end(), t.agent) == agents.end())
      agents.push_back(t.agent);
  std::vector<std::string> paths;
  for (std::uint32_t a : agents) {
    auto it = T_B_C.find(a);
    const Trajectory traj =
        agentTrajectory(map, a, it == T_B_C.end() ? std::nullopt : std::optional<SE3>(it->second));
    const std::string path = dir + "/agent_" + std::to_string(a) + ".tum";
    if (Status s = writeTumTrajectory(path, traj); !s) return Error{s.error()};
    paths.push_back(path);
  }
  return paths;
}

std::array<std::uint8_t, 3> robotColour(std::uint32_t robot) {
  static constexpr std::uint8_t kTab10[10][3] = {
      {31, 119, 180}, {255, 127, 14}, {44, 160, 44},  {214, 39, 40},  {148, 103, 189},
      {140, 86, 75},  {227, 119, 194}, {127, 127, 127}, {188, 189, 34}, {23, 190, 207}};
  const std::uint8_t* c = kTab10[robot % 10];
  return {c[0], c[1], c[2]};
}

Status writePly(const std::string& path, const std::vector<Vec3>& points, bool binary) {
  std::ofstream f(path, std::ios::binary);
  if (!f) return Error{"ply: cannot write " + path};
  f << "ply\nformat " << (binary ? "binary_little_endian" : "ascii") << " 1.0\n"
    << "comment hermes server global map (landmarks, world frame)\n"
    << "element vertex " << points.size() << "\n"
    << "property float x\nproperty float y\nproperty float z\nend_header\n";
  for (const Vec3& p : points) {
    const float v[3] = {static_cast<float>(p.x()), static_cast<float>(p.y()),
                        static_cast<float>(p.z())};
    if (binary)
      f.write(reinterpret_cast<const char*>(v), sizeof(v));
    else
      f << v[0] << ' ' << v[1] << ' ' << v[2] << '\n';
  }
  if (!f) return Error{"ply: write failed for " + path};
  return Status::Ok();
}

Expected<std::vector<Vec3>> readPly(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return Error{"ply: cannot open " + path};
  std::string line;
  bool binary = false;
  std::size_t count = 0;
  int properties = 0;
  if (!std::getline(f, line) || line != "ply") return Error{"ply: " + path + ": missing 'ply' magic"};
  while (std::getline(f, line) && line != "end_header") {
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "format") {
      ls >> word;
      binary = word == "binary_little_endian";
      if (!binary && word != "ascii") return Error{"ply: " + path + ": unsupported format " + word};
    } else if (word == "element") {
      ls >> word >> count;
    } else if (word == "property") {
      ls >> word;
      if (word != "float") return Error{"ply: " + path + ": only float properties supported"};
      ++properties;
    }
  }
  if (line != "end_header" || properties != 3)
    return Error{"ply: " + path + ": bad header (need end_header and 3 float properties)"};
  std::vector<Vec3> points;
  for (std::size_t i = 0; i < count; ++i) {
    float v[3];
    if (binary)
      f.read(reinterpret_cast<char*>(v), sizeof(v));
    else
      f >> v[0] >> v[1] >> v[2];
    if (!f) return Error{"ply: " + path + ": truncated at vertex " + std::to_string(i)};
    points.emplace_back(v[0], v[1], v[2]);
  }
  return points;
}

void fillHeldLoad(const Server& server, RobotId robot, AgentMetrics* metrics) {
  const HeldLoad* held = server.heldLoad(robot);
  metrics->held_submaps = static_cast<int64_t>(held ? held->submaps : 0);
  metrics->held_bytes = static_cast<int64_t>(held ? held->bytes : 0);
  metrics->held_bytes_peak = static_cast<int64_t>(held ? held->peak_bytes : 0);
}

void fillSessions(const Bookkeeper& bookkeeper, RobotId robot, AgentMetrics* metrics) {
  const AgentStats* s = bookkeeper.stats(robot);
  metrics->sessions = static_cast<int64_t>(s ? s->sessions.size() : 0);
  metrics->relocalised = s ? s->relocalisedSessions() : 0;
  metrics->reported_new = s ? s->newRobotSessions() : 0;
}

RunMetrics mergeMetrics(const Server& server) {
  RunMetrics m;
  const MapManager& mm = server.mapManager();
  m.loops_accepted = static_cast<int64_t>(mm.loopsAccepted());
  m.loops_rejected = static_cast<int64_t>(mm.loopsRejected());
  m.loops_bridged = mm.loopsBridged();
  m.timings_ms = server.timings().summary();
  return m;
}

void addIntakeMetrics(const Server& server, RunMetrics* m) {
  m->agents_merged = server.mapManager().agentsMerged();  // anchoring lives in the bookkeeper
  const Bookkeeper& bk = server.bookkeeper();
  int64_t bytes = 0;
  m->per_agent.clear();
  m->relocalised.reset();
  m->robots_new.reset();
  for (RobotId r : bk.robots()) {
    const AgentStats* s = bk.stats(r);
    if (!s) continue;
    AgentMetrics a;
    a.agent = s->name.empty() ? hermes::toString(s->uuid) : s->name;
    a.keyframes = static_cast<int64_t>(s->keyframes);
    a.landmarks = static_cast<int64_t>(s->landmarks);
    a.bytes = static_cast<int64_t>(s->bytes_received);
    a.submaps_applied = static_cast<int64_t>(s->submaps_applied);
    fillHeldLoad(server, r, &a);
    fillSessions(bk, r, &a);
    m->relocalised = m->relocalised.value_or(0) + *a.relocalised;
    m->robots_new = m->robots_new.value_or(0) + *a.reported_new;
    bytes += a.bytes.value_or(0);
    m->per_agent.push_back(a);
  }
  m->bytes_total = bytes;
  if (!m->relocalised) m->relocalised = m->robots_new = 0;
  const ReceiverStats& rs = server.receiverStats();
  m->frames_refused.clear();
  for (std::size_t c = 0; c < kReceiveCodes; ++c) {
    const auto code = static_cast<ReceiveCode>(c);
    if (code != ReceiveCode::kAccepted && rs.by_code[c] > 0)
      m->frames_refused[toString(code)] = static_cast<int64_t>(rs.by_code[c]);
  }
}

RunMetrics serverMetrics(const Server& server) {
  RunMetrics m = mergeMetrics(server);
  addIntakeMetrics(server, &m);
  return m;
}

}  // namespace server
}  // namespace hermes
