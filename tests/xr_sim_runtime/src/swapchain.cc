// Swapchains backed by GLES textures created in the application's EGL context.
#include <GLES3/gl3.h>

#include "api.h"

namespace m2s::xrsim {

ScopedAppContext::ScopedAppContext(const SessionObj& session) {
  if (eglGetCurrentContext() == session.context) {
    ok_ = true;
    return;
  }
  previous_display_ = eglGetCurrentDisplay();
  previous_draw_ = eglGetCurrentSurface(EGL_DRAW);
  previous_read_ = eglGetCurrentSurface(EGL_READ);
  previous_context_ = eglGetCurrentContext();
  ok_ =
      eglMakeCurrent(session.display, EGL_NO_SURFACE, EGL_NO_SURFACE, session.context) == EGL_TRUE;
  switched_ = ok_;
  if (!ok_) {
    LogInfo("ERROR: cannot make the application's EGL context current (EGL error 0x" +
            std::to_string(eglGetError()) + "); is it current in another thread?");
  }
}

ScopedAppContext::~ScopedAppContext() {
  if (!switched_) return;
  if (previous_context_ == EGL_NO_CONTEXT) {
    eglMakeCurrent(eglGetCurrentDisplay(), EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  } else {
    eglMakeCurrent(previous_display_, previous_draw_, previous_read_, previous_context_);
  }
}

namespace api {
namespace {

constexpr int64_t kFormats[] = {GL_SRGB8_ALPHA8, GL_RGBA8};

void DeleteTextures(const SessionObj& session, SwapchainObj& swapchain, InstanceObj& instance) {
  ScopedAppContext context(session);
  if (!context.ok()) {
    ++instance.counters.gl_failures;
    return;
  }
  glDeleteTextures(static_cast<GLsizei>(swapchain.textures.size()), swapchain.textures.data());
  swapchain.textures.clear();
}

#define M2S_SIM_SWAPCHAIN(var, handle)                                             \
  SwapchainObj* var = Runtime::Get().FindSwapchain(handle);                        \
  M2S_SIM_REQUIRE(var != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrSwapchain"); \
  M2S_SIM_SESSION(var##_session, var##_instance, var->session)

}  // namespace

XrResult XRAPI_CALL EnumerateSwapchainFormats(XrSession session, uint32_t capacity, uint32_t* count,
                                              int64_t* formats) {
  constexpr const char* kFn = "xrEnumerateSwapchainFormats";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE(count != nullptr, XR_ERROR_VALIDATION_FAILURE, "count output is NULL");
  constexpr uint32_t n = sizeof(kFormats) / sizeof(kFormats[0]);
  *count = n;
  if (capacity == 0) return XR_SUCCESS;
  M2S_SIM_REQUIRE(capacity >= n, XR_ERROR_SIZE_INSUFFICIENT, "capacity too small");
  M2S_SIM_REQUIRE(formats != nullptr, XR_ERROR_VALIDATION_FAILURE, "formats is NULL");
  for (uint32_t i = 0; i < n; ++i) formats[i] = kFormats[i];
  return XR_SUCCESS;
}

XrResult XRAPI_CALL CreateSwapchain(XrSession session, const XrSwapchainCreateInfo* info,
                                    XrSwapchain* swapchain) {
  constexpr const char* kFn = "xrCreateSwapchain";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_SWAPCHAIN_CREATE_INFO, "createInfo");
  M2S_SIM_REQUIRE(swapchain != nullptr, XR_ERROR_VALIDATION_FAILURE, "swapchain output is NULL");
  bool supported = false;
  for (int64_t f : kFormats) supported |= f == info->format;
  M2S_SIM_REQUIRE(supported, XR_ERROR_SWAPCHAIN_FORMAT_UNSUPPORTED,
                  "format " + std::to_string(info->format) + " was not enumerated");
  M2S_SIM_REQUIRE(info->width > 0 && info->height > 0 && info->width <= kMaxSwapchainSize &&
                      info->height <= kMaxSwapchainSize,
                  XR_ERROR_VALIDATION_FAILURE, "width/height out of [1, 4096]");
  M2S_SIM_REQUIRE(
      info->sampleCount == 1 && info->faceCount == 1 && info->arraySize == 1 && info->mipCount == 1,
      XR_ERROR_FEATURE_UNSUPPORTED,
      "only sampleCount = faceCount = arraySize = mipCount = 1 are supported");
  M2S_SIM_REQUIRE((info->usageFlags &
                   (XR_SWAPCHAIN_USAGE_COLOR_ATTACHMENT_BIT | XR_SWAPCHAIN_USAGE_SAMPLED_BIT |
                    XR_SWAPCHAIN_USAGE_TRANSFER_DST_BIT)) != 0,
                  XR_ERROR_FEATURE_UNSUPPORTED,
                  "usageFlags must include COLOR_ATTACHMENT, SAMPLED or TRANSFER_DST");
  auto obj = std::make_unique<SwapchainObj>();
  {
    ScopedAppContext context(*s);
    if (!context.ok()) return XR_ERROR_GRAPHICS_DEVICE_INVALID;
    obj->textures.resize(kSwapchainImageCount);
    glGenTextures(kSwapchainImageCount, obj->textures.data());
    for (uint32_t texture : obj->textures) {
      glBindTexture(GL_TEXTURE_2D, texture);
      glTexStorage2D(GL_TEXTURE_2D, 1, static_cast<GLenum>(info->format), info->width,
                     info->height);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    }
    glBindTexture(GL_TEXTURE_2D, 0);
    if (const GLenum error = glGetError(); error != GL_NO_ERROR) {
      LogInfo("ERROR: GL error " + std::to_string(error) + " creating swapchain textures");
      glDeleteTextures(kSwapchainImageCount, obj->textures.data());
      ++inst->counters.gl_failures;
      return XR_ERROR_RUNTIME_FAILURE;
    }
  }
  obj->handle = ToHandle<XrSwapchain>(rt.NewHandle());
  obj->session = session;
  obj->format = info->format;
  obj->width = info->width;
  obj->height = info->height;
  *swapchain = obj->handle;
  ++inst->counters.swapchains_created;
  rt.swapchains[reinterpret_cast<uint64_t>(obj->handle)] = std::move(obj);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL DestroySwapchain(XrSwapchain swapchain) {
  constexpr const char* kFn = "xrDestroySwapchain";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  SwapchainObj* obj = rt.FindSwapchain(swapchain);
  M2S_SIM_REQUIRE(obj != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrSwapchain");
  SessionObj* s = rt.FindSession(obj->session);
  InstanceObj* inst = rt.InstanceOf(*s);
  DeleteTextures(*s, *obj, *inst);
  ++inst->counters.swapchains_destroyed;
  rt.swapchains.erase(reinterpret_cast<uint64_t>(swapchain));
  return XR_SUCCESS;
}

XrResult XRAPI_CALL EnumerateSwapchainImages(XrSwapchain swapchain, uint32_t capacity,
                                             uint32_t* count, XrSwapchainImageBaseHeader* images) {
  constexpr const char* kFn = "xrEnumerateSwapchainImages";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SWAPCHAIN(sc, swapchain);
  M2S_SIM_REQUIRE(count != nullptr, XR_ERROR_VALIDATION_FAILURE, "count output is NULL");
  *count = kSwapchainImageCount;
  if (capacity == 0) return XR_SUCCESS;
  M2S_SIM_REQUIRE(capacity >= kSwapchainImageCount, XR_ERROR_SIZE_INSUFFICIENT,
                  "capacity too small");
  M2S_SIM_REQUIRE(images != nullptr, XR_ERROR_VALIDATION_FAILURE, "images is NULL");
  auto* gles = reinterpret_cast<XrSwapchainImageOpenGLESKHR*>(images);
  for (uint32_t i = 0; i < kSwapchainImageCount; ++i) {
    M2S_SIM_REQUIRE(gles[i].type == XR_TYPE_SWAPCHAIN_IMAGE_OPENGL_ES_KHR,
                    XR_ERROR_VALIDATION_FAILURE,
                    "images[i].type is not XR_TYPE_SWAPCHAIN_IMAGE_OPENGL_ES_KHR");
    gles[i].image = sc->textures[i];
  }
  return XR_SUCCESS;
}

XrResult XRAPI_CALL AcquireSwapchainImage(XrSwapchain swapchain,
                                          const XrSwapchainImageAcquireInfo* info,
                                          uint32_t* index) {
  constexpr const char* kFn = "xrAcquireSwapchainImage";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SWAPCHAIN(sc, swapchain);
  if (info != nullptr) {
    M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_SWAPCHAIN_IMAGE_ACQUIRE_INFO, "acquireInfo");
  }
  M2S_SIM_REQUIRE(index != nullptr, XR_ERROR_VALIDATION_FAILURE, "index is NULL");
  M2S_SIM_REQUIRE(sc->acquired.size() < kSwapchainImageCount, XR_ERROR_CALL_ORDER_INVALID,
                  "every image is already acquired (release before acquiring again)");
  *index = sc->next_index;
  if (sc->acquired.empty()) sc->oldest_waited = false;
  sc->acquired.push_back(sc->next_index);
  sc->next_index = (sc->next_index + 1) % kSwapchainImageCount;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL WaitSwapchainImage(XrSwapchain swapchain,
                                       const XrSwapchainImageWaitInfo* info) {
  constexpr const char* kFn = "xrWaitSwapchainImage";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SWAPCHAIN(sc, swapchain);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_SWAPCHAIN_IMAGE_WAIT_INFO, "waitInfo");
  M2S_SIM_REQUIRE(!sc->acquired.empty(), XR_ERROR_CALL_ORDER_INVALID,
                  "no acquired image to wait on");
  M2S_SIM_REQUIRE(!sc->oldest_waited, XR_ERROR_CALL_ORDER_INVALID,
                  "the oldest acquired image was already waited on");
  sc->oldest_waited = true;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL ReleaseSwapchainImage(XrSwapchain swapchain,
                                          const XrSwapchainImageReleaseInfo* info) {
  constexpr const char* kFn = "xrReleaseSwapchainImage";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SWAPCHAIN(sc, swapchain);
  if (info != nullptr) {
    M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_SWAPCHAIN_IMAGE_RELEASE_INFO, "releaseInfo");
  }
  M2S_SIM_REQUIRE(!sc->acquired.empty() && sc->oldest_waited, XR_ERROR_CALL_ORDER_INVALID,
                  "release without a successful xrWaitSwapchainImage");
  sc->last_released = sc->acquired.front();
  sc->acquired.pop_front();
  sc->oldest_waited = false;
  return XR_SUCCESS;
}

}  // namespace api
}  // namespace m2s::xrsim
