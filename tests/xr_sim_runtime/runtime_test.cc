// The simulated runtime through the real OpenXR loader: negotiation, the session state
// machine (app- and script-driven), frame timing, views from a TUM trajectory, swapchains and
// the capture facility. Misuse detection is in misuse_test.cc.
#include <opencv2/imgcodecs.hpp>

#include "sim_test_fixture.h"

namespace m2s::xrsim_test {
namespace {

using States = std::vector<XrSessionState>;

TEST_F(SimRuntimeTest, NegotiatesAndDescribesTheSystem) {
  uint32_t n = 0;
  ASSERT_EQ(xrEnumerateInstanceExtensionProperties(nullptr, 0, &n, nullptr), XR_SUCCESS);
  std::vector<XrExtensionProperties> extensions(n, {XR_TYPE_EXTENSION_PROPERTIES});
  ASSERT_EQ(xrEnumerateInstanceExtensionProperties(nullptr, n, &n, extensions.data()), XR_SUCCESS);
  bool egl = false;
  for (const auto& e : extensions) egl |= std::string(e.extensionName) == "XR_MNDX_egl_enable";
  EXPECT_TRUE(egl);
  setenv("M2S_XR_SIM_EYE_SIZE", "320x240", 1);
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  XrInstanceProperties properties{XR_TYPE_INSTANCE_PROPERTIES};
  ASSERT_EQ(xrGetInstanceProperties(instance_, &properties), XR_SUCCESS);
  EXPECT_STREQ(properties.runtimeName, "Mesh2SLAM simulated runtime");
  ASSERT_EQ(xrEnumerateViewConfigurationViews(
                instance_, system_, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO, 0, &n, nullptr),
            XR_SUCCESS);
  ASSERT_EQ(n, 2u);
  std::vector<XrViewConfigurationView> views(2, {XR_TYPE_VIEW_CONFIGURATION_VIEW});
  ASSERT_EQ(xrEnumerateViewConfigurationViews(
                instance_, system_, XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO, 2, &n, views.data()),
            XR_SUCCESS);
  EXPECT_EQ(views[1].recommendedImageRectWidth, 320u);
  EXPECT_EQ(views[1].recommendedImageRectHeight, 240u);
  XrSystemGetInfo handheld{XR_TYPE_SYSTEM_GET_INFO};
  handheld.formFactor = XR_FORM_FACTOR_HANDHELD_DISPLAY;
  XrSystemId other = 0;
  EXPECT_EQ(xrGetSystem(instance_, &handheld, &other), XR_ERROR_FORM_FACTOR_UNSUPPORTED);
  ASSERT_EQ(xrDestroyInstance(instance_), XR_SUCCESS);
  instance_ = XR_NULL_HANDLE;
  EXPECT_EQ(Report()["misuse"], 0);
}

TEST_F(SimRuntimeTest, FullLifecycleWithAppRequestedExit) {
  setenv("M2S_XR_SIM_RATE_HZ", "90", 1);
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  EXPECT_EQ(PollStates(), (States{XR_SESSION_STATE_IDLE, XR_SESSION_STATE_READY}));
  Begin();
  XrFrameState first = Frame(kRed);
  EXPECT_FALSE(first.shouldRender);  // SYNCHRONIZED: not yet visible
  EXPECT_EQ(PollStates(), (States{XR_SESSION_STATE_SYNCHRONIZED}));
  XrFrameState second = Frame(kRed);
  EXPECT_TRUE(second.shouldRender);
  EXPECT_EQ(PollStates(), (States{XR_SESSION_STATE_VISIBLE, XR_SESSION_STATE_FOCUSED}));
  // Simulated time: exactly one period per frame, no real waiting.
  EXPECT_EQ(second.predictedDisplayPeriod, static_cast<XrDuration>(1e9 / 90 + 0.5));
  EXPECT_EQ(second.predictedDisplayTime - first.predictedDisplayTime,
            second.predictedDisplayPeriod);
  for (int i = 0; i < 5; ++i) Frame(kRed);
  ASSERT_EQ(xrRequestExitSession(session_), XR_SUCCESS);
  EXPECT_EQ(PollStates(), (States{XR_SESSION_STATE_VISIBLE, XR_SESSION_STATE_SYNCHRONIZED,
                                  XR_SESSION_STATE_STOPPING}));
  ASSERT_EQ(xrEndSession(session_), XR_SUCCESS);
  EXPECT_EQ(PollStates(), (States{XR_SESSION_STATE_IDLE, XR_SESSION_STATE_EXITING}));
  DestroyAll();
  const nlohmann::json report = Report();
  EXPECT_EQ(report["misuse"], 0) << report["misuse_messages"];
  EXPECT_EQ(report["handles_left_alive"], 0);
  EXPECT_EQ(report["implicitly_destroyed"], 0);
  EXPECT_EQ(report["frames_ended"], 7);
  EXPECT_EQ(report["swapchains_destroyed"], 1);
}

TEST_F(SimRuntimeTest, ScriptDrivesFocusLossHideAndExit) {
  setenv("M2S_XR_SIM_SCRIPT", "focus_loss@4:2,hide@8:1,exit@12", 1);
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  Begin();
  States seen = PollStates();
  std::vector<int> should_render;
  for (int frame = 1; frame <= 12; ++frame) {
    should_render.push_back(Frame(kRed).shouldRender ? 1 : 0);
    for (XrSessionState s : PollStates()) seen.push_back(s);
  }
  // frame 1: SYNCHRONIZED; 2-3 FOCUSED; 4-5 VISIBLE; 6-7 FOCUSED; 8 SYNCHRONIZED; 9-11 FOCUSED.
  EXPECT_EQ(should_render, (std::vector<int>{0, 1, 1, 1, 1, 1, 1, 0, 1, 1, 1, 0}));
  const States expected = {
      XR_SESSION_STATE_IDLE,         XR_SESSION_STATE_READY,   XR_SESSION_STATE_SYNCHRONIZED,
      XR_SESSION_STATE_VISIBLE,      XR_SESSION_STATE_FOCUSED, XR_SESSION_STATE_VISIBLE,
      XR_SESSION_STATE_FOCUSED,      XR_SESSION_STATE_VISIBLE, XR_SESSION_STATE_SYNCHRONIZED,
      XR_SESSION_STATE_VISIBLE,      XR_SESSION_STATE_FOCUSED, XR_SESSION_STATE_VISIBLE,
      XR_SESSION_STATE_SYNCHRONIZED, XR_SESSION_STATE_STOPPING};
  EXPECT_EQ(seen, expected);
  ASSERT_EQ(xrEndSession(session_), XR_SUCCESS);
  EXPECT_EQ(PollStates(), (States{XR_SESSION_STATE_IDLE, XR_SESSION_STATE_EXITING}));
  DestroyAll();
  EXPECT_EQ(Report()["misuse"], 0);
}

TEST_F(SimRuntimeTest, ViewsFollowTheTrajectoryWithOpenXrAxes) {
  // Two poses one second apart: the camera (x right, y down, z forward) moves 1 m along x and
  // turns 90 degrees about its y axis.
  const fs::path tum = dir_ / "head.tum";
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
  {
    std::ofstream out(tum);
    out << "10.0 0 0 0 0 0 0 1\n";
    out << "11.0 1 0 0 " << turn.x() << " " << turn.y() << " " << turn.z() << " " << turn.w()
        << "\n";
  }
  setenv("M2S_XR_SIM_TRAJECTORY", tum.c_str(), 1);
  setenv("M2S_XR_SIM_IPD_M", "0.06", 1);
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  // Display time in ns equals the trajectory stamp (positive stamps).
  const XrTime half = static_cast<XrTime>(10.5e9);
  XrSpaceLocation location{XR_TYPE_SPACE_LOCATION};
  ASSERT_EQ(xrLocateSpace(view_, local_, half, &location), XR_SUCCESS);
  EXPECT_NEAR(location.pose.position.x, 0.5, 1e-6);
  // Halfway: 45 degrees about the camera's y (down) axis = -45 degrees about OpenXR's y (up),
  // composed with the 180-degree turn about x between the two axis conventions.
  const Eigen::Quaterniond cam_q(Eigen::AngleAxisd(M_PI / 4, Eigen::Vector3d::UnitY()));
  const Eigen::Quaterniond expected = cam_q * Eigen::Quaterniond(0, 1, 0, 0);
  const Eigen::Quaterniond got(location.pose.orientation.w, location.pose.orientation.x,
                               location.pose.orientation.y, location.pose.orientation.z);
  EXPECT_NEAR(std::abs(got.dot(expected)), 1.0, 1e-6);
  // The VIEW space looks down -z: the camera's forward (+z) is the view's -z.
  const Eigen::Vector3d forward = got * Eigen::Vector3d(0, 0, -1);
  EXPECT_TRUE(forward.isApprox(cam_q * Eigen::Vector3d::UnitZ(), 1e-6));

  XrViewLocateInfo info{XR_TYPE_VIEW_LOCATE_INFO};
  info.viewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  info.displayTime = static_cast<XrTime>(10e9);
  info.space = local_;
  XrViewState state{XR_TYPE_VIEW_STATE};
  XrView views[2] = {{XR_TYPE_VIEW}, {XR_TYPE_VIEW}};
  uint32_t n = 0;
  ASSERT_EQ(xrLocateViews(session_, &info, &state, 2, &n, views), XR_SUCCESS);
  // At t = 10 the head is the identity camera: eyes at -+IPD/2 along x.
  EXPECT_NEAR(views[0].pose.position.x, -0.03, 1e-6);
  EXPECT_NEAR(views[1].pose.position.x, 0.03, 1e-6);
  EXPECT_NEAR(views[0].fov.angleRight, M_PI / 4, 1e-6);  // default 90 degrees
  DestroyAll();
  EXPECT_EQ(Report()["misuse"], 0);
}

TEST_F(SimRuntimeTest, CapturesTheSubmittedLeftEye) {
  setenv("M2S_XR_SIM_CAPTURE_DIR", (dir_ / "capture").c_str(), 1);
  setenv("M2S_XR_SIM_CAPTURE_FRAMES", "3", 1);
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  Begin();
  const float blue[4] = {0.f, 0.f, 1.f, 1.f};
  Frame(kRed);
  Frame(kRed);
  Frame(blue);  // frame 3
  Frame(kRed);
  const cv::Mat image = cv::imread((dir_ / "capture" / "left_000003.png").string());
  ASSERT_FALSE(image.empty());
  EXPECT_EQ(image.cols, 64);
  EXPECT_EQ(image.rows, 48);
  EXPECT_EQ(image.at<cv::Vec3b>(10, 10), cv::Vec3b(255, 0, 0));  // BGR: blue
  EXPECT_TRUE(fs::exists(dir_ / "capture" / "left_000003.json"));
  EXPECT_FALSE(fs::exists(dir_ / "capture" / "left_000004.png"));
  ASSERT_EQ(xrRequestExitSession(session_), XR_SUCCESS);
  PollStates();
  ASSERT_EQ(xrEndSession(session_), XR_SUCCESS);
  DestroyAll();
  EXPECT_EQ(Report()["captures"].size(), 1u);
}

TEST_F(SimRuntimeTest, SessionLossThenANewSession) {
  setenv("M2S_XR_SIM_SCRIPT", "session_loss@3", 1);
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  Begin();
  Frame(kRed);
  Frame(kRed);
  XrFrameState state{XR_TYPE_FRAME_STATE};
  EXPECT_EQ(xrWaitFrame(session_, nullptr, &state), XR_ERROR_SESSION_LOST);
  States states = PollStates();
  ASSERT_FALSE(states.empty());
  EXPECT_EQ(states.back(), XR_SESSION_STATE_LOSS_PENDING);
  EXPECT_EQ(xrDestroySwapchain(swapchain_), XR_SUCCESS);
  EXPECT_EQ(xrDestroySpace(local_), XR_SUCCESS);
  EXPECT_EQ(xrDestroySpace(view_), XR_SUCCESS);
  EXPECT_EQ(xrDestroySession(session_), XR_SUCCESS);
  swapchain_ = XR_NULL_HANDLE;
  local_ = view_ = XR_NULL_HANDLE;
  session_ = XR_NULL_HANDLE;
  // The system comes back after a short while.
  XrSystemGetInfo get{XR_TYPE_SYSTEM_GET_INFO};
  get.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
  int unavailable = 0;
  while (xrGetSystem(instance_, &get, &system_) == XR_ERROR_FORM_FACTOR_UNAVAILABLE) {
    ASSERT_LT(++unavailable, 10);
  }
  EXPECT_EQ(unavailable, 2);
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  EXPECT_EQ(PollStates(), (States{XR_SESSION_STATE_IDLE, XR_SESSION_STATE_READY}));
  Begin();
  Frame(kRed);
  ASSERT_EQ(xrRequestExitSession(session_), XR_SUCCESS);
  PollStates();
  ASSERT_EQ(xrEndSession(session_), XR_SUCCESS);
  DestroyAll();
  const nlohmann::json report = Report();
  EXPECT_EQ(report["misuse"], 0) << report["misuse_messages"];
  EXPECT_EQ(report["sessions_created"], 2);
}

TEST_F(SimRuntimeTest, InstanceLoss) {
  setenv("M2S_XR_SIM_SCRIPT", "instance_loss@2", 1);
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  Begin();
  Frame(kRed);
  XrFrameState state{XR_TYPE_FRAME_STATE};
  EXPECT_EQ(xrWaitFrame(session_, nullptr, &state), XR_ERROR_INSTANCE_LOST);
  XrEventDataBuffer event{XR_TYPE_EVENT_DATA_BUFFER};
  bool loss_event = false;
  XrResult r;
  while ((r = xrPollEvent(instance_, &event)) == XR_SUCCESS) {
    loss_event |= event.type == XR_TYPE_EVENT_DATA_INSTANCE_LOSS_PENDING;
    event = {XR_TYPE_EVENT_DATA_BUFFER};
  }
  EXPECT_TRUE(loss_event);
  EXPECT_EQ(r, XR_ERROR_INSTANCE_LOST);
  DestroyAll();  // destroy functions still work after the loss
  EXPECT_EQ(Report()["misuse"], 0);
  EXPECT_EQ(Report()["instance_lost"], true);
}

}  // namespace
}  // namespace m2s::xrsim_test
