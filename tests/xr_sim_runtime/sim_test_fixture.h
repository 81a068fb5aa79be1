// Test fixture for the simulated OpenXR runtime: a surfaceless GLES 3 context and an OpenXR
// instance/session/swapchain created through the real loader (XR_RUNTIME_JSON points at the
// runtime manifest built next to the library).
#pragma once
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl3.h>
#define XR_USE_PLATFORM_EGL
#define XR_USE_GRAPHICS_API_OPENGL_ES
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

namespace m2s::xrsim_test {

namespace fs = std::filesystem;

// A surfaceless GLES 3 context on Mesa (llvmpipe here), current on the test thread.
class EglContext {
 public:
  EglContext() {
    auto get_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
        eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (get_display == nullptr) return;
    display_ = get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (display_ == EGL_NO_DISPLAY || !eglInitialize(display_, nullptr, nullptr)) return;
    const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_SURFACE_TYPE, 0,
                                     EGL_NONE};
    EGLint n = 0;
    if (!eglChooseConfig(display_, config_attribs, &config_, 1, &n) || n < 1) return;
    eglBindAPI(EGL_OPENGL_ES_API);
    const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_NONE};
    context_ = eglCreateContext(display_, config_, EGL_NO_CONTEXT, context_attribs);
    ok_ = context_ != EGL_NO_CONTEXT &&
          eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, context_);
  }
  ~EglContext() {
    if (context_ != EGL_NO_CONTEXT) {
      eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
      eglDestroyContext(display_, context_);
    }
    if (display_ != EGL_NO_DISPLAY) eglTerminate(display_);
  }
  bool ok() const { return ok_; }
  XrGraphicsBindingEGLMNDX Binding() const {
    XrGraphicsBindingEGLMNDX b{XR_TYPE_GRAPHICS_BINDING_EGL_MNDX};
    b.getProcAddress = &eglGetProcAddress;
    b.display = display_;
    b.config = config_;
    b.context = context_;
    return b;
  }

 private:
  bool ok_ = false;
  EGLDisplay display_ = EGL_NO_DISPLAY;
  EGLConfig config_ = nullptr;
  EGLContext context_ = EGL_NO_CONTEXT;
};

class SimRuntimeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ =
        fs::path(M2S_BINARY_DIR) / "test_tmp" /
        ("xr_sim_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    setenv("XR_RUNTIME_JSON", M2S_XR_SIM_RUNTIME_JSON, 1);
    setenv("M2S_XR_SIM_REPORT", (dir_ / "report.json").c_str(), 1);
    for (const char* name :
         {"M2S_XR_SIM_TRAJECTORY", "M2S_XR_SIM_SCRIPT", "M2S_XR_SIM_CAPTURE_DIR",
          "M2S_XR_SIM_CAPTURE_FRAMES", "M2S_XR_SIM_RATE_HZ", "M2S_XR_SIM_EYE_SIZE",
          "M2S_XR_SIM_IPD_M", "M2S_XR_SIM_FOV_DEG", "M2S_XR_SIM_INPUT", "M2S_XR_SIM_CONTROLLER"}) {
      unsetenv(name);
    }
  }
  void TearDown() override {
    if (swapchain_ != XR_NULL_HANDLE) xrDestroySwapchain(swapchain_);
    if (local_ != XR_NULL_HANDLE) xrDestroySpace(local_);
    if (view_ != XR_NULL_HANDLE) xrDestroySpace(view_);
    if (session_ != XR_NULL_HANDLE) xrDestroySession(session_);
    if (instance_ != XR_NULL_HANDLE) xrDestroyInstance(instance_);
  }

  XrResult TryCreateInstance(bool enable_egl = true) {
    XrInstanceCreateInfo info{XR_TYPE_INSTANCE_CREATE_INFO};
    std::snprintf(info.applicationInfo.applicationName, XR_MAX_APPLICATION_NAME_SIZE, "sim_test");
    info.applicationInfo.apiVersion = XR_MAKE_VERSION(1, 0, 0);
    const char* extensions[] = {XR_MNDX_EGL_ENABLE_EXTENSION_NAME};
    info.enabledExtensionCount = enable_egl ? 1 : 0;
    info.enabledExtensionNames = extensions;
    return xrCreateInstance(&info, &instance_);
  }

  void CreateInstance(bool enable_egl = true) {
    ASSERT_EQ(TryCreateInstance(enable_egl), XR_SUCCESS);
    XrSystemGetInfo get{XR_TYPE_SYSTEM_GET_INFO};
    get.formFactor = XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY;
    ASSERT_EQ(xrGetSystem(instance_, &get, &system_), XR_SUCCESS);
  }

  void CreateSession() {
    ASSERT_TRUE(egl_.ok()) << "no surfaceless EGL/GLES3 context";
    const XrGraphicsBindingEGLMNDX binding = egl_.Binding();
    XrSessionCreateInfo info{XR_TYPE_SESSION_CREATE_INFO};
    info.next = &binding;
    info.systemId = system_;
    ASSERT_EQ(xrCreateSession(instance_, &info, &session_), XR_SUCCESS);
    XrReferenceSpaceCreateInfo space{XR_TYPE_REFERENCE_SPACE_CREATE_INFO};
    space.poseInReferenceSpace.orientation.w = 1.f;
    space.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_LOCAL;
    ASSERT_EQ(xrCreateReferenceSpace(session_, &space, &local_), XR_SUCCESS);
    space.referenceSpaceType = XR_REFERENCE_SPACE_TYPE_VIEW;
    ASSERT_EQ(xrCreateReferenceSpace(session_, &space, &view_), XR_SUCCESS);
    XrSwapchainCreateInfo sc{XR_TYPE_SWAPCHAIN_CREATE_INFO};
    sc.usageFlags = XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT;
    sc.format = GL_RGBA8;
    sc.sampleCount = sc.faceCount = sc.arraySize = sc.mipCount = 1;
    sc.width = 64;
    sc.height = 48;
    ASSERT_EQ(xrCreateSwapchain(session_, &sc, &swapchain_), XR_SUCCESS);
    uint32_t n = 0;
    ASSERT_EQ(xrEnumerateSwapchainImages(swapchain_, 0, &n, nullptr), XR_SUCCESS);
    images_.assign(n, {XR_TYPE_SWAPCHAIN_IMAGE_OPENGL_ES_KHR});
    ASSERT_EQ(xrEnumerateSwapchainImages(
                  swapchain_, n, &n, reinterpret_cast<XrSwapchainImageBaseHeader*>(images_.data())),
              XR_SUCCESS);
  }

  // Drains the event queue; returns the session states seen, in order.
  std::vector<XrSessionState> PollStates() {
    std::vector<XrSessionState> states;
    XrEventDataBuffer event{XR_TYPE_EVENT_DATA_BUFFER};
    while (xrPollEvent(instance_, &event) == XR_SUCCESS) {
      if (event.type == XR_TYPE_EVENT_DATA_SESSION_STATE_CHANGED) {
        states.push_back(reinterpret_cast<XrEventDataSessionStateChanged&>(event).state);
      }
      event = {XR_TYPE_EVENT_DATA_BUFFER};
    }
    return states;
  }

  void Begin() {
    XrSessionBeginInfo begin{XR_TYPE_SESSION_BEGIN_INFO};
    begin.primaryViewConfigurationType = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
    ASSERT_EQ(xrBeginSession(session_, &begin), XR_SUCCESS);
  }

  // One full frame, clearing the swapchain image to `rgba` and submitting it for both eyes.
  XrFrameState Frame(const float rgba[4]) {
    XrFrameState state{XR_TYPE_FRAME_STATE};
    EXPECT_EQ(xrWaitFrame(session_, nullptr, &state), XR_SUCCESS);
    EXPECT_EQ(xrBeginFrame(session_, nullptr), XR_SUCCESS);
    uint32_t index = 0;
    EXPECT_EQ(xrAcquireSwapchainImage(swapchain_, nullptr, &index), XR_SUCCESS);
    XrSwapchainImageWaitInfo wait{XR_TYPE_SWAPCHAIN_IMAGE_WAIT_INFO};
    wait.timeout = XR_INFINITE_DURATION;
    EXPECT_EQ(xrWaitSwapchainImage(swapchain_, &wait), XR_SUCCESS);
    GLuint fbo = 0;
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D,
                           images_[index].image, 0);
    glClearColor(rgba[0], rgba[1], rgba[2], rgba[3]);
    glClear(GL_COLOR_BUFFER_BIT);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glDeleteFramebuffers(1, &fbo);
    EXPECT_EQ(xrReleaseSwapchainImage(swapchain_, nullptr), XR_SUCCESS);
    XrCompositionLayerProjectionView views[2];
    for (auto& v : views) {
      v = {XR_TYPE_COMPOSITION_LAYER_PROJECTION_VIEW};
      v.pose.orientation.w = 1.f;
      v.fov = {-0.7f, 0.7f, 0.5f, -0.5f};
      v.subImage.swapchain = swapchain_;
      v.subImage.imageRect = {{0, 0}, {64, 48}};
    }
    XrCompositionLayerProjection layer{XR_TYPE_COMPOSITION_LAYER_PROJECTION};
    layer.space = local_;
    layer.viewCount = 2;
    layer.views = views;
    const XrCompositionLayerBaseHeader* layers[] = {
        reinterpret_cast<XrCompositionLayerBaseHeader*>(&layer)};
    XrFrameEndInfo end{XR_TYPE_FRAME_END_INFO};
    end.displayTime = state.predictedDisplayTime;
    end.environmentBlendMode = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    end.layerCount = state.shouldRender ? 1 : 0;
    end.layers = layers;
    EXPECT_EQ(xrEndFrame(session_, &end), XR_SUCCESS);
    return state;
  }

  // Ends the running session the way an app asks for it, then DestroyAll().
  void EndAndDestroyAll() {
    ASSERT_EQ(xrRequestExitSession(session_), XR_SUCCESS);
    ASSERT_EQ(xrEndSession(session_), XR_SUCCESS);
    DestroyAll();
  }

  void DestroyAll() {
    EXPECT_EQ(xrDestroySwapchain(swapchain_), XR_SUCCESS);
    EXPECT_EQ(xrDestroySpace(local_), XR_SUCCESS);
    EXPECT_EQ(xrDestroySpace(view_), XR_SUCCESS);
    EXPECT_EQ(xrDestroySession(session_), XR_SUCCESS);
    EXPECT_EQ(xrDestroyInstance(instance_), XR_SUCCESS);
    swapchain_ = XR_NULL_HANDLE;
    local_ = view_ = XR_NULL_HANDLE;
    session_ = XR_NULL_HANDLE;
    instance_ = XR_NULL_HANDLE;
  }

  nlohmann::json Report() {
    std::ifstream file(dir_ / "report.json");
    EXPECT_TRUE(file.good()) << "no report at " << dir_ / "report.json";
    nlohmann::json report;
    if (file) file >> report;
    return report;
  }

  XrPath Path(const char* path) {
    XrPath p = XR_NULL_PATH;
    EXPECT_EQ(xrStringToPath(instance_, path, &p), XR_SUCCESS) << path;
    return p;
  }

  fs::path dir_;
  EglContext egl_;
  XrInstance instance_ = XR_NULL_HANDLE;
  XrSystemId system_ = XR_NULL_SYSTEM_ID;
  XrSession session_ = XR_NULL_HANDLE;
  XrSpace local_ = XR_NULL_HANDLE;
  XrSpace view_ = XR_NULL_HANDLE;
  XrSwapchain swapchain_ = XR_NULL_HANDLE;
  std::vector<XrSwapchainImageOpenGLESKHR> images_;
};

inline constexpr float kRed[4] = {1.f, 0.f, 0.f, 1.f};

}  // namespace m2s::xrsim_test
