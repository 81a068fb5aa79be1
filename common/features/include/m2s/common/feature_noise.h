// Research degradations of projected features: pixel noise, quantisation, dropout and wrong
// ids. (The feature budget is not a degradation: it is the balanced selection of
// m2s/common/feature_rank.h, applied by the client before sending and by the server.)
//
// Determinism: every random decision is drawn from a counter-based generator keyed by
// (seed, frame_index, vertex id, stage), so the result depends only on the options, the
// camera, num_scene_vertices, frame_index and the *set* of input features - not on their
// order - and a feature's noise does not change when another option (say dropout) changes.
// The output is sorted by id.
//
// Stages, in this order:
//  1. Dropout: each feature is removed with probability dropout_probability.
//  2. Pixel noise: u and v each get independent N(0, pixel_noise_sigma^2) noise.
//  3. Quantisation (quantization_px = q > 0): u -> (floor(u / q) + 0.5) q, same for v: the
//     centre of the q-pixel cell the point falls in. With q = 1 this is the centre of the
//     pixel (pixel (i, j) spans [i, i+1) x [j, j+1)), i.e. the original method's whole-pixel
//     positions (integers floor(u), floor(v)) plus 0.5, which keeps the quantisation unbiased.
//  4. Features whose (u, v) left the image [0, width) x [0, height) are removed (noise near
//     the border, or a last partial cell when q does not divide the image size).
//  5. Wrong ids: each remaining feature, with probability wrong_id_fraction, gets a random id
//     in [0, num_scene_vertices) that is not the id of any feature in the frame (ids stay
//     unique); when no such id is left the feature is removed.
// Depth is passed through unchanged.
//
//   FeatureNoiseOptions noise;
//   noise.pixel_noise_sigma = 0.5;
//   ApplyFeatureNoise(noise, camera, scene.num_vertices(), frame_index, &features);
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "m2s/common/camera.h"
#include "m2s/common/types.h"

namespace m2s {

struct FeatureNoiseOptions {
  double pixel_noise_sigma = 0.0;    // standard deviation of the noise on u and v, pixels
  double quantization_px = 0.0;      // grid step in pixels; 0: off, 1: pixel centres
  double dropout_probability = 0.0;  // in [0, 1]
  double wrong_id_fraction = 0.0;    // in [0, 1]
  uint64_t seed = 0;

  // True when any option changes the features.
  bool Enabled() const;
  // False (with the reason) when an option is out of range or not finite.
  Status Check() const;
};

// Applies the stages above to `features` in place. Options must pass Check() (checked).
void ApplyFeatureNoise(const FeatureNoiseOptions& options, const Camera& camera,
                       uint32_t num_scene_vertices, uint64_t frame_index,
                       std::vector<ProjectedVertex>* features);

}  // namespace m2s
