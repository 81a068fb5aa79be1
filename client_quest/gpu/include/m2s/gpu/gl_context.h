// An OpenGL ES 3.1+ context: created headless through EGL, or adopted from a host application.
//
// CreateHeadless() tries, in order:
//   1. EGL_MESA_platform_surfaceless (Mesa: llvmpipe in CI, or a Mesa GPU driver),
//   2. EGL_EXT_device_enumeration + EGL_EXT_platform_device (NVIDIA's driver works headless so),
//   3. the default display with a 1x1 pbuffer surface,
// and on each display asks for GLES 3.2, then 3.1. Compute shaders need 3.1: a display that
// only offers less is skipped, and when none offers it the error says what was found. On a
// surfaceless-capable display no surface is made (all rendering goes to framebuffer objects).
//
// Adopt() wraps the context current on the calling thread (the OpenXR app's, on the headset)
// without owning it: MakeCurrent() re-binds exactly the display/surfaces/context captured at
// adoption, and the destructor leaves the context alone.
//
// With Options::debug (default on in builds without NDEBUG) the context is created with the
// debug flag and GL debug messages (KHR_debug / GLES 3.2) go to M2S_LOG.
//
// Thread-safety: a GL context is current on at most one thread at a time; the object itself is
// not thread-safe. Use it (and everything drawing with it) from one thread, or hand it over
// with ReleaseCurrent() / MakeCurrent().
//
//   auto context = m2s::GlContext::CreateHeadless();
//   if (!context) { M2S_LOG(kError) << context.error(); return; }
//   M2S_LOG(kInfo) << (*context)->renderer() << " / " << (*context)->version();
#pragma once

#include <memory>
#include <string>

#include "m2s/common/status.h"

namespace m2s {

class GlContext {
 public:
  struct Options {
#ifdef NDEBUG
    bool debug = false;  // create a debug context and log GL debug messages
#else
    bool debug = true;
#endif
    // Minimum GLES version accepted (3.1: compute shaders and SSBOs).
    int min_major = 3;
    int min_minor = 1;
  };

  // Creates and makes current a headless context (see the header comment for the order).
  static Expected<std::unique_ptr<GlContext>> CreateHeadless(const Options& options);
  static Expected<std::unique_ptr<GlContext>> CreateHeadless() { return CreateHeadless(Options{}); }
  // Wraps the EGL context current on this thread; error when none is current or it is below
  // GLES min_major.min_minor.
  static Expected<std::unique_ptr<GlContext>> Adopt(const Options& options);
  static Expected<std::unique_ptr<GlContext>> Adopt() { return Adopt(Options{}); }

  // True when at least one EGL display can be initialised in this process (used by tests to
  // decide between running and skipping).
  static bool AnyEglDisplayAvailable();

  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  // Binds this context to the calling thread (no-op when it already is).
  Status MakeCurrent();
  // Unbinds it from the calling thread (for an adopted context: unbinds whatever is current).
  Status ReleaseCurrent();
  bool IsCurrent() const;

  bool owned() const { return owned_; }
  // How the display was obtained: "surfaceless", "device", "default" or "adopted".
  const std::string& platform() const { return platform_; }
  const std::string& renderer() const { return renderer_; }  // GL_RENDERER
  const std::string& vendor() const { return vendor_; }      // GL_VENDOR
  const std::string& version() const { return version_; }    // GL_VERSION
  int major_version() const { return major_; }
  int minor_version() const { return minor_; }
  bool HasExtension(const std::string& name) const;

  // The raw EGL handles (EGLDisplay, EGLContext), for interop with a host application.
  void* egl_display() const { return display_; }
  void* egl_context() const { return context_; }

 private:
  GlContext() = default;
  Status QueryInfo(const Options& options);

  void* display_ = nullptr;
  void* context_ = nullptr;
  void* draw_surface_ = nullptr;
  void* read_surface_ = nullptr;
  bool owned_ = false;
  std::string platform_;
  std::string renderer_, vendor_, version_, extensions_;
  int major_ = 0;
  int minor_ = 0;
};

}  // namespace m2s
