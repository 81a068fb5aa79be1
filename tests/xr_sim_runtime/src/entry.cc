// Loader negotiation, the function table, and the runtime-wide helpers.
#include <cstring>
#include <iostream>

#include <openxr/openxr_reflection.h>

#include "api.h"
#include "loader_negotiation.h"

namespace m2s::xrsim {

Runtime& Runtime::Get() {
  static Runtime runtime;
  return runtime;
}

XrResult Runtime::Misuse(const char* function, XrResult result, const std::string& message) {
  misuse_log_.push_back(std::string(function) + ": " + ResultName(result) + ": " + message);
  std::cerr << "m2s_xr_sim: MISUSE #" << misuse_log_.size() << " in " << function << ": "
            << ResultName(result) << ": " << message << std::endl;
  return result;
}

void Runtime::MisuseWithoutError(const char* function, const std::string& message) {
  misuse_log_.push_back(std::string(function) + ": " + message);
  std::cerr << "m2s_xr_sim: MISUSE #" << misuse_log_.size() << " in " << function << ": " << message
            << std::endl;
}

void LogInfo(const std::string& message) { std::cerr << "m2s_xr_sim: " << message << std::endl; }

const char* ResultName(XrResult result) {
#define M2S_SIM_RESULT_CASE(name, value) \
  case name:                             \
    return #name;
  switch (result) {
    XR_LIST_ENUM_XrResult(M2S_SIM_RESULT_CASE) default : return "XR_UNKNOWN_RESULT";
  }
#undef M2S_SIM_RESULT_CASE
}

const char* StateName(XrSessionState state) {
#define M2S_SIM_STATE_CASE(name, value) \
  case name:                            \
    return #name;
  switch (state) {
    XR_LIST_ENUM_XrSessionState(M2S_SIM_STATE_CASE) default : return "XR_SESSION_STATE_INVALID";
  }
#undef M2S_SIM_STATE_CASE
}

namespace {

const char* StructureTypeName(XrStructureType type) {
#define M2S_SIM_TYPE_CASE(name, value) \
  case name:                           \
    return #name;
  switch (type) { XR_LIST_ENUM_XrStructureType(M2S_SIM_TYPE_CASE) default : return nullptr; }
#undef M2S_SIM_TYPE_CASE
}

struct NamedFunction {
  const char* name;
  PFN_xrVoidFunction function;
};

const NamedFunction kFunctions[] = {
#define M2S_SIM_ENTRY(name) {"xr" #name, reinterpret_cast<PFN_xrVoidFunction>(&api::name)},
    M2S_XR_SIM_FUNCTIONS(M2S_SIM_ENTRY)
#undef M2S_SIM_ENTRY
};

XrResult XRAPI_CALL GetInstanceProcAddr(XrInstance instance, const char* name,
                                        PFN_xrVoidFunction* function) {
  constexpr const char* kFn = "xrGetInstanceProcAddr";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_REQUIRE(name != nullptr && function != nullptr, XR_ERROR_VALIDATION_FAILURE,
                  "name or function is NULL");
  *function = nullptr;
  const std::string wanted = name;
  if (wanted == "xrGetInstanceProcAddr") {
    *function = reinterpret_cast<PFN_xrVoidFunction>(&GetInstanceProcAddr);
    return XR_SUCCESS;
  }
  if (instance == XR_NULL_HANDLE) {
    // Only these may be queried before an instance exists (spec 3.2).
    if (wanted != "xrEnumerateInstanceExtensionProperties" &&
        wanted != "xrEnumerateApiLayerProperties" && wanted != "xrCreateInstance") {
      return Runtime::Get().Misuse(kFn, XR_ERROR_HANDLE_INVALID,
                                   wanted + " queried with XR_NULL_HANDLE instance");
    }
  } else if (Runtime::Get().FindInstance(instance) == nullptr) {
    return Runtime::Get().Misuse(kFn, XR_ERROR_HANDLE_INVALID, "unknown instance for " + wanted);
  }
  for (const NamedFunction& entry : kFunctions) {
    if (wanted == entry.name) {
      *function = entry.function;
      return XR_SUCCESS;
    }
  }
  // Not an error of the caller: the loader asks for every core function it knows.
  return XR_ERROR_FUNCTION_UNSUPPORTED;
}

}  // namespace

namespace api {

XrResult XRAPI_CALL ResultToString(XrInstance instance, XrResult value,
                                   char buffer[XR_MAX_RESULT_STRING_SIZE]) {
  constexpr const char* kFn = "xrResultToString";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_REQUIRE(Runtime::Get().FindInstance(instance) != nullptr, XR_ERROR_HANDLE_INVALID,
                  "unknown instance");
  M2S_SIM_REQUIRE(buffer != nullptr, XR_ERROR_VALIDATION_FAILURE, "buffer is NULL");
  const char* name = ResultName(value);
  if (std::strcmp(name, "XR_UNKNOWN_RESULT") == 0) {
    std::snprintf(buffer, XR_MAX_RESULT_STRING_SIZE, "XR_%s_%d",
                  value < 0 ? "UNKNOWN_FAILURE" : "UNKNOWN_SUCCESS", static_cast<int>(value));
  } else {
    std::snprintf(buffer, XR_MAX_RESULT_STRING_SIZE, "%s", name);
  }
  return XR_SUCCESS;
}

XrResult XRAPI_CALL StructureTypeToString(XrInstance instance, XrStructureType value,
                                          char buffer[XR_MAX_STRUCTURE_NAME_SIZE]) {
  constexpr const char* kFn = "xrStructureTypeToString";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_REQUIRE(Runtime::Get().FindInstance(instance) != nullptr, XR_ERROR_HANDLE_INVALID,
                  "unknown instance");
  M2S_SIM_REQUIRE(buffer != nullptr, XR_ERROR_VALIDATION_FAILURE, "buffer is NULL");
  const char* name = StructureTypeName(value);
  if (name == nullptr) {
    std::snprintf(buffer, XR_MAX_STRUCTURE_NAME_SIZE, "XR_UNKNOWN_STRUCTURE_TYPE_%d",
                  static_cast<int>(value));
  } else {
    std::snprintf(buffer, XR_MAX_STRUCTURE_NAME_SIZE, "%s", name);
  }
  return XR_SUCCESS;
}

}  // namespace api
}  // namespace m2s::xrsim

// The one exported symbol: the loader finds it by name in the library the manifest names.
extern "C" __attribute__((visibility("default"))) XrResult XRAPI_CALL
xrNegotiateLoaderRuntimeInterface(const XrNegotiateLoaderInfo* loader_info,
                                  XrNegotiateRuntimeRequest* runtime_request) {
  using m2s::xrsim::Runtime;
  constexpr const char* kFn = "xrNegotiateLoaderRuntimeInterface";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  if (loader_info == nullptr || runtime_request == nullptr ||
      loader_info->structType != XR_LOADER_INTERFACE_STRUCT_LOADER_INFO ||
      loader_info->structVersion != XR_LOADER_INFO_STRUCT_VERSION ||
      loader_info->structSize != sizeof(XrNegotiateLoaderInfo) ||
      runtime_request->structType != XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST ||
      runtime_request->structVersion != XR_RUNTIME_INFO_STRUCT_VERSION ||
      runtime_request->structSize != sizeof(XrNegotiateRuntimeRequest)) {
    return Runtime::Get().Misuse(kFn, XR_ERROR_INITIALIZATION_FAILED,
                                 "malformed negotiation structures");
  }
  if (loader_info->minInterfaceVersion > XR_CURRENT_LOADER_RUNTIME_VERSION ||
      loader_info->maxInterfaceVersion < XR_CURRENT_LOADER_RUNTIME_VERSION ||
      XR_VERSION_MAJOR(loader_info->minApiVersion) > 1 ||
      XR_VERSION_MAJOR(loader_info->maxApiVersion) < 1) {
    return Runtime::Get().Misuse(kFn, XR_ERROR_INITIALIZATION_FAILED,
                                 "no common interface or API version");
  }
  runtime_request->runtimeInterfaceVersion = XR_CURRENT_LOADER_RUNTIME_VERSION;
  runtime_request->runtimeApiVersion = XR_CURRENT_API_VERSION;
  runtime_request->getInstanceProcAddr = &m2s::xrsim::GetInstanceProcAddr;
  return XR_SUCCESS;
}
