// The runtime's implementations of the OpenXR functions, looked up by name in
// xrGetInstanceProcAddr (entry.cc). They are not exported: the loader reaches them only
// through the table, so they never clash with the loader's own exported symbols.
#pragma once

#include "sim_state.h"

namespace m2s::xrsim::api {

#define M2S_XR_SIM_FUNCTIONS(X)           \
  X(EnumerateInstanceExtensionProperties) \
  X(EnumerateApiLayerProperties)          \
  X(CreateInstance)                       \
  X(DestroyInstance)                      \
  X(GetInstanceProperties)                \
  X(PollEvent)                            \
  X(ResultToString)                       \
  X(StructureTypeToString)                \
  X(GetSystem)                            \
  X(GetSystemProperties)                  \
  X(EnumerateEnvironmentBlendModes)       \
  X(EnumerateViewConfigurations)          \
  X(GetViewConfigurationProperties)       \
  X(EnumerateViewConfigurationViews)      \
  X(CreateSession)                        \
  X(DestroySession)                       \
  X(BeginSession)                         \
  X(EndSession)                           \
  X(RequestExitSession)                   \
  X(EnumerateReferenceSpaces)             \
  X(CreateReferenceSpace)                 \
  X(GetReferenceSpaceBoundsRect)          \
  X(DestroySpace)                         \
  X(LocateSpace)                          \
  X(LocateViews)                          \
  X(EnumerateSwapchainFormats)            \
  X(CreateSwapchain)                      \
  X(DestroySwapchain)                     \
  X(EnumerateSwapchainImages)             \
  X(AcquireSwapchainImage)                \
  X(WaitSwapchainImage)                   \
  X(ReleaseSwapchainImage)                \
  X(WaitFrame)                            \
  X(BeginFrame)                           \
  X(EndFrame)                             \
  X(StringToPath)                         \
  X(PathToString)                         \
  X(CreateActionSet)                      \
  X(DestroyActionSet)                     \
  X(CreateAction)                         \
  X(DestroyAction)                        \
  X(SuggestInteractionProfileBindings)    \
  X(AttachSessionActionSets)              \
  X(GetCurrentInteractionProfile)         \
  X(SyncActions)                          \
  X(GetActionStateBoolean)                \
  X(GetActionStateFloat)

XrResult XRAPI_CALL EnumerateInstanceExtensionProperties(const char* layerName, uint32_t capacity,
                                                         uint32_t* count,
                                                         XrExtensionProperties* properties);
XrResult XRAPI_CALL EnumerateApiLayerProperties(uint32_t capacity, uint32_t* count,
                                                XrApiLayerProperties* properties);
XrResult XRAPI_CALL CreateInstance(const XrInstanceCreateInfo* info, XrInstance* instance);
XrResult XRAPI_CALL DestroyInstance(XrInstance instance);
XrResult XRAPI_CALL GetInstanceProperties(XrInstance instance, XrInstanceProperties* properties);
XrResult XRAPI_CALL PollEvent(XrInstance instance, XrEventDataBuffer* event);
XrResult XRAPI_CALL ResultToString(XrInstance instance, XrResult value,
                                   char buffer[XR_MAX_RESULT_STRING_SIZE]);
XrResult XRAPI_CALL StructureTypeToString(XrInstance instance, XrStructureType value,
                                          char buffer[XR_MAX_STRUCTURE_NAME_SIZE]);
XrResult XRAPI_CALL GetSystem(XrInstance instance, const XrSystemGetInfo* info,
                              XrSystemId* system_id);
XrResult XRAPI_CALL GetSystemProperties(XrInstance instance, XrSystemId system_id,
                                        XrSystemProperties* properties);
XrResult XRAPI_CALL EnumerateEnvironmentBlendModes(XrInstance instance, XrSystemId system_id,
                                                   XrViewConfigurationType type, uint32_t capacity,
                                                   uint32_t* count, XrEnvironmentBlendMode* modes);
XrResult XRAPI_CALL EnumerateViewConfigurations(XrInstance instance, XrSystemId system_id,
                                                uint32_t capacity, uint32_t* count,
                                                XrViewConfigurationType* types);
XrResult XRAPI_CALL GetViewConfigurationProperties(XrInstance instance, XrSystemId system_id,
                                                   XrViewConfigurationType type,
                                                   XrViewConfigurationProperties* properties);
XrResult XRAPI_CALL EnumerateViewConfigurationViews(XrInstance instance, XrSystemId system_id,
                                                    XrViewConfigurationType type, uint32_t capacity,
                                                    uint32_t* count,
                                                    XrViewConfigurationView* views);
XrResult XRAPI_CALL CreateSession(XrInstance instance, const XrSessionCreateInfo* info,
                                  XrSession* session);
XrResult XRAPI_CALL DestroySession(XrSession session);
XrResult XRAPI_CALL BeginSession(XrSession session, const XrSessionBeginInfo* info);
XrResult XRAPI_CALL EndSession(XrSession session);
XrResult XRAPI_CALL RequestExitSession(XrSession session);
XrResult XRAPI_CALL EnumerateReferenceSpaces(XrSession session, uint32_t capacity, uint32_t* count,
                                             XrReferenceSpaceType* spaces);
XrResult XRAPI_CALL CreateReferenceSpace(XrSession session, const XrReferenceSpaceCreateInfo* info,
                                         XrSpace* space);
XrResult XRAPI_CALL GetReferenceSpaceBoundsRect(XrSession session, XrReferenceSpaceType type,
                                                XrExtent2Df* bounds);
XrResult XRAPI_CALL DestroySpace(XrSpace space);
XrResult XRAPI_CALL LocateSpace(XrSpace space, XrSpace base_space, XrTime time,
                                XrSpaceLocation* location);
XrResult XRAPI_CALL LocateViews(XrSession session, const XrViewLocateInfo* info,
                                XrViewState* view_state, uint32_t capacity, uint32_t* count,
                                XrView* views);
XrResult XRAPI_CALL EnumerateSwapchainFormats(XrSession session, uint32_t capacity, uint32_t* count,
                                              int64_t* formats);
XrResult XRAPI_CALL CreateSwapchain(XrSession session, const XrSwapchainCreateInfo* info,
                                    XrSwapchain* swapchain);
XrResult XRAPI_CALL DestroySwapchain(XrSwapchain swapchain);
XrResult XRAPI_CALL EnumerateSwapchainImages(XrSwapchain swapchain, uint32_t capacity,
                                             uint32_t* count, XrSwapchainImageBaseHeader* images);
XrResult XRAPI_CALL AcquireSwapchainImage(XrSwapchain swapchain,
                                          const XrSwapchainImageAcquireInfo* info, uint32_t* index);
XrResult XRAPI_CALL WaitSwapchainImage(XrSwapchain swapchain, const XrSwapchainImageWaitInfo* info);
XrResult XRAPI_CALL ReleaseSwapchainImage(XrSwapchain swapchain,
                                          const XrSwapchainImageReleaseInfo* info);
XrResult XRAPI_CALL WaitFrame(XrSession session, const XrFrameWaitInfo* info, XrFrameState* state);
XrResult XRAPI_CALL BeginFrame(XrSession session, const XrFrameBeginInfo* info);
XrResult XRAPI_CALL EndFrame(XrSession session, const XrFrameEndInfo* info);
XrResult XRAPI_CALL StringToPath(XrInstance instance, const char* path_string, XrPath* path);
XrResult XRAPI_CALL PathToString(XrInstance instance, XrPath path, uint32_t capacity,
                                 uint32_t* count, char* buffer);
XrResult XRAPI_CALL CreateActionSet(XrInstance instance, const XrActionSetCreateInfo* info,
                                    XrActionSet* action_set);
XrResult XRAPI_CALL DestroyActionSet(XrActionSet action_set);
XrResult XRAPI_CALL CreateAction(XrActionSet action_set, const XrActionCreateInfo* info,
                                 XrAction* action);
XrResult XRAPI_CALL DestroyAction(XrAction action);
XrResult XRAPI_CALL SuggestInteractionProfileBindings(
    XrInstance instance, const XrInteractionProfileSuggestedBinding* suggested);
XrResult XRAPI_CALL AttachSessionActionSets(XrSession session,
                                            const XrSessionActionSetsAttachInfo* info);
XrResult XRAPI_CALL GetCurrentInteractionProfile(XrSession session, XrPath top_level_user_path,
                                                 XrInteractionProfileState* profile);
XrResult XRAPI_CALL SyncActions(XrSession session, const XrActionsSyncInfo* info);
XrResult XRAPI_CALL GetActionStateBoolean(XrSession session, const XrActionStateGetInfo* info,
                                          XrActionStateBoolean* state);
XrResult XRAPI_CALL GetActionStateFloat(XrSession session, const XrActionStateGetInfo* info,
                                        XrActionStateFloat* state);

}  // namespace m2s::xrsim::api

// Checks shared by the entry points. `kFn` names the function in misuse messages.
#define M2S_SIM_REQUIRE(cond, result, message)                                     \
  do {                                                                             \
    if (!(cond)) return ::m2s::xrsim::Runtime::Get().Misuse(kFn, result, message); \
  } while (0)
#define M2S_SIM_REQUIRE_TYPE(ptr, xr_type, what)                                     \
  do {                                                                               \
    M2S_SIM_REQUIRE((ptr) != nullptr, XR_ERROR_VALIDATION_FAILURE, what " is NULL"); \
    M2S_SIM_REQUIRE((ptr)->type == (xr_type), XR_ERROR_VALIDATION_FAILURE,           \
                    std::string(what ".type is not " #xr_type));                     \
  } while (0)
// Instance lookup shared by the instance-level functions; lost instances answer
// XR_ERROR_INSTANCE_LOST (not misuse: the runtime caused it).
#define M2S_SIM_INSTANCE(var, handle)                                             \
  InstanceObj* var = Runtime::Get().FindInstance(handle);                         \
  M2S_SIM_REQUIRE(var != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrInstance"); \
  if (var->lost) return XR_ERROR_INSTANCE_LOST
// Session lookup shared by the session-level functions: a lost instance or session answers
// XR_ERROR_INSTANCE_LOST / XR_ERROR_SESSION_LOST (the runtime caused it: not misuse).
#define M2S_SIM_SESSION(var, inst, handle)                                       \
  SessionObj* var = Runtime::Get().FindSession(handle);                          \
  M2S_SIM_REQUIRE(var != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrSession"); \
  InstanceObj* inst = Runtime::Get().InstanceOf(*var);                           \
  if (inst->lost) return XR_ERROR_INSTANCE_LOST;                                 \
  if (var->lost) return XR_ERROR_SESSION_LOST

namespace m2s::xrsim::api {

// The two-call idiom (spec 2.11): capacity 0 asks for the count.
template <typename T, typename Fill>
XrResult TwoCall(const char* kFn, uint32_t capacity, uint32_t* count, T* items, uint32_t n,
                 Fill fill) {
  M2S_SIM_REQUIRE(count != nullptr, XR_ERROR_VALIDATION_FAILURE, "count output is NULL");
  *count = n;
  if (capacity == 0) return XR_SUCCESS;
  M2S_SIM_REQUIRE(capacity >= n, XR_ERROR_SIZE_INSUFFICIENT,
                  "capacity " + std::to_string(capacity) + " < " + std::to_string(n));
  M2S_SIM_REQUIRE(items != nullptr, XR_ERROR_VALIDATION_FAILURE, "array is NULL");
  for (uint32_t i = 0; i < n; ++i) {
    const XrResult r = fill(i, &items[i]);
    if (XR_FAILED(r)) return r;
  }
  return XR_SUCCESS;
}

}  // namespace m2s::xrsim::api
