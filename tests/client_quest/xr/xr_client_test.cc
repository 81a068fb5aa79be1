// The real m2s_xr_client on the simulated OpenXR runtime, headless on llvmpipe: on-device SLAM
// follows the played head trajectory (Sim3 ATE bound), the submitted eye images contain the
// overlay at the map points, and the session lifecycle scripted by the runtime (focus loss,
// hidden, session loss, exit, instance loss) is followed without misuse, leaks or hangs.
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "m2s/common/camera.h"
#include "m2s/common/evaluation.h"
#include "m2s/common/scene.h"
#include "m2s/xr/axis_conversion.h"
#include "xr_client_test_util.h"

namespace m2s::xr_test {
namespace {

constexpr int kFrames = 300;
constexpr int kCaptureFrame = 290;
constexpr double kAteBoundM = 0.05;  // metres, Sim3-aligned, over ~4 s of walking
constexpr size_t kMinTracked = 30;

std::string ClientCommand(const fs::path& dir, const fs::path& trajectory,
                          const std::string& script, const std::string& capture,
                          const std::string& args) {
  return RuntimeEnv(dir, trajectory, script, capture) + " " + kBin + "/m2s_xr_client --out " +
         Quote((dir / "out").string()) + " " + args;
}

// Pixels of the captured left eye where map points were drawn: red dominant (the renderer's
// point colour; sRGB-encoded by the swapchain).
bool IsPointColour(const cv::Vec3b& bgr) { return bgr[2] > 150 && bgr[1] < 140 && bgr[0] < 140; }

TEST(XrClient, OnDeviceTracksThePlayedHeadAndDrawsTheOverlay) {
  const fs::path dir = TestDir();
  const Trajectory played = WritePlayedTrajectory(dir / "head.tum", kFrames / kRateHz + 0.5);
  const int rc =
      RunBounded(ClientCommand(dir, dir / "head.tum", "", std::to_string(kCaptureFrame),
                               "--on-device --projector cpu --budget 2000 --no-mesh --frames " +
                                   std::to_string(kFrames)),
                 240, dir / "log.txt");
  ASSERT_EQ(rc, 0) << ReadText(dir / "log.txt");
  ExpectCleanRuntimeReport(ReadJson(dir / "runtime_report.json"));

  // The estimated trajectory against the played one (Sim3, matched by timestamp).
  auto estimate = ReadTum((dir / "out" / "trajectory.tum").string());
  ASSERT_TRUE(estimate.ok()) << estimate.error();
  // SLAM runs asynchronously (latest-wins queue): how many frames it takes depends on the
  // machine; initialisation plus tracking leaves well over this many.
  ASSERT_GE(estimate->size(), kMinTracked);
  // The played poses at the display times (the runtime interpolates the 30 Hz file).
  auto reference = InterpolateReferenceAt(played, *estimate);
  ASSERT_TRUE(reference.ok()) << reference.error();
  auto eval = EvaluateTrajectory(*reference, *estimate);
  ASSERT_TRUE(eval.ok()) << eval.error();
  EXPECT_LT(eval->ate.rmse, kAteBoundM);
  EXPECT_GE(eval->matches.size(), kMinTracked);

  // The app's ground truth (VIEW pose -> camera) is the played trajectory.
  auto truth = ReadTum((dir / "out" / "groundtruth.tum").string());
  ASSERT_TRUE(truth.ok()) << truth.error();
  double worst = 0.0;
  for (const TimedPose& p : *truth) {
    auto reference = played.Interpolate(p.timestamp);
    ASSERT_TRUE(reference.ok());
    worst = std::max(worst, (reference->translation() - p.world_from_camera.translation()).norm());
    EXPECT_NEAR(std::abs(reference->rotation().dot(p.world_from_camera.rotation())), 1.0, 1e-6);
  }
  EXPECT_LT(worst, 1e-4);

  const nlohmann::json metrics = ReadJson(dir / "out" / "xr_metrics.json");
  EXPECT_EQ(metrics["frames"], kFrames);
  EXPECT_GT(metrics["render_thread_ms"]["projection"]["n"].get<int>(), kFrames - 10);

  // The overlay: map points are drawn (red) where true scene vertices project in the
  // submitted left eye.
  const cv::Mat image = cv::imread(
      (dir / "capture" / ("left_000" + std::to_string(kCaptureFrame) + ".png")).string());
  ASSERT_FALSE(image.empty());
  const nlohmann::json meta =
      ReadJson(dir / "capture" / ("left_000" + std::to_string(kCaptureFrame) + ".json"));
  const auto& pos = meta["pose_in_layer_space"]["position"];
  const auto& rot = meta["pose_in_layer_space"]["orientation_xyzw"];
  const Pose3 world_from_eye = xr::PoseFromXr(Eigen::Vector4d(rot[0], rot[1], rot[2], rot[3]),
                                              Eigen::Vector3d(pos[0], pos[1], pos[2]));
  const xr::FieldOfView fov{meta["fov_rad"]["left"], meta["fov_rad"]["right"],
                            meta["fov_rad"]["up"], meta["fov_rad"]["down"]};
  const Camera eye = xr::CameraFromXrFov(fov, image.cols, image.rows, 0.05, 100.0);
  const Pose3 eye_from_world = xr::WorldFromCameraFromXrView(world_from_eye).Inverse();
  // Map points the app held at the end, in the world frame by the run's Sim3.
  const Scene scene = MakeDefaultScene();
  cv::Mat near_vertex(image.rows, image.cols, CV_8U, cv::Scalar(0));
  for (const Eigen::Vector3f& v : scene.positions) {
    const Eigen::Vector3d p = eye_from_world * v.cast<double>();
    if (p.z() < 0.1) continue;
    const Eigen::Vector2d uv = eye.Project(p);
    if (!eye.InImage(uv.x(), uv.y())) continue;
    cv::circle(near_vertex, cv::Point(static_cast<int>(uv.x()), static_cast<int>(uv.y())), 4, 255,
               -1);
  }
  int red = 0, red_near_vertex = 0;
  for (int y = 0; y < image.rows; ++y) {
    for (int x = 0; x < image.cols; ++x) {
      if (!IsPointColour(image.at<cv::Vec3b>(y, x))) continue;
      ++red;
      red_near_vertex += near_vertex.at<uint8_t>(y, x) != 0;
    }
  }
  EXPECT_GT(red, 50) << "no map points drawn in the left eye";
  EXPECT_GT(red_near_vertex, 0.9 * red) << "map points drawn away from the scene's vertices";
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
    EXPECT_LT((reference->translation() - offset - p.world_from_camera.translation()).norm(), 1e-4);
    EXPECT_NEAR(std::abs(reference->rotation().dot(p.world_from_camera.rotation())), 1.0, 1e-6);
  }
}

}  // namespace
}  // namespace m2s::xr_test
