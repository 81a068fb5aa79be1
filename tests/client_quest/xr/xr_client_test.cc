// The real m2s_xr_client on the simulated OpenXR runtime, headless on llvmpipe: the app's
// world is the reference space it was asked for. The session lifecycle is in
// xr_lifecycle_test.cc; tracking accuracy and the overlay (asynchronous SLAM, real time) are in
// xr_client_realtime_test.cc.
#include "xr_client_test_util.h"

namespace m2s::xr_test {
namespace {

std::string ClientCommand(const fs::path& dir, const fs::path& trajectory,
                          const std::string& script, const std::string& capture,
                          const std::string& args) {
  return RuntimeEnv(dir, trajectory, script, capture) + " " + kBin + "/m2s_xr_client --out " +
         Quote((dir / "out").string()) + " " + args;
}

TEST(XrClient, StageSpaceIsTheWorldWhenAsked) {
  // STAGE's origin sits at `offset` in LOCAL (the played trajectory's frame): with --stage the
  // app's world is STAGE, so every true camera position is the played one minus the offset.
  const fs::path dir = TestDir();
  const Trajectory played = WritePlayedTrajectory(dir / "head.tum", 1.0);
  const Eigen::Vector3d offset(0.5, -1.6, 0.25);
  const int rc = RunBounded("M2S_XR_SIM_STAGE_OFFSET=0.5,-1.6,0.25 " +
                                ClientCommand(dir, dir / "head.tum", "", "",
                                              "--stage --projector cpu --budget 500 --no-mesh "
                                              "--frames 40"),
                            60, dir / "log.txt");
  ASSERT_EQ(rc, 0) << ReadText(dir / "log.txt");
  ExpectCleanRuntimeReport(ReadJson(dir / "runtime_report.json"));
  auto truth = ReadTum((dir / "out" / "groundtruth.tum").string());
  ASSERT_TRUE(truth.ok()) << truth.error();
  ASSERT_GE(truth->size(), 30u);
  for (const TimedPose& p : *truth) {
    auto reference = played.Interpolate(p.timestamp);
    ASSERT_TRUE(reference.ok());
    // Measured: positions within 1.6e-7 m (the runtime's float poses), 1 - |q.q'| within
    // 2.8e-14; the bounds allow 6x and 10x.
    EXPECT_LT((reference->translation() - offset - p.world_from_camera.translation()).norm(), 1e-6);
    EXPECT_NEAR(std::abs(reference->rotation().dot(p.world_from_camera.rotation())), 1.0, 3e-13);
  }
}

}  // namespace
}  // namespace m2s::xr_test
