// The store behind `bench system --full`: finished runs are found again, an
// unfinished or damaged one is run again, another setup is refused by name.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include "hermes/system/bench_store.h"

namespace fs = std::filesystem;

namespace hermes::system {
namespace {

fs::path freshDir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / (name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  return d;
}

const nlohmann::json kSetup = {{"data", "mh_full"}, {"rate_hz", 20}, {"overrides", {"a=1"}}};

TEST(BenchStore, AFinishedRunIsFoundAgainAfterReopening) {
  const fs::path dir = freshDir("bench_store_resume");
  {
    auto store = BenchStore::open(dir.string(), kSetup);
    ASSERT_TRUE(store.ok()) << store.error();
    EXPECT_FALSE(store->find("raw_10").has_value());
    ASSERT_TRUE(store->save("raw_10", {{"ate_rmse_m", 0.012}, {"agents_merged", 5}}));
  }
  auto again = BenchStore::open(dir.string(), kSetup);
  ASSERT_TRUE(again.ok()) << again.error();
  auto row = again->find("raw_10");
  ASSERT_TRUE(row.has_value());
  EXPECT_DOUBLE_EQ((*row)["ate_rmse_m"].get<double>(), 0.012);
  EXPECT_FALSE(again->find("hermes_10").has_value());
  EXPECT_EQ(again->runDir("raw_10"), (dir / "raw_10").string());
  EXPECT_FALSE(fs::exists(dir / "raw_10" / "bench_row.json.tmp"));
  fs::remove_all(dir);
}

TEST(BenchStore, ARunWithoutARowOrWithADamagedRowIsRunAgain) {
  const fs::path dir = freshDir("bench_store_damaged");
  auto store = BenchStore::open(dir.string(), kSetup);
  ASSERT_TRUE(store.ok()) << store.error();
  fs::create_directories(dir / "hermes_0");  // a run killed before its row was written
  std::ofstream(dir / "hermes_0" / "metrics.json") << "{}";
  EXPECT_FALSE(store->find("hermes_0").has_value());
  fs::create_directories(dir / "hermes_2");
  std::ofstream(dir / "hermes_2" / "bench_row.json") << "{\"ate_rmse_m\": 0.0";  // cut short
  EXPECT_FALSE(store->find("hermes_2").has_value());
  fs::remove_all(dir);
}

TEST(BenchStore, AnotherSetupIsRefusedNamingTheKey) {
  const fs::path dir = freshDir("bench_store_setup");
  ASSERT_TRUE(BenchStore::open(dir.string(), kSetup).ok());
  nlohmann::json other = kSetup;
  other["overrides"] = {"a=2"};
  auto store = BenchStore::open(dir.string(), other);
  ASSERT_FALSE(store.ok());
  EXPECT_NE(store.error().find("overrides"), std::string::npos) << store.error();
  EXPECT_NE(store.error().find("a=2"), std::string::npos) << store.error();
  // A damaged setup.json is named too, never silently replaced.
  std::ofstream(dir / "setup.json") << "{";
  auto damaged = BenchStore::open(dir.string(), kSetup);
  ASSERT_FALSE(damaged.ok());
  EXPECT_NE(damaged.error().find("setup.json"), std::string::npos) << damaged.error();
  fs::remove_all(dir);
}

TEST(BenchStore, AFolderThatCannotBeMadeIsAnError) {
  const fs::path file = freshDir("bench_store_file");
  std::ofstream(file.string()) << "x";
  auto store = BenchStore::open((file / "sub").string(), kSetup);
  ASSERT_FALSE(store.ok());
  EXPECT_NE(store.error().find(file.string()), std::string::npos) << store.error();
  fs::remove(file);
}

}  // namespace
}  // namespace hermes::system
