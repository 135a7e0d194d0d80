// hermes_bench_wire: encode/decode speed and byte accounting of the submap wire
// format on a typical synthetic submap (10 keyframes x 800 keypoints, 3000
// landmarks), with and without zstd, plus a least-squares fit of the byte model
// bytes ≈ c0 + c_KF·N_KF + c_obs·obs + c_LM·N_LM over varied submaps.
// Prints JSON to stdout (and to --json FILE).
#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <string>

#include "hermes/core/wire_format.h"
#include "hermes/core/wire_synthetic.h"
#include "hermes_help/hermes_bench_wire.h"  // tools/help/hermes_bench_wire.txt

using namespace hermes;
using Json = nlohmann::json;

namespace {

double now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

/// Runs f repeatedly for about `seconds`; returns seconds per call.
template <class F>
double timePerCall(double seconds, F&& f) {
  f();  // warm up
  int calls = 0;
  const double t0 = now();
  double t = t0;
  do {
    f();
    ++calls;
    t = now();
  } while (t - t0 < seconds);
  return (t - t0) / calls;
}

Json measure(const Submap& s, const WireOptions& o, double seconds) {
  WireStats st;
  auto frame = encodeSubmap(s, o, &st);
  if (!frame.ok()) {
    std::fprintf(stderr, "hermes_bench_wire: %s\n", frame.error().c_str());
    std::exit(1);
  }
  const double t_enc = timePerCall(seconds, [&] { (void)encodeSubmap(s, o); });
  bool ok = true;
  const double t_dec = timePerCall(seconds, [&] { ok = ok && decodeSubmap(frame.value()).ok(); });
  if (!ok) {
    std::fprintf(stderr, "hermes_bench_wire: decode failed\n");
    std::exit(1);
  }
  const double t_peek =
      timePerCall(seconds / 4, [&] { (void)peekFrame(frame->data(), frame->size()); });
  const double mb = static_cast<double>(st.total) / 1e6;  // speeds on uncompressed bytes
  Json j;
  j["zstd"] = o.zstd;
  if (o.zstd) j["zstd_level"] = o.zstd_level;
  j["frame_bytes"] = frame->size();
  j["uncompressed_bytes"] = st.total;
  j["compression_ratio"] = static_cast<double>(st.total) / frame->size();
  j["encode_ms"] = 1e3 * t_enc;
  j["decode_ms"] = 1e3 * t_dec;
  j["peek_us"] = 1e6 * t_peek;
  j["encode_MBps"] = mb / t_enc;
  j["decode_MBps"] = mb / t_dec;
  return j;
}

/// Least-squares fit of frame bytes on [1, N_KF, obs, N_LM] over varied submaps.
Json fitByteModel() {
  std::vector<Eigen::Vector4d> rows;
  std::vector<double> bytes;
  for (int kfs : {4, 8, 12, 16})
    for (int lms : {500, 1500, 3000})
      for (double p : {0.2, 0.5}) {
        SyntheticSubmapOptions o;
        o.keyframes = kfs;
        o.landmarks = lms;
        o.observe_probability = p;
        o.seed = static_cast<std::uint64_t>(kfs * 1000 + lms) + (p > 0.3);
        const Submap s = makeSyntheticSubmap(o);
        rows.emplace_back(1.0, kfs, static_cast<double>(s.observationCount()), lms);
        bytes.push_back(static_cast<double>(encodedSizeUncompressed(s)));
      }
  Eigen::MatrixXd A(rows.size(), 4);
  Eigen::VectorXd b(rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    A.row(i) = rows[i].transpose();
    b(i) = bytes[i];
  }
  const Eigen::Vector4d c = A.colPivHouseholderQr().solve(b);
  const Eigen::VectorXd rel = ((A * c - b).array() / b.array()).abs();
  Json j;
  j["keypoints_per_keyframe"] = 800;
  j["samples"] = rows.size();
  j["c0"] = c(0);
  j["c_KF"] = c(1);
  j["c_obs"] = c(2);
  j["c_LM"] = c(3);
  j["max_relative_error"] = rel.maxCoeff();
  return j;
}

}  // namespace

int main(int argc, char** argv) {
  std::string json_path;
  double seconds = 0.5;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--help" || a == "-h") {
      std::fputs(hermes_help::kText, stdout);
      return 0;
    } else if (a == "--json" && i + 1 < argc) {
      json_path = argv[++i];
    } else if (a == "--seconds" && i + 1 < argc) {
      seconds = std::atof(argv[++i]);
      if (!(seconds > 0)) {
        std::fprintf(stderr, "hermes_bench_wire: --seconds needs a positive number\n");
        return 2;
      }
    } else {
      std::fprintf(stderr, "hermes_bench_wire: unknown argument '%s' (see --help)\n", a.c_str());
      return 2;
    }
  }

  SyntheticSubmapOptions o;  // defaults: 10 KFs x 800 keypoints, 3000 landmarks
  const Submap s = makeSyntheticSubmap(o);
  const WireStats st = wireStats(s);
  const std::size_t n_kp = 800u * 10u;
  const std::size_t n_obs = s.observationCount();

  Json out;
  out["benchmark"] = "wire";
  out["submap"] = {{"keyframes", s.keyframes.size()},
                   {"keypoints", n_kp},
                   {"landmarks", s.landmarks.size()},
                   {"observations", n_obs},
                   {"odometry_edges", s.odometry.size()}};
  out["bytes"] = {{"total", st.total},         {"header", st.header},
                  {"keyframes", st.keyframes}, {"keypoints", st.keypoints},
                  {"descriptors", st.descriptors}, {"landmarks", st.landmarks},
                  {"observations", st.observations}, {"odometry", st.odometry}};
  out["bytes_per"] = {
      {"keyframe_fixed", static_cast<double>(st.keyframes) / s.keyframes.size()},
      {"keyframe_with_keypoints_and_odometry",
       static_cast<double>(st.keyframes + st.keypoints + st.descriptors + st.odometry) /
           s.keyframes.size()},
      {"keypoint_with_descriptor", static_cast<double>(st.keypoints + st.descriptors) / n_kp},
      {"landmark", static_cast<double>(st.landmarks) / s.landmarks.size()},
      {"observation", static_cast<double>(st.observations) / n_obs},
      {"odometry_edge", static_cast<double>(st.odometry) / s.odometry.size()}};
  const double t_size = timePerCall(seconds / 4, [&] { (void)encodedSizeUncompressed(s); });
  out["encodedSizeUncompressed_us"] = 1e6 * t_size;

  Json runs = Json::array();
  runs.push_back(measure(s, WireOptions{false, 3}, seconds));
  for (int level : {1, 3, 9}) runs.push_back(measure(s, WireOptions{true, level}, seconds));
  out["runs"] = runs;
  out["byte_model_fit"] = fitByteModel();

  const std::string text = out.dump(2);
  std::cout << text << std::endl;
  if (!json_path.empty()) {
    std::ofstream f(json_path);
    if (!(f << text << '\n')) {
      std::fprintf(stderr, "hermes_bench_wire: cannot write '%s'\n", json_path.c_str());
      return 1;
    }
  }
  return 0;
}
