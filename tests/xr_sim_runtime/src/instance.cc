// Instance, system, view configuration and event queue.
#include <cmath>
#include <cstring>

#include "api.h"

namespace m2s::xrsim::api {
namespace {

#define M2S_SIM_SYSTEM(instance, system_id)                                                        \
  M2S_SIM_REQUIRE((system_id) == kSystemId && (instance)->system_queried, XR_ERROR_SYSTEM_INVALID, \
                  "systemId was not returned by xrGetSystem")

}  // namespace

XrResult XRAPI_CALL EnumerateInstanceExtensionProperties(const char* layer_name, uint32_t capacity,
                                                         uint32_t* count,
                                                         XrExtensionProperties* properties) {
  constexpr const char* kFn = "xrEnumerateInstanceExtensionProperties";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_REQUIRE(layer_name == nullptr, XR_ERROR_API_LAYER_NOT_PRESENT,
                  "the runtime has no API layers");
  return TwoCall(
      kFn, capacity, count, properties, 1, [&](uint32_t, XrExtensionProperties* p) -> XrResult {
        M2S_SIM_REQUIRE(p->type == XR_TYPE_EXTENSION_PROPERTIES, XR_ERROR_VALIDATION_FAILURE,
                        "element type is not XR_TYPE_EXTENSION_PROPERTIES");
        std::snprintf(p->extensionName, XR_MAX_EXTENSION_NAME_SIZE, "%s",
                      XR_MNDX_EGL_ENABLE_EXTENSION_NAME);
        p->extensionVersion = XR_MNDX_egl_enable_SPEC_VERSION;
        return XR_SUCCESS;
      });
}

XrResult XRAPI_CALL EnumerateApiLayerProperties(uint32_t capacity, uint32_t* count,
                                                XrApiLayerProperties*) {
  constexpr const char* kFn = "xrEnumerateApiLayerProperties";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_REQUIRE(count != nullptr, XR_ERROR_VALIDATION_FAILURE, "count output is NULL");
  *count = 0;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL CreateInstance(const XrInstanceCreateInfo* info, XrInstance* instance) {
  constexpr const char* kFn = "xrCreateInstance";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_INSTANCE_CREATE_INFO, "createInfo");
  M2S_SIM_REQUIRE(instance != nullptr, XR_ERROR_VALIDATION_FAILURE, "instance output is NULL");
  M2S_SIM_REQUIRE(XR_VERSION_MAJOR(info->applicationInfo.apiVersion) == 1,
                  XR_ERROR_API_VERSION_UNSUPPORTED, "only OpenXR 1.x is supported");
  M2S_SIM_REQUIRE(info->applicationInfo.applicationName[0] != '\0', XR_ERROR_NAME_INVALID,
                  "applicationName is empty");
  auto obj = std::make_unique<InstanceObj>();
  for (uint32_t i = 0; i < info->enabledExtensionCount; ++i) {
    const char* name = info->enabledExtensionNames[i];
    M2S_SIM_REQUIRE(name != nullptr && std::strcmp(name, XR_MNDX_EGL_ENABLE_EXTENSION_NAME) == 0,
                    XR_ERROR_EXTENSION_NOT_PRESENT,
                    std::string("extension not supported: ") + (name ? name : "(null)"));
    obj->egl_enabled = true;
  }
  std::string why;
  if (!ReadConfigFromEnvironment(&obj->config, &why)) {
    LogInfo("ERROR: " + why);
    return XR_ERROR_RUNTIME_FAILURE;
  }
  if (!obj->config.trajectory_path.empty()) {
    if (!obj->trajectory.Load(obj->config.trajectory_path, &why)) {
      LogInfo("ERROR: " + why);
      return XR_ERROR_RUNTIME_FAILURE;
    }
    // Display time (ns) equals the trajectory stamp when the stamps are positive.
    obj->trajectory_time_origin = obj->trajectory.first_stamp();
    if (obj->trajectory.first_stamp() > 0.0) {
      obj->time_origin = static_cast<XrTime>(std::llround(obj->trajectory.first_stamp() * 1e9));
    }
  }
  obj->application_name = info->applicationInfo.applicationName;
  obj->wall_origin = std::chrono::steady_clock::now();
  obj->misuse_at_create = rt.misuse_count();
  obj->handle = ToHandle<XrInstance>(rt.NewHandle());
  *instance = obj->handle;
  LogInfo(
      "instance created for '" + obj->application_name + "' (rate " +
      std::to_string(obj->config.rate_hz) + " Hz, eye " + std::to_string(obj->config.eye_width) +
      "x" + std::to_string(obj->config.eye_height) +
      (obj->trajectory.empty() ? ", static head" : ", trajectory " + obj->config.trajectory_path) +
      ")");
  rt.instances[reinterpret_cast<uint64_t>(obj->handle)] = std::move(obj);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL DestroyInstance(XrInstance instance) {
  constexpr const char* kFn = "xrDestroyInstance";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  InstanceObj* obj = rt.FindInstance(instance);
  M2S_SIM_REQUIRE(obj != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrInstance");
  // Children the application left alive are destroyed with the instance and reported.
  int64_t live_children = 0;
  for (auto it = rt.sessions.begin(); it != rt.sessions.end();) {
    if (it->second->instance != instance) {
      ++it;
      continue;
    }
    const XrSession session = it->second->handle;
    for (auto s = rt.spaces.begin(); s != rt.spaces.end();) {
      s = s->second->session == session ? (++live_children, rt.spaces.erase(s)) : std::next(s);
    }
    for (auto s = rt.swapchains.begin(); s != rt.swapchains.end();) {
      s = s->second->session == session ? (++live_children, rt.swapchains.erase(s)) : std::next(s);
    }
    ++live_children;
    it = rt.sessions.erase(it);
  }
  for (auto it = rt.action_sets.begin(); it != rt.action_sets.end();) {
    const XrActionSet set = it->second->handle;
    ++it;
    if (rt.FindActionSet(set)->instance == instance) live_children += rt.EraseActionSet(set);
  }
  if (live_children > 0) {
    rt.MisuseWithoutError(
        kFn, std::to_string(live_children) + " child handle(s) still alive at xrDestroyInstance");
  }
  obj->counters.implicitly_destroyed += live_children;
  WriteReport(*obj, live_children);
  rt.instances.erase(reinterpret_cast<uint64_t>(instance));
  return XR_SUCCESS;
}

XrResult XRAPI_CALL GetInstanceProperties(XrInstance instance, XrInstanceProperties* properties) {
  constexpr const char* kFn = "xrGetInstanceProperties";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_INSTANCE(obj, instance);
  M2S_SIM_REQUIRE_TYPE(properties, XR_TYPE_INSTANCE_PROPERTIES, "instanceProperties");
  properties->runtimeVersion = XR_MAKE_VERSION(0, 1, 0);
  std::snprintf(properties->runtimeName, XR_MAX_RUNTIME_NAME_SIZE, "%s",
                "Mesh2SLAM simulated runtime");
  return XR_SUCCESS;
}

XrResult XRAPI_CALL PollEvent(XrInstance instance, XrEventDataBuffer* event) {
  constexpr const char* kFn = "xrPollEvent";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  InstanceObj* obj = Runtime::Get().FindInstance(instance);
  M2S_SIM_REQUIRE(obj != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrInstance");
  M2S_SIM_REQUIRE_TYPE(event, XR_TYPE_EVENT_DATA_BUFFER, "eventData");
  if (obj->events.empty()) return obj->lost ? XR_ERROR_INSTANCE_LOST : XR_EVENT_UNAVAILABLE;
  std::memcpy(event, &obj->events.front(), sizeof(XrEventDataBuffer));
  obj->events.pop_front();
  ++obj->counters.events_delivered;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL GetSystem(XrInstance instance, const XrSystemGetInfo* info,
                              XrSystemId* system_id) {
  constexpr const char* kFn = "xrGetSystem";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_INSTANCE(obj, instance);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_SYSTEM_GET_INFO, "getInfo");
  M2S_SIM_REQUIRE(system_id != nullptr, XR_ERROR_VALIDATION_FAILURE, "systemId is NULL");
  if (info->formFactor != XR_FORM_FACTOR_HEAD_MOUNTED_DISPLAY) {
    M2S_SIM_REQUIRE(info->formFactor == XR_FORM_FACTOR_HANDHELD_DISPLAY,
                    XR_ERROR_FORM_FACTOR_UNSUPPORTED, "formFactor is not a valid enum");
    return XR_ERROR_FORM_FACTOR_UNSUPPORTED;  // a valid question with a negative answer
  }
  if (obj->unavailable_system_calls > 0) {
    --obj->unavailable_system_calls;
    return XR_ERROR_FORM_FACTOR_UNAVAILABLE;  // after a session loss, for a few calls
  }
  obj->system_queried = true;
  *system_id = kSystemId;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL GetSystemProperties(XrInstance instance, XrSystemId system_id,
                                        XrSystemProperties* properties) {
  constexpr const char* kFn = "xrGetSystemProperties";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_INSTANCE(obj, instance);
  M2S_SIM_SYSTEM(obj, system_id);
  M2S_SIM_REQUIRE_TYPE(properties, XR_TYPE_SYSTEM_PROPERTIES, "properties");
  properties->systemId = system_id;
  properties->vendorId = 0x4D32;  // "M2"
  std::snprintf(properties->systemName, XR_MAX_SYSTEM_NAME_SIZE, "%s",
                "Mesh2SLAM simulated headset");
  properties->graphicsProperties.maxSwapchainImageWidth = kMaxSwapchainSize;
  properties->graphicsProperties.maxSwapchainImageHeight = kMaxSwapchainSize;
  properties->graphicsProperties.maxLayerCount = kMaxLayers;
  properties->trackingProperties.orientationTracking = XR_TRUE;
  properties->trackingProperties.positionTracking = XR_TRUE;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL EnumerateEnvironmentBlendModes(XrInstance instance, XrSystemId system_id,
                                                   XrViewConfigurationType type, uint32_t capacity,
                                                   uint32_t* count, XrEnvironmentBlendMode* modes) {
  constexpr const char* kFn = "xrEnumerateEnvironmentBlendModes";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_INSTANCE(obj, instance);
  M2S_SIM_SYSTEM(obj, system_id);
  M2S_SIM_REQUIRE(type == XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO,
                  XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED, "only PRIMARY_STEREO");
  return TwoCall(kFn, capacity, count, modes, 1, [](uint32_t, XrEnvironmentBlendMode* m) {
    *m = XR_ENVIRONMENT_BLEND_MODE_OPAQUE;
    return XR_SUCCESS;
  });
}

XrResult XRAPI_CALL EnumerateViewConfigurations(XrInstance instance, XrSystemId system_id,
                                                uint32_t capacity, uint32_t* count,
                                                XrViewConfigurationType* types) {
  constexpr const char* kFn = "xrEnumerateViewConfigurations";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_INSTANCE(obj, instance);
  M2S_SIM_SYSTEM(obj, system_id);
  return TwoCall(kFn, capacity, count, types, 1, [](uint32_t, XrViewConfigurationType* t) {
    *t = XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO;
    return XR_SUCCESS;
  });
}

XrResult XRAPI_CALL GetViewConfigurationProperties(XrInstance instance, XrSystemId system_id,
                                                   XrViewConfigurationType type,
                                                   XrViewConfigurationProperties* properties) {
  constexpr const char* kFn = "xrGetViewConfigurationProperties";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_INSTANCE(obj, instance);
  M2S_SIM_SYSTEM(obj, system_id);
  M2S_SIM_REQUIRE(type == XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO,
                  XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED, "only PRIMARY_STEREO");
  M2S_SIM_REQUIRE_TYPE(properties, XR_TYPE_VIEW_CONFIGURATION_PROPERTIES,
                       "configurationProperties");
  properties->viewConfigurationType = type;
  properties->fovMutable = XR_FALSE;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL EnumerateViewConfigurationViews(XrInstance instance, XrSystemId system_id,
                                                    XrViewConfigurationType type, uint32_t capacity,
                                                    uint32_t* count,
                                                    XrViewConfigurationView* views) {
  constexpr const char* kFn = "xrEnumerateViewConfigurationViews";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_INSTANCE(obj, instance);
  M2S_SIM_SYSTEM(obj, system_id);
  M2S_SIM_REQUIRE(type == XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO,
                  XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED, "only PRIMARY_STEREO");
  const SimConfig& config = obj->config;
  return TwoCall(
      kFn, capacity, count, views, 2, [&](uint32_t, XrViewConfigurationView* v) -> XrResult {
        M2S_SIM_REQUIRE(v->type == XR_TYPE_VIEW_CONFIGURATION_VIEW, XR_ERROR_VALIDATION_FAILURE,
                        "element type is not XR_TYPE_VIEW_CONFIGURATION_VIEW");
        v->recommendedImageRectWidth = config.eye_width;
        v->recommendedImageRectHeight = config.eye_height;
        v->maxImageRectWidth = kMaxSwapchainSize;
        v->maxImageRectHeight = kMaxSwapchainSize;
        v->recommendedSwapchainSampleCount = 1;
        v->maxSwapchainSampleCount = 1;
        return XR_SUCCESS;
      });
}

}  // namespace m2s::xrsim::api
