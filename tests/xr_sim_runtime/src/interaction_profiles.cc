#include "interaction_profiles.h"

#include <openxr/openxr.h>

#include <algorithm>
#include <map>

namespace m2s::xrsim {
namespace {

// Components per hand, relative to the hand's top-level path.
const std::map<std::string, std::map<std::string, std::vector<std::string>>>& Profiles() {
  static const std::map<std::string, std::map<std::string, std::vector<std::string>>> profiles{
      {kSimpleController,
       {{kLeftHand,
         {"/input/select/click", "/input/menu/click", "/input/grip/pose", "/input/aim/pose",
          "/output/haptic"}},
        {kRightHand,
         {"/input/select/click", "/input/menu/click", "/input/grip/pose", "/input/aim/pose",
          "/output/haptic"}}}},
      {kTouchController,
       {{kLeftHand,
         {"/input/x/click", "/input/x/touch", "/input/y/click", "/input/y/touch",
          "/input/menu/click", "/input/squeeze/value", "/input/trigger/value",
          "/input/trigger/touch", "/input/thumbstick/x", "/input/thumbstick/y",
          "/input/thumbstick/click", "/input/thumbstick/touch", "/input/thumbrest/touch",
          "/input/grip/pose", "/input/aim/pose", "/output/haptic"}},
        {kRightHand,
         {"/input/a/click", "/input/a/touch", "/input/b/click", "/input/b/touch",
          "/input/squeeze/value", "/input/trigger/value", "/input/trigger/touch",
          "/input/thumbstick/x", "/input/thumbstick/y", "/input/thumbstick/click",
          "/input/thumbstick/touch", "/input/thumbrest/touch", "/input/grip/pose",
          "/input/aim/pose", "/output/haptic"}}}},
  };
  return profiles;
}

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

bool NameCharacter(char c) {
  return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' || c == '_' || c == '.';
}

}  // namespace

bool KnownProfile(const std::string& profile) { return Profiles().count(profile) > 0; }

bool ProfileHasPath(const std::string& profile, const std::string& path) {
  const auto p = Profiles().find(profile);
  if (p == Profiles().end()) return false;
  const std::string hand = TopLevelPath(path);
  const auto h = p->second.find(hand);
  if (h == p->second.end()) return false;
  const std::string component = path.substr(hand.size());
  return std::find(h->second.begin(), h->second.end(), component) != h->second.end();
}

bool ScriptableInput(const std::string& profile, const std::string& path) {
  return ProfileHasPath(profile, path) &&
         (EndsWith(path, "/click") || EndsWith(path, "/touch") || EndsWith(path, "/value"));
}

std::string TopLevelPath(const std::string& path) {
  for (const char* hand : {kLeftHand, kRightHand}) {
    const std::string prefix = hand;
    if (path.compare(0, prefix.size(), prefix) == 0 &&
        (path.size() == prefix.size() || path[prefix.size()] == '/')) {
      return prefix;
    }
  }
  return "";
}

bool WellFormedPath(const std::string& path) {
  if (path.size() < 2 || path.size() >= XR_MAX_PATH_LENGTH || path[0] != '/') return false;
  size_t start = 1;
  while (start <= path.size()) {
    const size_t end = std::min(path.find('/', start), path.size());
    const std::string segment = path.substr(start, end - start);
    if (!WellFormedName(segment) || segment == "." || segment == "..") return false;
    start = end + 1;
  }
  return true;
}

bool WellFormedName(const std::string& name) {
  return !name.empty() && std::all_of(name.begin(), name.end(), NameCharacter);
}

}  // namespace m2s::xrsim
