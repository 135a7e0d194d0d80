// Command-line contract of hermes_eval (DESIGN §8): exit codes and metrics JSON.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <climits>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "hermes/core/metrics.h"

using namespace hermes;

namespace {

std::string evalExe() {
  char buf[PATH_MAX];
  const ssize_t n = ::readlink("/proc/self/exe", buf, sizeof(buf) - 1);
  if (n <= 0) return "";
  std::string self(buf, size_t(n));
  return self.substr(0, self.find_last_of('/')) + "/../bin/hermes_eval";
}

/// Runs hermes_eval with args; returns the exit code, stdout in *out.
int run(const std::string& args, std::string* out = nullptr) {
  const std::string dir = ::testing::TempDir();
  const std::string cmd =
      evalExe() + " " + args + " >" + dir + "/cli_out.txt 2>" + dir + "/cli_err.txt";
  const int rc = std::system(cmd.c_str());
  if (out) {
    std::ifstream in(dir + "/cli_out.txt");
    std::stringstream ss;
    ss << in.rdbuf();
    *out = ss.str();
  }
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

}  // namespace

TEST(EvalCli, ExitCodesAndJson) {
  if (::access(evalExe().c_str(), X_OK) != 0)
    GTEST_SKIP() << "hermes_eval not built next to the tests (" << evalExe() << ")";
  const std::string dir = ::testing::TempDir();
  Trajectory gt, est;
  for (int i = 0; i < 100; ++i) {
    const double t = 100.0 + 0.1 * i;
    gt.push_back({t, SE3(expSO3(Vec3(0, 0, 0.2 * t)), Vec3(std::cos(t), std::sin(t), 0.1 * t))});
    // Every second estimate pose is 0.1 m off in z.
    est.push_back({t, SE3(gt.back().T_W_B.quat(),
                          gt.back().T_W_B.translation() + Vec3(0, 0, i % 2 ? 0.1 : 0.0))});
  }
  const std::string g = dir + "/cli_gt.txt", e = dir + "/cli_est.txt";
  ASSERT_TRUE(writeTumTrajectory(g, gt));
  ASSERT_TRUE(writeTumTrajectory(e, est));

  EXPECT_EQ(run("--help"), 0);
  EXPECT_EQ(run("--gt " + g), 2);                              // no --est
  EXPECT_EQ(run("--gt " + g + " --est " + e + " --gt " + g), 2);  // counts differ
  EXPECT_EQ(run("--gt " + g + " --est " + e + " --frobnicate"), 2);
  EXPECT_EQ(run("--gt " + g + " --est " + dir + "/missing.txt"), 2);
  EXPECT_EQ(run("--gt " + g + " --est " + e + " --align affine"), 2);
  Trajectory late = est;
  for (auto& p : late) p.t += 50;
  ASSERT_TRUE(writeTumTrajectory(dir + "/cli_late.txt", late));
  EXPECT_EQ(run("--gt " + g + " --est " + dir + "/cli_late.txt"), 2);  // nothing matches

  const std::string json_path = dir + "/cli_metrics.json";
  ASSERT_EQ(run("--gt " + g + " --est " + e + " --align none --json " + json_path), 0);
  auto m = readMetricsJson(json_path);
  ASSERT_TRUE(m.ok()) << m.error();
  ASSERT_TRUE(m->ate_rmse_m.has_value());
  EXPECT_NEAR(*m->ate_rmse_m, 0.1 / std::sqrt(2.0), 1e-9);
  ASSERT_EQ(m->per_agent.size(), 1u);
  EXPECT_EQ(m->per_agent[0].agent, "cli_est");
  EXPECT_EQ(*m->per_agent[0].matched_poses, 100);

  std::string out;
  ASSERT_EQ(run("--gt " + g + " --est " + e + " --gt " + g + " --est " + g + " --json -", &out),
            0);
  auto j = nlohmann::json::parse(out, nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << out;
  auto two = metricsFromJson(j, "stdout");
  ASSERT_TRUE(two.ok()) << two.error();
  EXPECT_EQ(two->per_agent.size(), 2u);
  EXPECT_EQ(*two->matched_poses, 200);
}
