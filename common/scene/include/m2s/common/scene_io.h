// Writes a Scene as a single-mesh OBJ or binary PLY file, for viewers and other tools.
//
// Positions are written exactly (OBJ: 9 significant digits, which round-trip a float; PLY:
// raw little-endian floats), triangles in order. For a scene whose ids are in LoadScene order
// (ids first used in triangle order, then unused vertices), such as MakeDefaultScene(),
// LoadScene() of the written file gives the same ids. OBJ drops vertices no triangle uses.
//
//   Status s = WriteScenePly("room.ply", MakeDefaultScene());
#pragma once

#include <string>

#include "m2s/common/scene.h"
#include "m2s/common/status.h"

namespace m2s {

Status WriteSceneObj(const std::string& path, const Scene& scene);
Status WriteScenePly(const std::string& path, const Scene& scene);

}  // namespace m2s
