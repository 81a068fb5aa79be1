// Platform glue of the OpenXR app, one implementation per platform, each in its own file:
//   Linux/desktop (client_quest/xr/src/platform_egl.cc): XR_MNDX_egl_enable with
//     XrGraphicsBindingEGLMNDX; works with Monado and with the simulated runtime of the tests.
//   Android/Quest (client_quest/android/platform_android.cc): XR_KHR_opengl_es_enable and
//     XR_KHR_android_create_instance, XrGraphicsBindingOpenGLESAndroidKHR.
// Everything else in client_quest/xr is platform-independent.
//
// The OpenXR headers come with the platform defines through xr_headers.h.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "m2s/common/status.h"
#include "m2s/xr/xr_headers.h"

namespace m2s::xr {

// The EGL objects of the app's GLES context, handed to the runtime at session creation.
struct EglHandles {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLConfig config = nullptr;
  EGLContext context = EGL_NO_CONTEXT;
};

class XrPlatform {
 public:
  virtual ~XrPlatform() = default;
  // Instance extensions the platform needs (graphics binding, Android instance creation).
  virtual std::vector<std::string> InstanceExtensions() const = 0;
  // Chained into XrInstanceCreateInfo::next (null on Linux).
  virtual const void* InstanceCreateNext() const = 0;
  // Called once per system before a session is created (graphics requirements where the
  // extension demands the call); an error names what is missing.
  virtual Status CheckGraphicsRequirements(XrInstance instance, XrSystemId system) = 0;
  // The graphics binding chained into XrSessionCreateInfo::next; valid until the next call.
  virtual const void* GraphicsBinding(const EglHandles& egl) = 0;
};

// The platform of this build (Linux: MNDX EGL). `android_app` is the android_app* of the
// native activity on Android and ignored elsewhere.
std::unique_ptr<XrPlatform> MakePlatform(void* android_app);

}  // namespace m2s::xr
