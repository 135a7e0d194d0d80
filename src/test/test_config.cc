#include <gtest/gtest.h>

#include "hermes/core/config.h"

using namespace hermes;

TEST(Config, ReadsTypedKeysAndReportsUnused) {
  auto c = Config::fromString("distill:\n  strategy: milp\n  fixed_k: 100\n  typo_key: 3\n", "t.yaml");
  ASSERT_TRUE(c.ok()) << c.error();
  std::string s = "none";
  int k = 0;
  ASSERT_TRUE(c->getChoice("distill.strategy", {"milp", "none"}, &s));
  ASSERT_TRUE(c->get("distill.fixed_k", &k));
  EXPECT_EQ(s, "milp");
  EXPECT_EQ(k, 100);
  auto unused = c->unusedKeys();
  ASSERT_EQ(unused.size(), 1u);
  EXPECT_EQ(unused[0], "distill.typo_key");
}

TEST(Config, WrongTypeNamesKeyAndFile) {
  auto c = Config::fromString("a:\n  b: hello\n", "my.yaml");
  ASSERT_TRUE(c.ok());
  double v = 1.0;
  Status s = c->get("a.b", &v);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("a.b"), std::string::npos);
  EXPECT_NE(s.error().find("my.yaml"), std::string::npos);
  EXPECT_EQ(v, 1.0);
}

TEST(Config, BadChoiceAndBrokenYaml) {
  auto c = Config::fromString("x: {", "broken.yaml");
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.error().find("broken.yaml"), std::string::npos);
  auto d = Config::fromString("", "empty");
  ASSERT_TRUE(d.ok());
  ASSERT_TRUE(d->applyOverride("distill.strategy=magic"));
  std::string s = "milp";
  EXPECT_FALSE(d->getChoice("distill.strategy", {"milp", "none"}, &s).ok());
  EXPECT_FALSE(d->applyOverride("novalue").ok());
}

TEST(Config, MissingFileNamesPath) {
  auto c = Config::fromFile("/nonexistent/hermes.yaml");
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.error().find("/nonexistent/hermes.yaml"), std::string::npos);
}

TEST(Config, WriterRoundTrip) {
  ConfigWriter w;
  w.set("distill.strategy", std::string("milp"));
  w.set("distill.eta", 0.8);
  w.set("link.rate", 10);
  w.set("top", true);
  auto c = Config::fromString(w.yaml(), "written");
  ASSERT_TRUE(c.ok()) << c.error() << "\n" << w.yaml();
  std::string s;
  double eta = 0;
  int rate = 0;
  bool top = false;
  ASSERT_TRUE(c->get("distill.strategy", &s));
  ASSERT_TRUE(c->get("distill.eta", &eta));
  ASSERT_TRUE(c->get("link.rate", &rate));
  ASSERT_TRUE(c->get("top", &top));
  EXPECT_EQ(s, "milp");
  EXPECT_DOUBLE_EQ(eta, 0.8);
  EXPECT_EQ(rate, 10);
  EXPECT_TRUE(top);
}
