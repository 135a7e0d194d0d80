// Pose graphs as text in the g2o format (VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX),
// so that a graph the server solved can be solved again offline (the
// pose-graph replay benchmark) or opened by other back ends (g2o, GTSAM's
// readG2o). g2o's edge error is [t; vec(q)], Hermes' is [t; 2 vec(q)]: the
// information's rotation rows/columns are converted on the way (I_g2o = D I D,
// D = diag(1,1,1,2,2,2)). Hermes adds comment lines other readers skip:
//   # hermes node <vertex id> <agent> <session> <keyframe>
//   # hermes edges odometry|loop      (the kind of the edges that follow)
// Without them (a g2o file from elsewhere) vertex i is keyframe i of agent 0,
// and an edge between consecutive vertices is odometry, any other a loop.
#pragma once

#include <istream>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "hermes/server/pose_graph.h"

namespace hermes {
namespace server {

struct PoseGraphFile {
  std::vector<std::pair<KeyframeKey, SE3>> nodes;  ///< in file order
  std::vector<KeyframeKey> fixed;
  std::vector<PoseGraph::EdgeMeasurement> edges;

  /// The graph with these nodes (initial poses as given), edges and fixed nodes.
  Expected<PoseGraph> build(const PoseGraphParams& params) const;
};

/// Writes `graph` at its current poses.
void writePoseGraphG2o(const PoseGraph& graph, std::ostream& out);
Status writePoseGraphG2o(const PoseGraph& graph, const std::string& path);

/// Reads a g2o file; errors name the line (`name`:line) and what is wrong.
Expected<PoseGraphFile> readPoseGraphG2o(std::istream& in, const std::string& name);
Expected<PoseGraphFile> readPoseGraphG2o(const std::string& path);

}  // namespace server
}  // namespace hermes
