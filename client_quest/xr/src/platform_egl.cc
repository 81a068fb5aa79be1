// Linux / desktop platform: XR_MNDX_egl_enable (see xr_platform.h).
#if !defined(__ANDROID__)

#include "m2s/xr/xr_platform.h"

namespace m2s::xr {
namespace {

class EglPlatform final : public XrPlatform {
 public:
  std::vector<std::string> InstanceExtensions() const override {
    return {XR_MNDX_EGL_ENABLE_EXTENSION_NAME};
  }
  const void* InstanceCreateNext() const override { return nullptr; }
  // XR_MNDX_egl_enable has no graphics-requirements call.
  Status CheckGraphicsRequirements(XrInstance, XrSystemId) override { return Status::Ok(); }
  const void* GraphicsBinding(const EglHandles& egl) override {
    binding_ = {XR_TYPE_GRAPHICS_BINDING_EGL_MNDX};
    binding_.getProcAddress = &eglGetProcAddress;
    binding_.display = egl.display;
    binding_.config = egl.config;
    binding_.context = egl.context;
    return &binding_;
  }

 private:
  XrGraphicsBindingEGLMNDX binding_{XR_TYPE_GRAPHICS_BINDING_EGL_MNDX};
};

}  // namespace

std::unique_ptr<XrPlatform> MakePlatform(void*) { return std::make_unique<EglPlatform>(); }

}  // namespace m2s::xr

#endif  // !__ANDROID__
