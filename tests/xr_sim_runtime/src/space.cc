// Reference spaces (VIEW, LOCAL, STAGE), xrLocateSpace and xrLocateViews.
#include <cmath>

#include "api.h"

namespace m2s::xrsim::api {
namespace {

SimPose FromXr(const XrPosef& p) {
  return {Eigen::Quaterniond(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z),
          Eigen::Vector3d(p.position.x, p.position.y, p.position.z)};
}

XrPosef ToXr(const SimPose& p) {
  const Eigen::Quaterniond q = p.rotation.normalized();
  XrPosef out;
  out.orientation = {static_cast<float>(q.x()), static_cast<float>(q.y()),
                     static_cast<float>(q.z()), static_cast<float>(q.w())};
  out.position = {static_cast<float>(p.translation.x()), static_cast<float>(p.translation.y()),
                  static_cast<float>(p.translation.z())};
  return out;
}

bool ValidPose(const XrPosef& p) {
  const double n = std::sqrt(p.orientation.x * p.orientation.x + p.orientation.y * p.orientation.y +
                             p.orientation.z * p.orientation.z + p.orientation.w * p.orientation.w);
  return std::isfinite(n) && std::abs(n - 1.0) <= 0.01 && std::isfinite(p.position.x) &&
         std::isfinite(p.position.y) && std::isfinite(p.position.z);
}

// The reference space's origin in LOCAL at a display time.
SimPose LocalFromReference(const InstanceObj& instance, XrReferenceSpaceType type, XrTime t) {
  switch (type) {
    case XR_REFERENCE_SPACE_TYPE_VIEW:
      return instance.Head(t);
    case XR_REFERENCE_SPACE_TYPE_STAGE:
      return {Eigen::Quaterniond::Identity(), instance.config.stage_offset};
    default:
      return {};
  }
}

SimPose LocalFromSpace(const InstanceObj& instance, const SpaceObj& space, XrTime t) {
  return LocalFromReference(instance, space.type, t) * space.reference_from_space;
}

bool Supported(XrReferenceSpaceType type) {
  return type == XR_REFERENCE_SPACE_TYPE_VIEW || type == XR_REFERENCE_SPACE_TYPE_LOCAL ||
         type == XR_REFERENCE_SPACE_TYPE_STAGE;
}

}  // namespace

XrResult XRAPI_CALL EnumerateReferenceSpaces(XrSession session, uint32_t capacity, uint32_t* count,
                                             XrReferenceSpaceType* spaces) {
  constexpr const char* kFn = "xrEnumerateReferenceSpaces";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  static constexpr XrReferenceSpaceType kTypes[] = {
      XR_REFERENCE_SPACE_TYPE_VIEW, XR_REFERENCE_SPACE_TYPE_LOCAL, XR_REFERENCE_SPACE_TYPE_STAGE};
  M2S_SIM_REQUIRE(count != nullptr, XR_ERROR_VALIDATION_FAILURE, "count output is NULL");
  *count = 3;
  if (capacity == 0) return XR_SUCCESS;
  M2S_SIM_REQUIRE(capacity >= 3, XR_ERROR_SIZE_INSUFFICIENT, "capacity < 3");
  M2S_SIM_REQUIRE(spaces != nullptr, XR_ERROR_VALIDATION_FAILURE, "array is NULL");
  for (int i = 0; i < 3; ++i) spaces[i] = kTypes[i];
  return XR_SUCCESS;
}

XrResult XRAPI_CALL CreateReferenceSpace(XrSession session, const XrReferenceSpaceCreateInfo* info,
                                         XrSpace* space) {
  constexpr const char* kFn = "xrCreateReferenceSpace";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_REFERENCE_SPACE_CREATE_INFO, "createInfo");
  M2S_SIM_REQUIRE(space != nullptr, XR_ERROR_VALIDATION_FAILURE, "space output is NULL");
  M2S_SIM_REQUIRE(Supported(info->referenceSpaceType), XR_ERROR_REFERENCE_SPACE_UNSUPPORTED,
                  "reference space type " + std::to_string(info->referenceSpaceType));
  M2S_SIM_REQUIRE(ValidPose(info->poseInReferenceSpace), XR_ERROR_POSE_INVALID,
                  "poseInReferenceSpace has a non-unit quaternion or non-finite position");
  auto obj = std::make_unique<SpaceObj>();
  obj->handle = ToHandle<XrSpace>(rt.NewHandle());
  obj->session = session;
  obj->type = info->referenceSpaceType;
  obj->reference_from_space = FromXr(info->poseInReferenceSpace);
  *space = obj->handle;
  ++inst->counters.spaces_created;
  rt.spaces[reinterpret_cast<uint64_t>(obj->handle)] = std::move(obj);
  return XR_SUCCESS;
}

XrResult XRAPI_CALL GetReferenceSpaceBoundsRect(XrSession session, XrReferenceSpaceType type,
                                                XrExtent2Df* bounds) {
  constexpr const char* kFn = "xrGetReferenceSpaceBoundsRect";
  std::lock_guard<std::mutex> lock(Runtime::Get().mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE(Supported(type), XR_ERROR_REFERENCE_SPACE_UNSUPPORTED, "unsupported type");
  M2S_SIM_REQUIRE(bounds != nullptr, XR_ERROR_VALIDATION_FAILURE, "bounds is NULL");
  if (type != XR_REFERENCE_SPACE_TYPE_STAGE) {
    *bounds = {0.f, 0.f};
    return XR_SPACE_BOUNDS_UNAVAILABLE;
  }
  constexpr float kStageSizeM = 4.f;
  *bounds = {kStageSizeM, kStageSizeM};
  return XR_SUCCESS;
}

XrResult XRAPI_CALL DestroySpace(XrSpace space) {
  constexpr const char* kFn = "xrDestroySpace";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  SpaceObj* obj = rt.FindSpace(space);
  M2S_SIM_REQUIRE(obj != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrSpace");
  if (SessionObj* s = rt.FindSession(obj->session)) ++rt.InstanceOf(*s)->counters.spaces_destroyed;
  rt.spaces.erase(reinterpret_cast<uint64_t>(space));
  return XR_SUCCESS;
}

XrResult XRAPI_CALL LocateSpace(XrSpace space, XrSpace base_space, XrTime time,
                                XrSpaceLocation* location) {
  constexpr const char* kFn = "xrLocateSpace";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  SpaceObj* a = rt.FindSpace(space);
  SpaceObj* b = rt.FindSpace(base_space);
  M2S_SIM_REQUIRE(a != nullptr && b != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrSpace");
  M2S_SIM_SESSION(s, inst, a->session);
  M2S_SIM_REQUIRE(a->session == b->session, XR_ERROR_VALIDATION_FAILURE,
                  "space and baseSpace belong to different sessions");
  M2S_SIM_REQUIRE_TYPE(location, XR_TYPE_SPACE_LOCATION, "location");
  M2S_SIM_REQUIRE(time > 0, XR_ERROR_TIME_INVALID, "time <= 0");
  const SimPose base_from_space =
      LocalFromSpace(*inst, *b, time).Inverse() * LocalFromSpace(*inst, *a, time);
  location->pose = ToXr(base_from_space);
  location->locationFlags =
      XR_SPACE_LOCATION_ORIENTATION_VALID_BIT | XR_SPACE_LOCATION_POSITION_VALID_BIT |
      XR_SPACE_LOCATION_ORIENTATION_TRACKED_BIT | XR_SPACE_LOCATION_POSITION_TRACKED_BIT;
  return XR_SUCCESS;
}

XrResult XRAPI_CALL LocateViews(XrSession session, const XrViewLocateInfo* info,
                                XrViewState* view_state, uint32_t capacity, uint32_t* count,
                                XrView* views) {
  constexpr const char* kFn = "xrLocateViews";
  Runtime& rt = Runtime::Get();
  std::lock_guard<std::mutex> lock(rt.mutex());
  M2S_SIM_SESSION(s, inst, session);
  M2S_SIM_REQUIRE_TYPE(info, XR_TYPE_VIEW_LOCATE_INFO, "viewLocateInfo");
  M2S_SIM_REQUIRE_TYPE(view_state, XR_TYPE_VIEW_STATE, "viewState");
  M2S_SIM_REQUIRE(info->viewConfigurationType == XR_VIEW_CONFIGURATION_TYPE_PRIMARY_STEREO,
                  XR_ERROR_VIEW_CONFIGURATION_TYPE_UNSUPPORTED, "only PRIMARY_STEREO");
  M2S_SIM_REQUIRE(info->displayTime > 0, XR_ERROR_TIME_INVALID, "displayTime <= 0");
  SpaceObj* base = rt.FindSpace(info->space);
  M2S_SIM_REQUIRE(base != nullptr, XR_ERROR_HANDLE_INVALID, "unknown XrSpace in viewLocateInfo");
  M2S_SIM_REQUIRE(base->session == session, XR_ERROR_VALIDATION_FAILURE,
                  "viewLocateInfo.space belongs to another session");
  M2S_SIM_REQUIRE(count != nullptr, XR_ERROR_VALIDATION_FAILURE, "viewCountOutput is NULL");
  *count = 2;
  if (capacity == 0) return XR_SUCCESS;
  M2S_SIM_REQUIRE(capacity >= 2, XR_ERROR_SIZE_INSUFFICIENT, "viewCapacityInput < 2");
  M2S_SIM_REQUIRE(views != nullptr, XR_ERROR_VALIDATION_FAILURE, "views is NULL");
  const SimConfig& config = inst->config;
  const SimPose base_from_view =
      LocalFromSpace(*inst, *base, info->displayTime).Inverse() * inst->Head(info->displayTime);
  const double half_h = 0.5 * config.hfov_deg * M_PI / 180.0;
  const double half_v = std::atan(std::tan(half_h) * config.eye_height / config.eye_width);
  for (int eye = 0; eye < 2; ++eye) {
    M2S_SIM_REQUIRE(views[eye].type == XR_TYPE_VIEW, XR_ERROR_VALIDATION_FAILURE,
                    "views[i].type is not XR_TYPE_VIEW");
    const double x = (eye == 0 ? -0.5 : 0.5) * config.ipd_m;  // left eye at -x
    const SimPose view_from_eye{Eigen::Quaterniond::Identity(), Eigen::Vector3d(x, 0, 0)};
    views[eye].pose = ToXr(base_from_view * view_from_eye);
    views[eye].fov = {static_cast<float>(-half_h), static_cast<float>(half_h),
                      static_cast<float>(half_v), static_cast<float>(-half_v)};
  }
  view_state->viewStateFlags =
      XR_VIEW_STATE_ORIENTATION_VALID_BIT | XR_VIEW_STATE_POSITION_VALID_BIT |
      XR_VIEW_STATE_ORIENTATION_TRACKED_BIT | XR_VIEW_STATE_POSITION_TRACKED_BIT;
  return XR_SUCCESS;
}

}  // namespace m2s::xrsim::api
