// The loader <-> runtime negotiation ABI of the OpenXR loader (OpenXR-SDK
// src/common/loader_interfaces.h, interface version 1). Debian's libopenxr-dev does not ship
// that header, so the few structures are declared here, layout for layout.
#pragma once

#include <cstddef>
#include <cstdint>

#include <openxr/openxr.h>

extern "C" {

typedef enum XrLoaderInterfaceStructs {
  XR_LOADER_INTERFACE_STRUCT_UNINTIALIZED = 0,
  XR_LOADER_INTERFACE_STRUCT_LOADER_INFO,
  XR_LOADER_INTERFACE_STRUCT_API_LAYER_REQUEST,
  XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST,
  XR_LOADER_INTERFACE_STRUCT_API_LAYER_CREATE_INFO,
  XR_LOADER_INTERFACE_STRUCT_API_LAYER_NEXT_INFO,
} XrLoaderInterfaceStructs;

#define XR_LOADER_INFO_STRUCT_VERSION 1
typedef struct XrNegotiateLoaderInfo {
  XrLoaderInterfaceStructs structType;  // XR_LOADER_INTERFACE_STRUCT_LOADER_INFO
  uint32_t structVersion;               // XR_LOADER_INFO_STRUCT_VERSION
  size_t structSize;                    // sizeof(XrNegotiateLoaderInfo)
  uint32_t minInterfaceVersion;
  uint32_t maxInterfaceVersion;
  XrVersion minApiVersion;
  XrVersion maxApiVersion;
} XrNegotiateLoaderInfo;

#define XR_CURRENT_LOADER_RUNTIME_VERSION 1
#define XR_RUNTIME_INFO_STRUCT_VERSION 1
typedef struct XrNegotiateRuntimeRequest {
  XrLoaderInterfaceStructs structType;            // XR_LOADER_INTERFACE_STRUCT_RUNTIME_REQUEST
  uint32_t structVersion;                         // XR_RUNTIME_INFO_STRUCT_VERSION
  size_t structSize;                              // sizeof(XrNegotiateRuntimeRequest)
  uint32_t runtimeInterfaceVersion;               // filled in by the runtime
  XrVersion runtimeApiVersion;                    // filled in by the runtime
  PFN_xrGetInstanceProcAddr getInstanceProcAddr;  // filled in by the runtime
} XrNegotiateRuntimeRequest;

}  // extern "C"
