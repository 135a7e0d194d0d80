// hermes_run end to end on the real micro dataset (40 EuRoC V1_01 pairs; the
// drone sits still, so the estimate must too) and its error cases.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "hermes/agent/run_config.h"
#include "hermes/system/system_params.h"
#include "hermes/core/evaluation.h"
#include "hermes/core/metrics.h"
#include "hermes/core/trajectory.h"

using namespace hermes;
namespace fs = std::filesystem;

namespace {

std::string runBinary() {
  return (fs::read_symlink("/proc/self/exe").parent_path().parent_path() / "bin" / "hermes_run")
      .string();
}

const std::string kMicro = std::string(HERMES_DATA_DIR) + "/euroc_V1_01_micro";

struct Outcome {
  int code = -1;
  std::string err;
};

/// Runs hermes_run with `args`; stderr captured into a file.
Outcome run(const std::string& args, const std::string& tag) {
  const std::string err_file = ::testing::TempDir() + "/hermes_run_" + tag + ".err";
  const int rc = std::system((runBinary() + " " + args + " >/dev/null 2>" + err_file).c_str());
  Outcome o;
  o.code = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  std::ifstream f(err_file);
  std::stringstream ss;
  ss << f.rdbuf();
  o.err = ss.str();
  return o;
}

std::string outDir(const std::string& tag) {
  const std::string d = ::testing::TempDir() + "/hermes_run_out_" + tag;
  fs::remove_all(d);
  return d;
}

}  // namespace

TEST(RunCli, MicroDatasetStaticDroneStaysStill) {
  ASSERT_TRUE(fs::exists(runBinary())) << "build hermes_run first: " << runBinary();
  const std::string out = outDir("micro");
  const Outcome o = run("--dataset " + kMicro + " --out " + out + " --no-server", "micro");
  ASSERT_EQ(o.code, 0) << o.err;

  // metrics.json holds every DESIGN §7 field.
  std::ifstream mf(out + "/metrics.json");
  ASSERT_TRUE(mf.good());
  const nlohmann::json j = nlohmann::json::parse(mf);
  for (const char* key : {"ate_rmse_m", "per_agent", "bytes_total", "kBps_mean", "kBps_peak",
                          "loops_accepted", "loops_rejected", "agents_merged", "timings_ms"})
    EXPECT_TRUE(j.contains(key)) << key;
  ASSERT_EQ(j["per_agent"].size(), 1u);
  const nlohmann::json& a = j["per_agent"][0];
  for (const char* key : {"agent", "ate_rmse_m", "lost_rate", "keyframes", "landmarks", "bytes",
                          "submaps_sent", "submaps_applied", "submaps_deferred"})
    EXPECT_TRUE(a.contains(key)) << key;
  EXPECT_EQ(a["agent"], "euroc_V1_01_micro");
  EXPECT_EQ(a["lost_rate"].get<double>(), 0.0);
  EXPECT_GE(a["keyframes"].get<int>(), 1);
  EXPECT_GT(a["landmarks"].get<int>(), 100);
  EXPECT_EQ(a["bytes"].get<int>(), 0);
  EXPECT_EQ(a["submaps_sent"].get<int>(), 0);
  ASSERT_TRUE(a["ate_rmse_m"].is_number());
  EXPECT_LT(a["ate_rmse_m"].get<double>(), 0.01);
  EXPECT_TRUE(j["timings_ms"].contains("track"));
  EXPECT_EQ(j["timings_ms"]["track"]["count"].get<int>(), 40);
  auto parsed = readMetricsJson(out + "/metrics.json");
  ASSERT_TRUE(parsed.ok()) << parsed.error();

  // The trajectory: every frame, and the drone never moves (< 1 cm, < 0.5 deg).
  auto traj = readTumTrajectory(out + "/trajectories/euroc_V1_01_micro_raw.tum");
  ASSERT_TRUE(traj.ok()) << traj.error();
  ASSERT_EQ(traj->size(), 40u);
  const SE3& first = traj->front().T_W_B;
  double max_move = 0, max_turn_deg = 0;
  for (const StampedPose& p : *traj) {
    max_move = std::max(max_move, (p.T_W_B.translation() - first.translation()).norm());
    max_turn_deg =
        std::max(max_turn_deg, eval::relativeAngle(first.quat(), p.T_W_B.quat()) * 180 / M_PI);
  }
  std::printf("static drone: max move %.4f m, max turn %.4f deg\n", max_move, max_turn_deg);
  EXPECT_LT(max_move, 0.01);
  EXPECT_LT(max_turn_deg, 0.5);

  // config_used.yaml holds the modules' keys.
  std::ifstream cf(out + "/config_used.yaml");
  std::stringstream cs;
  cs << cf.rdbuf();
  for (const char* key : {"distill:", "strategy:", "keyframe:", "uplink:", "dataset:", "eval:",
                          "server:", "link:"})
    EXPECT_NE(cs.str().find(key), std::string::npos) << key;
}

TEST(RunCli, MaxFramesAndSetOverride) {
  const std::string out = outDir("short");
  const Outcome o = run("--dataset " + kMicro + " --out " + out +
                            " --no-server --max-frames 10 --set distill.strategy=greedy_logdet",
                        "short");
  ASSERT_EQ(o.code, 0) << o.err;
  auto traj = readTumTrajectory(out + "/trajectories/euroc_V1_01_micro_raw.tum");
  ASSERT_TRUE(traj.ok()) << traj.error();
  EXPECT_EQ(traj->size(), 10u);
  std::ifstream cf(out + "/config_used.yaml");
  std::stringstream cs;
  cs << cf.rdbuf();
  EXPECT_NE(cs.str().find("greedy_logdet"), std::string::npos);
}

TEST(RunCli, ErrorsExitTwoNamingTheCulprit) {
  const std::string out = outDir("errors");
  const std::string missing = ::testing::TempDir() + "/no_such_dataset_dir";
  Outcome o = run("--dataset " + missing + " --out " + out + " --no-server", "missing");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find(missing), std::string::npos) << o.err;

  o = run("--dataset " + kMicro + " --out " + out + " --no-server --set distill.stratgy=milp",
          "unknown");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("distill.stratgy"), std::string::npos) << o.err;

  o = run("--dataset " + kMicro + " --out " + out + " --no-server --set distill.strategy=bogus",
          "badvalue");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("distill.strategy"), std::string::npos) << o.err;

  const std::string bad_cfg = ::testing::TempDir() + "/hermes_run_bad.yaml";
  {
    std::ofstream f(bad_cfg);
    f << "distill:\n  strategy: [unclosed\n";
  }
  o = run("--dataset " + kMicro + " --out " + out + " --no-server --config " + bad_cfg, "badcfg");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find(bad_cfg), std::string::npos) << o.err;

  const std::string no_cfg = ::testing::TempDir() + "/hermes_run_no_such.yaml";
  o = run("--dataset " + kMicro + " --out " + out + " --no-server --config " + no_cfg, "nocfg");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find(no_cfg), std::string::npos) << o.err;

  o = run("--dataset " + kMicro + " --dataset " + kMicro + " --out " + out + " --no-server",
          "multi");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("one --dataset"), std::string::npos) << o.err;
  o = run("--dataset " + kMicro + " --out " + out + " --bandwidth 0", "zerobw");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("--bandwidth"), std::string::npos) << o.err;
  o = run("--dataset " + kMicro + " --out " + out + " --link-trace /no/such/trace.csv", "notrace");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("/no/such/trace.csv"), std::string::npos) << o.err;
  o = run("--dataset " + kMicro + " --out " + out + " --scenario /no/such/scenario.txt", "noscenario");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("scenario file /no/such/scenario.txt does not exist"), std::string::npos) << o.err;
  const std::string scenario = ::testing::TempDir() + "/hermes_run_bad_scenario.txt";
  std::ofstream(scenario) << "link euroc_V1_01_micro server const:5\nlink drone_9 server const:5\n";
  o = run("--dataset " + kMicro + " --out " + out + " --scenario " + scenario, "badscenario");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find(scenario + ":2: unknown robot 'drone_9' (robots of this run: euroc_V1_01_micro)"),
            std::string::npos)
      << o.err;
  o = run("--dataset " + kMicro + " --out " + out + " --scenario " + scenario + " --bandwidth 5", "twolinks");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("exclude each other"), std::string::npos) << o.err;
  o = run("--dataset " + kMicro + " --out " + out + " --set link.loss=1.5", "badloss");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("link.loss"), std::string::npos) << o.err;

  o = run("--out " + out, "nodataset");
  EXPECT_EQ(o.code, 2);
  o = run("--help", "help");
  EXPECT_EQ(o.code, 0);
  EXPECT_FALSE(fs::exists(out + "/metrics.json"));  // no failed run wrote results
}

TEST(RunConfig, ShippedConfigsReadCleanly) {
  for (const char* name : {"hermes.yaml", "fault_injection.yaml", "euroc_stereo.yaml", "tum_rgbd.yaml"}) {
    const std::string path = std::string(HERMES_SOURCE_DIR) + "/config/" + name;
    auto config = loadConfig(path, {});
    ASSERT_TRUE(config.ok()) << config.error();
    auto params = system::readSystemParams(*config);
    EXPECT_TRUE(params.ok()) << name << ": " << params.error();
  }
  // hermes.yaml holds exactly the defaults: config_used of defaults reads back
  // to the same text.
  auto config = loadConfig(std::string(HERMES_SOURCE_DIR) + "/config/hermes.yaml", {});
  ASSERT_TRUE(config.ok());
  auto params = system::readSystemParams(*config);
  ASSERT_TRUE(params.ok()) << params.error();
  EXPECT_EQ(params->yaml(), system::SystemParams().yaml());
  // ... and every key a module reads is in it or, for the fault injection and
  // testing hooks, in config/fault_injection.yaml (ctest configuration_doc_is_current
  // checks the same, with the keys' comments).
  auto all = Config::fromString(system::SystemParams().yaml(), "defaults");
  auto shipped = Config::fromFile(std::string(HERMES_SOURCE_DIR) + "/config/hermes.yaml");
  auto hooks = Config::fromFile(std::string(HERMES_SOURCE_DIR) + "/config/fault_injection.yaml");
  ASSERT_TRUE(all.ok() && shipped.ok() && hooks.ok());
  for (const std::string& key : all->unusedKeys())
    EXPECT_NE(shipped->has(key), hooks->has(key)) << key << ": in exactly one of config/hermes.yaml and "
                                                  << "config/fault_injection.yaml";
  for (const char* hook : {"corrupt.kind", "system.server_restart_at", "system.agent_reset",
                           "system.tracking_record_dir", "system.tracking_replay_dir"})
    EXPECT_TRUE(hooks->has(hook) && !shipped->has(hook)) << hook;

  auto bad = loadConfig("", {"tracker.min_trackd=5"});
  ASSERT_TRUE(bad.ok());
  auto p = system::readSystemParams(*bad);
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.error().find("tracker.min_trackd"), std::string::npos) << p.error();
}

TEST(RunCli, RecordThenReplayTracking) {
  const std::string tracking = outDir("tracking_dir");
  const std::string live = outDir("tracking_live"), replay = outDir("tracking_replay");
  Outcome o = run("--dataset " + kMicro + " --out " + live + " --no-plots --max-frames 40 --record-tracking " +
                      tracking, "track_rec");
  ASSERT_EQ(o.code, 0) << o.err;
  ASSERT_TRUE(fs::exists(tracking + "/euroc_V1_01_micro.htrk"));
  o = run("--dataset " + kMicro + " --out " + replay + " --no-plots --max-frames 40 --replay-tracking " +
              tracking, "track_replay");
  ASSERT_EQ(o.code, 0) << o.err;
  auto metrics = [](const std::string& dir) {
    std::ifstream f(dir + "/metrics.json");
    return nlohmann::json::parse(f, nullptr, false);
  };
  const nlohmann::json a = metrics(live), b = metrics(replay);
  ASSERT_FALSE(a.is_discarded() || b.is_discarded());
  EXPECT_EQ(a["bytes_total"], b["bytes_total"]);
  EXPECT_EQ(a["per_agent"][0]["raw_ate_rmse_m"], b["per_agent"][0]["raw_ate_rmse_m"]);
  EXPECT_EQ(a["per_agent"][0]["keyframes"], b["per_agent"][0]["keyframes"]);

  o = run("--dataset " + kMicro + " --out " + replay + " --max-frames 30 --replay-tracking " + tracking,
          "track_stale");
  EXPECT_EQ(o.code, 2);
  EXPECT_NE(o.err.find("'frames' differs: recorded '40', this run '30'"), std::string::npos) << o.err;
  // Both: the agent whose recording fits is replayed, one that does not
  // (other frames here) is tracked and recorded into the record folder.
  const std::string again = outDir("tracking_again");
  o = run("--dataset " + kMicro + " --out " + replay + " --no-plots --max-frames 40 --replay-tracking " +
              tracking + " --record-tracking " + again, "track_both_fit");
  ASSERT_EQ(o.code, 0) << o.err;
  EXPECT_FALSE(fs::exists(again + "/euroc_V1_01_micro.htrk"));
  EXPECT_EQ(metrics(replay)["bytes_total"], a["bytes_total"]);
  o = run("--dataset " + kMicro + " --out " + replay + " --no-plots --max-frames 30 --replay-tracking " +
              tracking + " --record-tracking " + again, "track_both_stale");
  ASSERT_EQ(o.code, 0) << o.err;
  EXPECT_TRUE(fs::exists(again + "/euroc_V1_01_micro.htrk"));
}
