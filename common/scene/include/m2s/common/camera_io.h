// Camera files for the command-line tools: CAMERA.json is
// {"width","height","fx","fy","cx","cy","near","far"} (near and far optional).
// Only main() functions and tools read files; libraries take a Camera value.
#pragma once

#include <string>

#include "m2s/common/camera.h"
#include "m2s/common/status.h"

namespace m2s {

// The camera in `path`, checked with Camera::Check; a one-line error otherwise.
Expected<Camera> ReadCameraJson(const std::string& path);

}  // namespace m2s
