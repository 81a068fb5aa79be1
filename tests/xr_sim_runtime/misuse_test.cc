// Misuse detection: each wrong call returns the XR_ERROR_* code the specification names, is
// logged and counted, and the count reaches the report written on xrDestroyInstance.
#include "sim_test_fixture.h"

namespace m2s::xrsim_test {
namespace {

TEST_F(SimRuntimeTest, FrameLoopCallOrder) {
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  XrFrameState state{XR_TYPE_FRAME_STATE};
  EXPECT_EQ(xrWaitFrame(session_, nullptr, &state), XR_ERROR_SESSION_NOT_RUNNING);  // 1
  Begin();
  XrSessionBeginInfo begin{XR_TYPE_SESSION_BEGIN_INFO};
  begin.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
  EXPECT_EQ(xrBeginSession(session_, &begin), XR_ERROR_SESSION_RUNNING);    // 2
  EXPECT_EQ(xrBeginFrame(session_, nullptr), XR_ERROR_CALL_ORDER_INVALID);  // 3
  XrFrameEndInfo end{XR_TYPE_FRAME_END_INFO};
  end.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  end.displayTime = 1;
  EXPECT_EQ(xrEndFrame(session_, &end), XR_ERROR_CALL_ORDER_INVALID);  // 4
  ASSERT_EQ(xrWaitFrame(session_, nullptr, &state), XR_SUCCESS);
  EXPECT_EQ(xrWaitFrame(session_, nullptr, &state), XR_ERROR_CALL_ORDER_INVALID);  // 5
  ASSERT_EQ(xrBeginFrame(session_, nullptr), XR_SUCCESS);
  end.displayTime = state.predictedDisplayTime + 1;
  EXPECT_EQ(xrEndFrame(session_, &end), XR_ERROR_TIME_INVALID);  // 6
  end.displayTime = state.predictedDisplayTime;
  end.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_ADDITIVE;
  EXPECT_EQ(xrEndFrame(session_, &end), XR_ERROR_ENVIRONMENT_BLEND_MODE_UNSUPPORTED);  // 7
  end.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
  // A layer referring to a swapchain that never released an image.
  XrCompositionLayerProjectionView views[2] = {{XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW},
                                               {XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW}};
  for (auto& v : views) {
    v.pose.orientation.w = 1.f;
    v.fov = {-0.5f, 0.5f, 0.5f, -0.5f};
    v.subImage.swapchain = swapchain_;
    v.subImage.imageRect = {{0, 0}, {64, 48}};
  }
  XrCompositionLayerProjection layer{XR_TYPE_COMPOSITION_LAYER_PROJECTION};
  layer.space = local_;
  layer.viewCount = 2;
  layer.views = views;
  const XrCompositionLayerBaseHeader* layers[] = {
      reinterpret_cast<XrCompositionLayerBaseHeader*>(&layer)};
  end.layerCount = 1;
  end.layers = layers;
  EXPECT_EQ(xrEndFrame(session_, &end), XR_ERROR_LAYER_INVALID);  // 8
  end.layerCount = 0;
  EXPECT_EQ(xrEndFrame(session_, &end), XR_SUCCESS);
  // A frame begun twice discards the first (a success code, not misuse).
  ASSERT_EQ(xrWaitFrame(session_, nullptr, &state), XR_SUCCESS);
  ASSERT_EQ(xrBeginFrame(session_, nullptr), XR_SUCCESS);
  ASSERT_EQ(xrWaitFrame(session_, nullptr, &state), XR_SUCCESS);
  EXPECT_EQ(xrBeginFrame(session_, nullptr), XR_FRAME_DISCARDED);
  end.displayTime = state.predictedDisplayTime;
  EXPECT_EQ(xrEndFrame(session_, &end), XR_SUCCESS);
  EXPECT_EQ(xrEndSession(session_), XR_ERROR_SESSION_NOT_STOPPING);  // 9
  ASSERT_EQ(xrRequestExitSession(session_), XR_SUCCESS);
  ASSERT_EQ(xrEndSession(session_), XR_SUCCESS);
  DestroyAll();
  const nlohmann::json report = Report();
  EXPECT_EQ(report["misuse"], 9) << report["misuse_messages"];
  EXPECT_EQ(report["frames_discarded"], 1);
}

TEST_F(SimRuntimeTest, SwapchainImageOrder) {
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  XrSwapchainImageWaitInfo wait{XR_TYPE_SWAPCHAIN_IMAGE_WAIT_INFO};
  wait.timeout = XR_INFINITE_DURATION;
  EXPECT_EQ(xrWaitSwapchainImage(swapchain_, &wait), XR_ERROR_CALL_ORDER_INVALID);  // 1
  uint32_t index = 0;
  ASSERT_EQ(xrAcquireSwapchainImage(swapchain_, nullptr, &index), XR_SUCCESS);
  EXPECT_EQ(xrReleaseSwapchainImage(swapchain_, nullptr), XR_ERROR_CALL_ORDER_INVALID);  // 2
  ASSERT_EQ(xrWaitSwapchainImage(swapchain_, &wait), XR_SUCCESS);
  EXPECT_EQ(xrWaitSwapchainImage(swapchain_, &wait), XR_ERROR_CALL_ORDER_INVALID);  // 3
  ASSERT_EQ(xrReleaseSwapchainImage(swapchain_, nullptr), XR_SUCCESS);
  for (int i = 0; i < 3; ++i) {
    ASSERT_EQ(xrAcquireSwapchainImage(swapchain_, nullptr, &index), XR_SUCCESS);
  }
  EXPECT_EQ(xrAcquireSwapchainImage(swapchain_, nullptr, &index),
            XR_ERROR_CALL_ORDER_INVALID);  // 4: all three images held
  XrSwapchainCreateInfo bad{XR_TYPE_SWAPCHAIN_CREATE_INFO};
  bad.usageFlags = XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT;
  bad.format = 0x1234;
  bad.sampleCount = bad.faceCount = bad.arraySize = bad.mipCount = 1;
  bad.width = bad.height = 16;
  XrSwapchain other = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateSwapchain(session_, &bad, &other), XR_ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED);  // 5
  DestroyAll();
  EXPECT_EQ(Report()["misuse"], 5) << Report()["misuse_messages"];
}

TEST_F(SimRuntimeTest, HandlesAndStructureTypes) {
  ASSERT_NO_FATAL_FAILURE(CreateInstance());
  // A session without the graphics binding, and one whose info has the wrong type.
  XrSessionCreateInfo info{XR_TYPE_SESSION_CREATE_INFO};
  info.systemId = system_;
  XrSession session = XR_NULL_HANDLE;
  EXPECT_EQ(xrCreateSession(instance_, &info, &session), XR_ERROR_GRAPHICS_DEVICE_INVALID);  // 1
  info.type = XR_TYPE_SESSION_BEGIN_INFO;
  EXPECT_EQ(xrCreateSession(instance_, &info, &session), XR_ERROR_VALIDATION_FAILURE);  // 2
  ASSERT_NO_FATAL_FAILURE(CreateSession());
  // A space handle used as a session, and a destroyed space.
  EXPECT_EQ(xrRequestExitSession(reinterpret_cast<XrSession>(local_)),
            XR_ERROR_HANDLE_INVALID);  // 3
  XrSpace extra = XR_NULL_HANDLE;
  XrReferenceSpaceCreateInfo space{XR_TYPE_REFERENCE_SPACE_CREATE_INFO};
  space.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_STAGE;
  space.poseInReferenceSpace.orientation = {0.f, 0.f, 0.f, 2.f};
  EXPECT_EQ(xrCreateReferenceSpace(session_, &space, &extra), XR_ERROR_POSE_INVALID);  // 4
  space.poseInReferenceSpace.orientation = {0.f, 0.f, 0.f, 1.f};
  ASSERT_EQ(xrCreateReferenceSpace(session_, &space, &extra), XR_SUCCESS);
  ASSERT_EQ(xrDestroySpace(extra), XR_SUCCESS);
  XrSpaceLocation location{XR_TYPE_SPACE_LOCATION};
  EXPECT_EQ(xrLocateSpace(extra, local_, 1, &location), XR_ERROR_HANDLE_INVALID);  // 5
  location.type = XR_TYPE_VIEW;
  EXPECT_EQ(xrLocateSpace(view_, local_, 1, &location), XR_ERROR_VALIDATION_FAILURE);  // 6
  // Leaving a space alive at xrDestroyInstance is reported.
  ASSERT_EQ(xrCreateReferenceSpace(session_, &space, &extra), XR_SUCCESS);
  ASSERT_EQ(xrDestroySwapchain(swapchain_), XR_SUCCESS);
  swapchain_ = XR_NULL_HANDLE;
  ASSERT_EQ(xrDestroyInstance(instance_), XR_SUCCESS);  // 7: 4 handles left alive
  instance_ = XR_NULL_HANDLE;
  session_ = XR_NULL_HANDLE;
  local_ = view_ = XR_NULL_HANDLE;
  const nlohmann::json report = Report();
  EXPECT_EQ(report["misuse"], 7) << report["misuse_messages"];
  EXPECT_EQ(report["handles_left_alive"], 4);  // session, LOCAL, VIEW, STAGE
}

}  // namespace
}  // namespace m2s::xrsim_test
