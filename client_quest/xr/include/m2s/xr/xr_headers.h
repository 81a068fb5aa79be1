// The OpenXR headers with EGL + OpenGL ES enabled, included the same way everywhere.
#pragma once

#include <EGL/egl.h>
#include <EGL/eglext.h>
#if defined(__ANDROID__)
#include <jni.h>
#define XR_USE_PLATFORM_ANDROID
#else
#define XR_USE_PLATFORM_EGL
#endif
#define XR_USE_GRAPHICS_API_OPENGL_ES
#include <openxr/openxr.h>
#include <openxr/openxr_platform.h>
