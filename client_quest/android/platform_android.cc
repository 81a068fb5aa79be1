// Android / Quest platform of the OpenXR app (see client_quest/xr/include/m2s/xr/xr_platform.h):
// XR_KHR_loader_init + XR_KHR_android_create_instance (the loader and the instance learn the
// JavaVM and the activity) and XR_KHR_opengl_es_enable (XrGraphicsBindingOpenGLESAndroidKHR,
// with the mandatory xrGetOpenGLESGraphicsRequirementsKHR call before xrCreateSession).
// Built only by the NDK (client_quest/android/CMakeLists.txt); not compiled on this machine.
#if defined(__ANDROID__)

#include <android_native_app_glue.h>

#include <GLES3/gl3.h>

#include "m2s/common/logging.h"
#include "m2s/xr/xr_platform.h"

namespace m2s::xr {
namespace {

class AndroidPlatform final : public XrPlatform {
 public:
  explicit AndroidPlatform(android_app* app) : app_(app) {
    // The Android loader must be initialised before any other OpenXR call.
    PFN_xrInitializeLoaderKHR initialize = nullptr;
    if (XR_SUCCEEDED(xrGetInstanceProcAddr(XR_NULL_HANDLE, "xrInitializeLoaderKHR",
                                           reinterpret_cast<PFN_xrVoidFunction*>(&initialize))) &&
        initialize != nullptr) {
      XrLoaderInitInfoAndroidKHR info{XR_TYPE_LOADER_INIT_INFO_ANDROID_KHR};
      info.applicationVM = app_->activity->vm;
      info.applicationContext = app_->activity->clazz;
      initialize(reinterpret_cast<const XrLoaderInitInfoBaseHeaderKHR*>(&info));
    }
    instance_info_ = {XR_TYPE_INSTANCE_CREATE_INFO_ANDROID_KHR};
    instance_info_.applicationVM = app_->activity->vm;
    instance_info_.applicationActivity = app_->activity->clazz;
  }

  std::vector<std::string> InstanceExtensions() const override {
    return {XR_KHR_OPENGL_ES_ENABLE_EXTENSION_NAME, XR_KHR_ANDROID_CREATE_INSTANCE_EXTENSION_NAME};
  }
  const void* InstanceCreateNext() const override { return &instance_info_; }

  Status CheckGraphicsRequirements(XrInstance instance, XrSystemId system) override {
    PFN_xrGetOpenGLESGraphicsRequirementsKHR get = nullptr;
    if (XR_FAILED(xrGetInstanceProcAddr(instance, "xrGetOpenGLESGraphicsRequirementsKHR",
                                        reinterpret_cast<PFN_xrVoidFunction*>(&get)))) {
      return Status::Error("xrGetOpenGLESGraphicsRequirementsKHR is missing");
    }
    XrGraphicsRequirementsOpenGLESKHR requirements{XR_TYPE_GRAPHICS_REQUIREMENTS_OPENGL_ES_KHR};
    if (XR_FAILED(get(instance, system, &requirements))) {
      return Status::Error("xrGetOpenGLESGraphicsRequirementsKHR failed");
    }
    GLint major = 0, minor = 0;
    glGetIntegerv(GL_MAJOR_VERSION, &major);
    glGetIntegerv(GL_MINOR_VERSION, &minor);
    const XrVersion have = XR_MAKE_VERSION(major, minor, 0);
    if (have < requirements.minApiVersionSupported) {
      return Status::Error("the runtime needs a newer OpenGL ES than " + std::to_string(major) +
                           "." + std::to_string(minor));
    }
    return Status::Ok();
  }

  const void* GraphicsBinding(const EglHandles& egl) override {
    binding_ = {XR_TYPE_GRAPHICS_BINDING_OPENGL_ES_ANDROID_KHR};
    binding_.display = egl.display;
    binding_.config = egl.config;
    binding_.context = egl.context;
    return &binding_;
  }

 private:
  android_app* const app_;
  XrInstanceCreateInfoAndroidKHR instance_info_{XR_TYPE_INSTANCE_CREATE_INFO_ANDROID_KHR};
  XrGraphicsBindingOpenGLESAndroidKHR binding_{XR_TYPE_GRAPHICS_BINDING_OPENGL_ES_ANDROID_KHR};
};

}  // namespace

std::unique_ptr<XrPlatform> MakePlatform(void* android_app_ptr) {
  return std::make_unique<AndroidPlatform>(static_cast<android_app*>(android_app_ptr));
}

}  // namespace m2s::xr

#endif  // __ANDROID__
