#include "hermes/server/pose_graph_io.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <map>
#include <sstream>

namespace hermes {
namespace server {
namespace {

// Hermes' error = D * g2o's error (rotation part doubled), so I_g2o = D I D.
const Vec6 kD = (Vec6() << 1, 1, 1, 2, 2, 2).finished();

void writePose(std::ostream& o, const SE3& T) {
  const Vec3 t = T.translation();
  const Quat q = T.quat();
  o << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' '
    << q.w();
}

bool readPose(std::istringstream& in, SE3* T) {
  double x, y, z, qx, qy, qz, qw;
  if (!(in >> x >> y >> z >> qx >> qy >> qz >> qw)) return false;
  Quat q(qw, qx, qy, qz);
  if (!std::isfinite(q.norm()) || q.norm() < 1e-6 || !std::isfinite(x + y + z)) return false;
  q.normalize();
  *T = SE3(q, Vec3(x, y, z));
  return true;
}

}  // namespace

Expected<PoseGraph> PoseGraphFile::build(const PoseGraphParams& params) const {
  PoseGraph g(params);
  for (const auto& [key, T] : nodes)
    if (Status s = g.addNode(key, T); !s) return Error{s.error()};
  for (const KeyframeKey& k : fixed)
    if (Status s = g.setFixed(k); !s) return Error{s.error()};
  for (const auto& e : edges) {
    Status s = e.loop ? g.addLoopEdge(e.a, e.b, e.T_a_b, e.information)
                      : g.addOdometryEdge(e.a, e.b, e.T_a_b, e.information);
    if (!s) return Error{s.error()};
  }
  return g;
}

void writePoseGraphG2o(const PoseGraph& graph, std::ostream& o) {
  o << std::setprecision(17);
  std::map<KeyframeKey, int> id;
  for (const auto& [key, T] : graph.poses()) {
    const int i = static_cast<int>(id.size());
    id[key] = i;
    o << "# hermes node " << i << ' ' << key.agent << ' ' << key.session << ' ' << key.id << '\n';
    o << "VERTEX_SE3:QUAT " << i << ' ';
    writePose(o, T);
    o << '\n';
  }
  for (const KeyframeKey& k : graph.fixedNodes()) o << "FIX " << id.at(k) << '\n';
  int kind = -1;
  for (const auto& e : graph.measurements()) {
    if (static_cast<int>(e.loop) != kind) {
      kind = e.loop;
      o << "# hermes edges " << (e.loop ? "loop" : "odometry") << '\n';
    }
    o << "EDGE_SE3:QUAT " << id.at(e.a) << ' ' << id.at(e.b) << ' ';
    writePose(o, e.T_a_b);
    const Mat6 I = kD.asDiagonal() * e.information * kD.asDiagonal();
    for (int r = 0; r < 6; ++r)
      for (int c = r; c < 6; ++c) o << ' ' << I(r, c);
    o << '\n';
  }
}

Status writePoseGraphG2o(const PoseGraph& graph, const std::string& path) {
  std::ofstream f(path);
  if (!f) return Error{"cannot write pose graph to " + path};
  writePoseGraphG2o(graph, f);
  f.close();
  if (!f) return Error{"writing pose graph to " + path + " failed"};
  return Status::Ok();
}

Expected<PoseGraphFile> readPoseGraphG2o(std::istream& in, const std::string& name) {
  PoseGraphFile f;
  std::map<long, KeyframeKey> hermes_keys;  // from "# hermes node" lines
  std::map<long, std::size_t> node_index;   // vertex id -> index in f.nodes
  std::vector<long> fixed_ids;
  struct RawEdge {
    long a, b;
    SE3 T;
    Mat6 info;
    int kind;  // -1 unknown, 0 odometry, 1 loop
    int line;
  };
  std::vector<RawEdge> raw;
  int kind = -1;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    const std::string where = name + ":" + std::to_string(n) + ": ";
    std::istringstream ls(line);
    std::string tag;
    if (!(ls >> tag)) continue;
    if (tag[0] == '#') {
      std::string h, what;
      if (!(ls >> h >> what) || h != "hermes") continue;
      if (what == "node") {
        long i;
        KeyframeKey k;
        if (!(ls >> i >> k.agent >> k.session >> k.id)) return Error{where + "malformed hermes node comment"};
        hermes_keys[i] = k;
      } else if (what == "edges") {
        std::string k;
        ls >> k;
        if (k != "odometry" && k != "loop") return Error{where + "edge kind must be odometry or loop"};
        kind = k == "loop";
      }
      continue;
    }
    if (tag == "VERTEX_SE3:QUAT") {
      long i;
      SE3 T;
      if (!(ls >> i) || !readPose(ls, &T)) return Error{where + "malformed VERTEX_SE3:QUAT"};
      if (node_index.count(i)) return Error{where + "vertex " + std::to_string(i) + " defined twice"};
      KeyframeKey k;
      if (auto it = hermes_keys.find(i); it != hermes_keys.end())
        k = it->second;
      else
        k.id = static_cast<KeyframeId>(i);
      node_index[i] = f.nodes.size();
      f.nodes.emplace_back(k, T);
    } else if (tag == "FIX") {
      for (long i; ls >> i;) fixed_ids.push_back(i);
    } else if (tag == "EDGE_SE3:QUAT") {
      RawEdge e;
      e.kind = kind;
      e.line = n;
      if (!(ls >> e.a >> e.b) || !readPose(ls, &e.T)) return Error{where + "malformed EDGE_SE3:QUAT"};
      Mat6 I;
      for (int r = 0; r < 6; ++r)
        for (int c = r; c < 6; ++c)
          if (!(ls >> I(r, c))) return Error{where + "EDGE_SE3:QUAT needs 21 information entries"};
      I.triangularView<Eigen::StrictlyLower>() = I.transpose().triangularView<Eigen::StrictlyLower>();
      if (!I.allFinite()) return Error{where + "non-finite information"};
      e.info = kD.asDiagonal().inverse() * I * kD.asDiagonal().inverse();
      raw.push_back(e);
    } else {
      return Error{where + "unsupported record '" + tag + "' (only SE(3) quaternion graphs)"};
    }
  }
  if (f.nodes.empty()) return Error{name + ": no VERTEX_SE3:QUAT"};
  auto key = [&](long i, int n) -> Expected<KeyframeKey> {
    auto it = node_index.find(i);
    if (it == node_index.end())
      return Error{name + ":" + std::to_string(n) + ": unknown vertex " + std::to_string(i)};
    return f.nodes[it->second].first;
  };
  for (long i : fixed_ids) {
    Expected<KeyframeKey> k = key(i, 0);
    if (!k) return Error{name + ": FIX of unknown vertex " + std::to_string(i)};
    f.fixed.push_back(*k);
  }
  for (const RawEdge& r : raw) {
    Expected<KeyframeKey> a = key(r.a, r.line), b = key(r.b, r.line);
    if (!a) return Error{a.error()};
    if (!b) return Error{b.error()};
    const bool consecutive = r.b == r.a + 1;
    f.edges.push_back({*a, *b, r.T, r.info, r.kind >= 0 ? r.kind == 1 : !consecutive});
  }
  return f;
}

Expected<PoseGraphFile> readPoseGraphG2o(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{"cannot open pose graph " + path};
  return readPoseGraphG2o(in, path);
}

}  // namespace server
}  // namespace hermes
