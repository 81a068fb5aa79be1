#include "m2s/gpu/gl_context.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl32.h>

#include <cstdio>
#include <cstring>
#include <sstream>
#include <vector>

#include "m2s/common/logging.h"

namespace m2s {
namespace {

bool HasToken(const char* list, const char* token) {
  if (list == nullptr) return false;
  const size_t n = std::strlen(token);
  for (const char* p = list; (p = std::strstr(p, token)) != nullptr; p += n) {
    const bool starts = p == list || p[-1] == ' ';
    const bool ends = p[n] == '\0' || p[n] == ' ';
    if (starts && ends) return true;
  }
  return false;
}

std::string EglErrorString(EGLint error) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "EGL error 0x%04x", static_cast<unsigned>(error));
  return buffer;
}

void GL_APIENTRY DebugCallback(GLenum /*source*/, GLenum type, GLuint id, GLenum severity,
                               GLsizei /*length*/, const GLchar* message, const void* /*user*/) {
  if (severity == GL_DEBUG_SEVERITY_NOTIFICATION) return;
  const LogLevel level = type == GL_DEBUG_TYPE_ERROR          ? LogLevel::kError
                         : severity == GL_DEBUG_SEVERITY_HIGH ? LogLevel::kWarning
                                                              : LogLevel::kDebug;
  std::ostringstream os;
  os << "GL debug [" << id << "]: " << message;
  Log(level, os.str());
}

void InstallDebugCallback() {
  using Proc = void(GL_APIENTRY*)(GLDEBUGPROC, const void*);
  auto proc = reinterpret_cast<Proc>(eglGetProcAddress("glDebugMessageCallback"));
  if (proc == nullptr)
    proc = reinterpret_cast<Proc>(eglGetProcAddress("glDebugMessageCallbackKHR"));
  if (proc == nullptr) return;
  glEnable(GL_DEBUG_OUTPUT);
  proc(&DebugCallback, nullptr);
}

struct Candidate {
  EGLDisplay display;
  std::string platform;
};

// Every display worth trying, in the documented order (not yet initialised).
std::vector<Candidate> CandidateDisplays() {
  std::vector<Candidate> out;
  const char* client_ext = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  auto get_platform_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(
      eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (get_platform_display != nullptr && HasToken(client_ext, "EGL_MESA_platform_surfaceless")) {
    EGLDisplay d =
        get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (d != EGL_NO_DISPLAY) out.push_back({d, "surfaceless"});
  }
  auto query_devices =
      reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
  if (get_platform_display != nullptr && query_devices != nullptr &&
      HasToken(client_ext, "EGL_EXT_platform_device")) {
    constexpr EGLint kMaxDevices = 16;
    EGLDeviceEXT devices[kMaxDevices];
    EGLint num_devices = 0;
    if (query_devices(kMaxDevices, devices, &num_devices)) {
      for (EGLint i = 0; i < num_devices; ++i) {
        EGLDisplay d = get_platform_display(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr);
        if (d != EGL_NO_DISPLAY) out.push_back({d, "device"});
      }
    }
  }
  EGLDisplay d = eglGetDisplay(EGL_DEFAULT_DISPLAY);
  if (d != EGL_NO_DISPLAY) out.push_back({d, "default"});
  return out;
}

}  // namespace

bool GlContext::AnyEglDisplayAvailable() {
  for (const Candidate& c : CandidateDisplays()) {
    EGLint major = 0, minor = 0;
    if (eglInitialize(c.display, &major, &minor)) return true;
  }
  return false;
}

Expected<std::unique_ptr<GlContext>> GlContext::CreateHeadless(const Options& options) {
  std::vector<std::string> failures;
  for (const Candidate& candidate : CandidateDisplays()) {
    EGLDisplay display = candidate.display;
    EGLint egl_major = 0, egl_minor = 0;
    if (!eglInitialize(display, &egl_major, &egl_minor)) {
      failures.push_back(candidate.platform + ": eglInitialize failed (" +
                         EglErrorString(eglGetError()) + ")");
      continue;
    }
    if (!eglBindAPI(EGL_OPENGL_ES_API)) {
      failures.push_back(candidate.platform + ": no OpenGL ES API");
      continue;
    }
    const char* display_ext = eglQueryString(display, EGL_EXTENSIONS);
    const bool surfaceless = HasToken(display_ext, "EGL_KHR_surfaceless_context");
    const EGLint config_attribs[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_ES3_BIT, EGL_SURFACE_TYPE,
                                     surfaceless ? 0 : EGL_PBUFFER_BIT, EGL_NONE};
    EGLConfig config = nullptr;
    EGLint num_configs = 0;
    if (!eglChooseConfig(display, config_attribs, &config, 1, &num_configs) || num_configs < 1) {
      failures.push_back(candidate.platform + ": no GLES 3 config");
      continue;
    }
    EGLContext context = EGL_NO_CONTEXT;
    // Newest first; the debug flag is dropped when the driver refuses it.
    for (int minor : {2, 1, 0}) {
      if (3 < options.min_major || (3 == options.min_major && minor < options.min_minor)) break;
      for (bool debug : {options.debug, false}) {
        std::vector<EGLint> attribs = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION,
                                       minor};
        if (debug) attribs.insert(attribs.end(), {EGL_CONTEXT_OPENGL_DEBUG, EGL_TRUE});
        attribs.push_back(EGL_NONE);
        context = eglCreateContext(display, config, EGL_NO_CONTEXT, attribs.data());
        if (context != EGL_NO_CONTEXT || !debug) break;
      }
      if (context != EGL_NO_CONTEXT) break;
    }
    if (context == EGL_NO_CONTEXT) {
      failures.push_back(candidate.platform + ": no GLES " + std::to_string(options.min_major) +
                         "." + std::to_string(options.min_minor) + " context (" +
                         EglErrorString(eglGetError()) + ")");
      continue;
    }
    EGLSurface surface = EGL_NO_SURFACE;
    if (!surfaceless) {
      const EGLint pbuffer_attribs[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
      surface = eglCreatePbufferSurface(display, config, pbuffer_attribs);
      if (surface == EGL_NO_SURFACE) {
        eglDestroyContext(display, context);
        failures.push_back(candidate.platform + ": no pbuffer surface");
        continue;
      }
    }
    std::unique_ptr<GlContext> result(new GlContext());
    result->display_ = display;
    result->context_ = context;
    result->draw_surface_ = surface;
    result->read_surface_ = surface;
    result->owned_ = true;
    result->platform_ = candidate.platform;
    if (Status s = result->MakeCurrent(); !s) {
      failures.push_back(candidate.platform + ": " + s.message());
      continue;  // the destructor releases what was created
    }
    if (Status s = result->QueryInfo(options); !s) {
      failures.push_back(candidate.platform + ": " + s.message());
      continue;
    }
    return result;
  }
  if (failures.empty()) return Expected<std::unique_ptr<GlContext>>::Error("no EGL display found");
  std::string message = "no usable GLES context:";
  for (const std::string& f : failures) message += " [" + f + "]";
  return Expected<std::unique_ptr<GlContext>>::Error(message);
}

Expected<std::unique_ptr<GlContext>> GlContext::Adopt(const Options& options) {
  EGLContext context = eglGetCurrentContext();
  if (context == EGL_NO_CONTEXT) {
    return Expected<std::unique_ptr<GlContext>>::Error(
        "GlContext::Adopt: no EGL context is current on this thread");
  }
  std::unique_ptr<GlContext> result(new GlContext());
  result->display_ = eglGetCurrentDisplay();
  result->context_ = context;
  result->draw_surface_ = eglGetCurrentSurface(EGL_DRAW);
  result->read_surface_ = eglGetCurrentSurface(EGL_READ);
  result->owned_ = false;
  result->platform_ = "adopted";
  if (Status s = result->QueryInfo(options); !s) return s;
  return result;
}

GlContext::~GlContext() {
  if (!owned_) return;
  if (eglGetCurrentContext() == context_) {
    eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  }
  if (draw_surface_ != EGL_NO_SURFACE) eglDestroySurface(display_, draw_surface_);
  eglDestroyContext(display_, context_);
  // The display is not terminated: EGL displays are process-wide and not reference counted,
  // so other contexts (another projector, the renderer) may still use it.
}

Status GlContext::MakeCurrent() {
  if (IsCurrent()) return Status::Ok();
  if (!eglMakeCurrent(display_, draw_surface_, read_surface_, context_)) {
    return Status::Error("eglMakeCurrent failed (" + EglErrorString(eglGetError()) + ")");
  }
  return Status::Ok();
}

Status GlContext::ReleaseCurrent() {
  EGLDisplay display = owned_ ? display_ : eglGetCurrentDisplay();
  if (display == EGL_NO_DISPLAY || eglGetCurrentContext() == EGL_NO_CONTEXT) return Status::Ok();
  if (!eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)) {
    return Status::Error("eglMakeCurrent(none) failed (" + EglErrorString(eglGetError()) + ")");
  }
  return Status::Ok();
}

bool GlContext::IsCurrent() const {
  return eglGetCurrentContext() == context_ && eglGetCurrentDisplay() == display_ &&
         eglGetCurrentSurface(EGL_DRAW) == draw_surface_;
}

bool GlContext::HasExtension(const std::string& name) const {
  return HasToken(extensions_.c_str(), name.c_str());
}

Status GlContext::QueryInfo(const Options& options) {
  auto str = [](GLenum name) {
    const GLubyte* s = glGetString(name);
    return s ? std::string(reinterpret_cast<const char*>(s)) : std::string();
  };
  renderer_ = str(GL_RENDERER);
  vendor_ = str(GL_VENDOR);
  version_ = str(GL_VERSION);
  glGetIntegerv(GL_MAJOR_VERSION, &major_);
  glGetIntegerv(GL_MINOR_VERSION, &minor_);
  if (version_.rfind("OpenGL ES", 0) != 0) {
    return Status::Error("the context is not OpenGL ES (GL_VERSION \"" + version_ + "\")");
  }
  if (major_ < options.min_major || (major_ == options.min_major && minor_ < options.min_minor)) {
    return Status::Error("GLES " + std::to_string(options.min_major) + "." +
                         std::to_string(options.min_minor) + " required (compute shaders), got \"" +
                         version_ + "\" on " + renderer_);
  }
  GLint num_extensions = 0;
  glGetIntegerv(GL_NUM_EXTENSIONS, &num_extensions);
  extensions_.clear();
  for (GLint i = 0; i < num_extensions; ++i) {
    extensions_ += reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, i));
    extensions_ += ' ';
  }
  if (options.debug && owned_) InstallDebugCallback();
  return Status::Ok();
}

}  // namespace m2s
