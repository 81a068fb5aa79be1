// A textured test scene for image front ends: a closed room (the default scene's room box,
// DefaultRoomLayout(), so DefaultTrajectory() walks through it) with four boxes on the
// footprints of its largest furniture, every surface covered by a random texture of blobs
// (MakeBlobTexture) that ORB finds plenty of corners in. Written as OBJ + MTL + PNG textures;
// surfaces are tessellated into cells of about `cell_m` so that the vertex front end has
// vertices to compare with. Deterministic from the seed.
//
//   Expected<std::string> obj = testing::WriteTexturedRoom(dir, {.seed = 7});
//   headless_options.mesh_path = *obj;
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include <opencv2/core.hpp>

#include "m2s/common/status.h"

namespace m2s::testing {

// A BGR texture of width x height: overlapping filled circles, ellipses and rectangles of
// random colours and sizes (radius 3 to 24 px) on a random background, slightly blurred so
// that it does not alias when drawn smaller. Deterministic from the seed (cv::RNG).
cv::Mat MakeBlobTexture(int width, int height, uint64_t seed);

struct TexturedRoomOptions {
  uint64_t seed = 1;
  double cell_m = 0.25;         // tessellation of every surface
  double texels_per_m = 200.0;  // texture resolution on every surface
  int max_texture_px = 2048;    // per texture side
};

// Writes textured_room.obj, textured_room.mtl and one PNG per surface group into `dir`
// (created when missing); returns the OBJ's path. Error when a file cannot be written.
Expected<std::string> WriteTexturedRoom(const std::filesystem::path& dir,
                                        const TexturedRoomOptions& options = {});

}  // namespace m2s::testing
