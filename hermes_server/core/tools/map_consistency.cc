// hermes_map_consistency: the map-consistency measure of a saved global map
// (map_consistency.h): over the accepted loops' kept inlier
// keypoint pairs, each side's landmark against the other side's keypoint, as
// reprojection error [px] and 3-D distance to the keypoint's depth [m].
//   hermes_map_consistency RUN_DIR/global_map.hgm [--max-px 50]
// Prints one JSON object.
#include <cstdio>
#include <iostream>
#include <string>

#include <nlohmann/json.hpp>

#include "hermes/server/global_map.h"
#include "hermes/server/map_consistency.h"

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help") {
    std::fprintf(stderr, "usage: hermes_map_consistency GLOBAL_MAP.hgm [--max-px PX]\n");
    return argc < 2 ? 2 : 0;
  }
  double max_px = 50.0;
  if (argc == 4 && std::string(argv[2]) == "--max-px") max_px = std::stod(argv[3]);
  auto map = hermes::server::GlobalMap::load(argv[1]);
  if (!map) {
    std::fprintf(stderr, "hermes_map_consistency: %s\n", map.error().c_str());
    return 1;
  }
  const hermes::server::TieConsistency c = hermes::server::measureLoopTies(*map, max_px);
  nlohmann::json j;
  j["ties"] = c.ties;
  j["reproj_rms_px"] = c.reproj_rms_px;
  j["cross_ties"] = c.cross_ties;
  j["cross_reproj_rms_px"] = c.cross_reproj_rms_px;
  j["cross_reproj_median_px"] = c.cross_reproj_median_px;
  j["depth_ties"] = c.depth_ties;
  j["dist_rms_m"] = c.dist_rms_m;
  j["cross_depth_ties"] = c.cross_depth_ties;
  j["cross_dist_rms_m"] = c.cross_dist_rms_m;
  j["cross_dist_median_m"] = c.cross_dist_median_m;
  std::cout << j.dump(1) << "\n";
  return 0;
}
