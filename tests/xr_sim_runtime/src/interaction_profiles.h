// The interaction profiles the simulated runtime offers, with the binding paths of each
// (OpenXR 1.0, 6.4): /interaction_profiles/khr/simple_controller and
// /interaction_profiles/oculus/touch_controller, both hands.
//
//   if (ProfileHasPath(kTouchController, "/user/hand/right/input/a/click")) ...
#pragma once

#include <string>
#include <vector>

namespace m2s::xrsim {

inline constexpr const char* kSimpleController = "/interaction_profiles/khr/simple_controller";
inline constexpr const char* kTouchController = "/interaction_profiles/oculus/touch_controller";
inline constexpr const char* kLeftHand = "/user/hand/left";
inline constexpr const char* kRightHand = "/user/hand/right";

bool KnownProfile(const std::string& profile);
// True when `path` (e.g. "/user/hand/left/input/x/click") is a binding path of the profile.
bool ProfileHasPath(const std::string& profile, const std::string& path);
// True for the paths an input script may drive: inputs ending in /click, /touch or /value.
bool ScriptableInput(const std::string& profile, const std::string& path);
// The top-level user path of a binding path ("/user/hand/left/input/x/click" ->
// "/user/hand/left"); empty when it has none.
std::string TopLevelPath(const std::string& path);
// A well-formed path (OpenXR 1.0, 6.2): "/" then segments of [a-z0-9-_.], not "." or "..",
// no empty segment, no trailing "/", shorter than XR_MAX_PATH_LENGTH.
bool WellFormedPath(const std::string& path);
// A well-formed action or action set name: one segment of [a-z0-9-_.], not empty.
bool WellFormedName(const std::string& name);

}  // namespace m2s::xrsim
