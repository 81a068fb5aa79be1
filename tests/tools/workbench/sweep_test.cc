// The sweep file: parsing, refusals, the cells and the m2s_client command line of each.
#include <algorithm>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "m2s/workbench/sweep.h"

namespace m2s::workbench {
namespace {

using nlohmann::json;

json TwoMethods() {
  return json::parse(R"({
    "methods": [{"name": "vertex"}, {"name": "orb", "front_end": "orb"},
                {"name": "pnp", "plugin": "pnp_odometry", "plugin_config": "cfg/pnp.json"}],
    "scenes": [{"name": "room"}, {"name": "house", "mesh": "meshes/house.obj",
                "trajectory": "/abs/walk.tum", "duration_s": 5}],
    "fps": [30, 60], "noise_px": [0, 0.5], "outlier_ids": [0.01]})");
}

bool Has(const std::vector<std::string>& args, const std::string& flag, const std::string& value) {
  for (size_t i = 0; i + 1 < args.size(); ++i)
    if (args[i] == flag && args[i + 1] == value) return true;
  return false;
}

bool HasFlag(const std::vector<std::string>& args, const std::string& flag) {
  return std::find(args.begin(), args.end(), flag) != args.end();
}

TEST(SweepConfig, ParsesAndResolvesPathsAgainstTheFilesFolder) {
  Expected<SweepConfig> config = ParseSweepConfig(TwoMethods(), "/data/sweeps");
  ASSERT_TRUE(config) << config.error();
  ASSERT_EQ(config->methods.size(), 3u);
  EXPECT_EQ(config->methods[1].front_end, "orb");
  EXPECT_EQ(config->methods[2].plugin, "pnp_odometry");  // a name stays a name
  EXPECT_EQ(config->methods[2].plugin_config, "/data/sweeps/cfg/pnp.json");
  EXPECT_EQ(config->scenes[1].mesh, "/data/sweeps/meshes/house.obj");
  EXPECT_EQ(config->scenes[1].trajectory, "/abs/walk.tum");
  EXPECT_EQ(config->scenes[0].mesh, "");
  EXPECT_EQ(config->fps, (std::vector<double>{30, 60}));
  EXPECT_EQ(config->outlier_ids, (std::vector<double>{0.01}));
}

TEST(SweepConfig, RefusesMistakesWithTheirPlace) {
  struct Case {
    const char* text;
    const char* message_part;
  };
  const Case cases[] = {
      {R"({"methods": [{"name": "a"}], "scenes": [{"name": "s"}], "fsp": [30]})", "\"fsp\""},
      {R"({"methods": [{"name": "a", "frontend": "orb"}], "scenes": [{"name": "s"}]})",
       "methods[0]"},
      {R"({"methods": [], "scenes": [{"name": "s"}]})", "at least one method"},
      {R"({"methods": [{"name": "a"}, {"name": "a"}], "scenes": [{"name": "s"}]})", "twice"},
      {R"({"methods": [{"name": "a b"}], "scenes": [{"name": "s"}]})", "a b"},
      {R"({"methods": [{"name": "a", "front_end": "sift"}], "scenes": [{"name": "s"}]})",
       "front_end"},
      {R"({"methods": [{"name": "a"}], "scenes": [{"name": "s"}], "fps": [0]})", "fps"},
      {R"({"methods": [{"name": "a"}], "scenes": [{"name": "s"}], "noise_px": [-1]})", "noise_px"},
      {R"({"methods": [{"name": "a"}], "scenes": [{"name": "s", "duration_s": "x"}]})",
       "wrong type"},
      {R"({"scenes": [{"name": "s"}]})", "\"methods\""},
  };
  for (const Case& c : cases) {
    Expected<SweepConfig> config = ParseSweepConfig(json::parse(c.text), "/tmp");
    ASSERT_FALSE(config) << c.text;
    EXPECT_NE(config.error().find(c.message_part), std::string::npos)
        << c.text << " -> " << config.error();
  }
}

TEST(SweepConfig, ReadRefusesMissingAndInvalidFiles) {
  Expected<SweepConfig> missing = ReadSweepConfig("/nonexistent/sweep.json");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().find("/nonexistent/sweep.json"), std::string::npos);
}

TEST(SweepCells, EveryCombinationOnceWithUniqueNames) {
  Expected<SweepConfig> config = ParseSweepConfig(TwoMethods(), "/d");
  ASSERT_TRUE(config);
  const std::vector<Cell> cells = ExpandCells(*config);
  ASSERT_EQ(cells.size(), 3u * 2u * 2u * 2u * 1u);
  std::vector<std::string> names;
  for (const Cell& c : cells) names.push_back(c.Name(*config));
  std::sort(names.begin(), names.end());
  EXPECT_EQ(std::unique(names.begin(), names.end()), names.end());
  EXPECT_EQ(cells[0].Name(*config), "vertex__room__30fps__n0__o0.01");
  EXPECT_EQ(cells.back().Name(*config), "pnp__house__60fps__n0.5__o0.01");
}

TEST(SweepCells, ImageFrontEndsTakeNoFeatureNoise) {
  SweepConfig config = *ParseSweepConfig(TwoMethods(), "/d");
  config.outlier_ids = {0.0};
  const Cell orb_clean{1, 0, 30, 0.0, 0.0}, orb_noisy{1, 0, 30, 0.5, 0.0};
  const Cell vertex_noisy{0, 0, 30, 0.5, 0.0};
  EXPECT_EQ(SkipReason(config, orb_clean), "");
  EXPECT_NE(SkipReason(config, orb_noisy), "");
  EXPECT_EQ(SkipReason(config, vertex_noisy), "");
}

TEST(SweepCells, ClientArgumentsCarryTheCell) {
  const SweepConfig config = *ParseSweepConfig(TwoMethods(), "/d");
  const std::vector<std::string> vertex = ClientArguments(config, {0, 1, 60, 0.5, 0.01}, "/o/x");
  EXPECT_TRUE(HasFlag(vertex, "--on-device"));
  EXPECT_TRUE(HasFlag(vertex, "--fast"));
  EXPECT_TRUE(HasFlag(vertex, "--occlusion"));
  EXPECT_TRUE(Has(vertex, "--fps", "60"));
  EXPECT_TRUE(Has(vertex, "--out", "/o/x"));
  EXPECT_TRUE(Has(vertex, "--mesh", "/d/meshes/house.obj"));
  EXPECT_TRUE(Has(vertex, "--trajectory", "/abs/walk.tum"));
  EXPECT_TRUE(Has(vertex, "--duration", "5"));
  EXPECT_TRUE(Has(vertex, "--noise-px", "0.5"));
  EXPECT_TRUE(Has(vertex, "--outlier-ids", "0.01"));
  EXPECT_FALSE(HasFlag(vertex, "--method"));
  EXPECT_FALSE(HasFlag(vertex, "--front-end"));

  const std::vector<std::string> pnp = ClientArguments(config, {2, 0, 30, 0.0, 0.0}, "/o/y");
  EXPECT_TRUE(Has(pnp, "--method", "pnp_odometry"));
  EXPECT_TRUE(Has(pnp, "--method-config", "/d/cfg/pnp.json"));
  EXPECT_FALSE(HasFlag(pnp, "--mesh"));  // the default scene
  EXPECT_FALSE(HasFlag(pnp, "--noise-px"));

  const std::vector<std::string> orb = ClientArguments(config, {1, 0, 30, 0.0, 0.0}, "/o/z");
  EXPECT_TRUE(Has(orb, "--front-end", "orb"));
}

}  // namespace
}  // namespace m2s::workbench
