// The scene-diversity benchmark in small: composed scenes (scene_corpus.h) and short SLAM runs
// on a room furnished with meshes of assimp-testmodels (tests/data/scenes/testmodels.json), for
// head, hand-held and drone motion. Bounds are set from measured runs (Release, 4 s at 30 fps,
// deterministic); cases that fail today carry DISABLED_ and the measured failure.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>

#include <gtest/gtest.h>

#include "accuracy_run.h"
#include "scene_corpus.h"

namespace m2s::bench {
namespace {

const char kMeshRoot[] = "/usr/share/assimp/models";  // Debian's assimp-testmodels
const std::string kManifest = std::string(M2S_SOURCE_DIR) + "/tests/data/scenes/testmodels.json";

bool HaveTestModels() { return std::filesystem::exists(std::string(kMeshRoot) + "/PLY/Wuson.ply"); }

TEST(SceneCorpusTest, PlacesPropsBySizePositionAndYaw) {
  if (!HaveTestModels()) GTEST_SKIP() << "assimp-testmodels not installed";
  SceneSpec spec;
  spec.name = "two props";
  spec.room_size = Eigen::Vector3d(4.0, 3.0, 2.5);
  PropSpec table;
  table.name = "table";
  table.box_size = Eigen::Vector3d(1.0, 0.5, 0.7);
  table.position = Eigen::Vector3d(0.5, -0.5, 0.0);
  table.target = true;
  PropSpec wuson;
  wuson.name = "Wuson";
  wuson.mesh = "PLY/Wuson.ply";
  wuson.size_m = 0.4;
  wuson.position = Eigen::Vector3d(0.5, -0.5, 0.7);
  wuson.yaw_deg = 90.0;
  wuson.obstacle = false;
  spec.props = {table, wuson};
  Expected<ComposedScene> composed = ComposeScene(spec, kMeshRoot);
  ASSERT_TRUE(composed.ok()) << composed.error();

  ASSERT_EQ(composed->parts.size(), 3u);
  EXPECT_EQ(composed->parts[0].num_vertices, 8u);  // the room: one quad per wall
  EXPECT_EQ(composed->parts[1].num_vertices, 8u);
  const ComposedScene::Part& mesh = composed->parts[2];
  EXPECT_EQ(mesh.first_vertex, 16u);
  EXPECT_EQ(composed->scene.num_vertices(), 16u + mesh.num_vertices);
  Eigen::AlignedBox3f bounds;
  for (uint32_t i = mesh.first_vertex; i < mesh.first_vertex + mesh.num_vertices; ++i) {
    bounds.extend(composed->scene.positions[i]);
  }
  EXPECT_NEAR(bounds.sizes().maxCoeff(), 0.4f, 1e-5f);
  EXPECT_NEAR(bounds.min().z(), 0.7f, 1e-5f);
  EXPECT_NEAR(bounds.center().x(), 0.5f, 1e-5f);
  EXPECT_NEAR(bounds.center().y(), -0.5f, 1e-5f);

  EXPECT_TRUE(composed->layout.room.isApprox(
      Eigen::AlignedBox3d(Eigen::Vector3d(-2.0, -1.5, 0.0), Eigen::Vector3d(2.0, 1.5, 2.5))));
  ASSERT_EQ(composed->layout.obstacles.size(), 1u);  // the table only
  EXPECT_LT((composed->layout.obstacles[0].min() - Eigen::Vector2d(0.0, -0.75)).norm(), 1e-6);
  EXPECT_LT((composed->layout.obstacles[0].max() - Eigen::Vector2d(1.0, -0.25)).norm(), 1e-6);
  ASSERT_EQ(composed->targets.size(), 1u);
  EXPECT_LT((composed->targets[0] - Eigen::Vector3d(0.5, -0.5, 0.35)).norm(), 1e-6);
  for (uint32_t index : composed->scene.triangles) EXPECT_LT(index, composed->scene.num_vertices());
}

TEST(SceneCorpusTest, ReadsTheManifestAndNamesErrors) {
  Expected<std::vector<SceneSpec>> specs = ReadSceneManifest(kManifest);
  ASSERT_TRUE(specs.ok()) << specs.error();
  ASSERT_EQ(specs->size(), 1u);
  EXPECT_EQ((*specs)[0].name, "testmodels-room");
  EXPECT_GT((*specs)[0].props.size(), 10u);

  Expected<std::vector<SceneSpec>> missing = ReadSceneManifest("/nonexistent/scenes.json");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("/nonexistent/scenes.json"), std::string::npos);

  const std::string bad = testing::TempDir() + "/bad_scenes.json";
  std::ofstream(bad) << R"({"scenes": [{"name": "x", "props": [{"box": [1, 2]}]}]})";
  Expected<std::vector<SceneSpec>> malformed = ReadSceneManifest(bad);
  ASSERT_FALSE(malformed.ok());
  EXPECT_NE(malformed.error().find("[x, y, z]"), std::string::npos) << malformed.error();

  SceneSpec spec;
  spec.name = "broken";
  PropSpec prop;
  prop.name = "ghost";
  prop.mesh = "no/such/mesh.obj";
  spec.props = {prop};
  Expected<ComposedScene> composed = ComposeScene(spec, kMeshRoot);
  ASSERT_FALSE(composed.ok());
  EXPECT_NE(composed.error().find("ghost"), std::string::npos) << composed.error();
}

class SceneRunTest : public testing::Test {
 protected:
  struct Bounds {
    int max_init_frames;
    int max_lost;
    double max_ate_rmse_m;
    double max_ate_max_m;
  };

  // Runs `duration_s` of `motion` at 30 fps on the testmodels room and checks the bounds
  // (`more_views_after_s`: Options::initializer.more_views_after_s, unset: the default).
  static void Run(const std::string& motion, bool noisy, bool occlusion, const Bounds& bounds,
                  double duration_s = kDurationS,
                  std::optional<double> more_views_after_s = std::nullopt) {
    if (!HaveTestModels()) GTEST_SKIP() << "assimp-testmodels not installed";
    Expected<std::vector<SceneSpec>> specs = ReadSceneManifest(kManifest);
    ASSERT_TRUE(specs.ok()) << specs.error();
    Expected<ComposedScene> composed = ComposeScene(specs->front(), kMeshRoot);
    ASSERT_TRUE(composed.ok()) << composed.error();
    Expected<Trajectory> trajectory = MakeMotion(motion, *composed, /*seed=*/1, duration_s);
    ASSERT_TRUE(trajectory.ok()) << trajectory.error();
    RunConfig config;
    config.fps = 30.0;
    config.noisy = noisy;
    config.occlusion = occlusion;
    config.min_visible_for_lost = kMinVisible;
    config.more_views_after_s = more_views_after_s;
    Expected<RunMetrics> m = RunAccuracy(composed->scene, Sequence{motion, *trajectory}, config);
    ASSERT_TRUE(m.ok()) << m.error();
    std::printf("%s: init %d, untracked %d, ATE RMSE %.4f mm, max %.4f mm, %d keyframes\n",
                motion.c_str(), m->init_frames, m->untracked, m->ate_rmse_m * 1e3,
                m->ate_max_m * 1e3, m->keyframes);
    EXPECT_EQ(m->frames, static_cast<int>(std::lround(duration_s * 30.0)) + 1);
    EXPECT_GT(m->median_visible, 500.0);
    EXPECT_LE(m->init_frames, bounds.max_init_frames);
    EXPECT_LE(m->untracked, bounds.max_lost);
    EXPECT_GE(m->ate_rmse_m, 0.0);
    EXPECT_LT(m->ate_rmse_m, bounds.max_ate_rmse_m);
    EXPECT_LT(m->ate_max_m, bounds.max_ate_max_m);
  }

  static constexpr double kDurationS = 4.0;
  static constexpr int kMinVisible = 20;
};

// Noise-free features: measured ATE RMSE 0.1 / 0.0 / 0.1 um, ATE max <= 0.4 um, no frame
// lost, and every frame has a pose: those before the map's second view are solved on it
// (each run prints its figures).
constexpr double kExactAteM = 5e-6;

TEST_F(SceneRunTest, HeadNoiseFree) { Run("head", false, false, {0, 0, kExactAteM, kExactAteM}); }

TEST_F(SceneRunTest, HandheldNoiseFree) {
  Run("handheld", false, false, {0, 0, kExactAteM, kExactAteM});
}

TEST_F(SceneRunTest, DroneNoiseFree) { Run("drone", false, false, {0, 0, kExactAteM, kExactAteM}); }

// The 20 s flight yaws from the dense models onto the bare walls at 0.25 m/s (frames 63-64):
// rotation-only poses, whose centre the one map point in view places moving on at the measured
// velocity. Measured: ATE RMSE 0.141 mm, max 3.1 mm (with those frames held at the reference
// keyframe's centre: 0.745 / 16.3 mm).
TEST_F(SceneRunTest, DroneNoiseFreeYawingOntoBareWalls) {
  Run("drone", false, false, {0, 0, 0.0003, 0.005}, /*duration_s=*/20.0);
}

// Noisy features (0.5 px, 1% wrong ids): measured ATE RMSE 0.53 mm, max 1.6 mm, none lost.
TEST_F(SceneRunTest, HandheldNoisy) { Run("handheld", true, false, {0, 0, 0.004, 0.025}); }

// Fails today: no two frames of the 121 pass the two-view initialisation's checks (over 20 s
// it initialises at frame 43, bench_scenes); the bound is the accuracy benchmark's noisy bar
// (5 mm).
TEST_F(SceneRunTest, DISABLED_HeadNoisy) { Run("head", true, false, {30, 0, 0.005, 0.025}); }

// Fails today: no two frames of the 121 pass the two-view initialisation's checks.
TEST_F(SceneRunTest, DISABLED_DroneNoisy) { Run("drone", true, false, {30, 0, 0.005, 0.025}); }

// The 20 s flight with two-view initialisation only: its second map (frames 540 and 561) is
// adjusted into the minimum that USAC's motion leads to, 1.0 degree of rotation from the truth,
// instead of RANSAC's at 5.6 degrees (docs/design/two_view_initialisation.md, item 6).
// Measured: ATE RMSE 13.6 mm, max 59.3 mm, 269 frames without a pose (a first map only at
// frame 382, on forward flight); with RANSAC's minimum, 112 mm and 475 mm.
TEST_F(SceneRunTest, DroneNoisyTakesTheLowestTwoViewMinimum) {
  Run("drone", true, false, {0, 280, 0.03, 0.12}, /*duration_s=*/20.0,
      /*more_views_after_s=*/-1.0);
}

// The same flight as initialised by default: after 3 s of refusals, the kept frames between
// frames 107 and 119 decide the motion the two views leave undetermined (item 7). Measured:
// ATE RMSE 8.2 mm, max 76.0 mm, 4 frames without a pose.
TEST_F(SceneRunTest, DroneNoisyInitialisesFromMoreViews) {
  Run("drone", true, false, {0, 30, 0.02, 0.12}, /*duration_s=*/20.0);
}

// Fails today: no two frames of the 121 pass the two-view initialisation's checks.
TEST_F(SceneRunTest, DISABLED_HeadNoisyOcclusion) {
  Run("head", true, true, {30, 0, 0.005, 0.025});
}

// Measured ATE RMSE 0.60 mm, max 1.6 mm, none lost.
TEST_F(SceneRunTest, HandheldNoisyOcclusion) { Run("handheld", true, true, {0, 0, 0.005, 0.025}); }

// Fails today: initialised from frames 0 and 13, then lost; the new map started 0.5 s later does
// not initialise before the run ends (62 frames lost) and the run ends without a map to
// evaluate (0 keyframes).
TEST_F(SceneRunTest, DISABLED_DroneNoisyOcclusion) {
  Run("drone", true, true, {30, 0, 0.005, 0.025});
}

}  // namespace
}  // namespace m2s::bench
