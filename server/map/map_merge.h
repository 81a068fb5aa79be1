// Aligning and merging two maps of the same mesh by vertex id.
//
// Two maps built from the same scene (two sessions, two agents, or the maps before and after
// a tracking loss) key their points by the same vertex ids, so the points they share are
// exact correspondences: no place recognition, no descriptor matching, no false loops. Their
// relative pose and scale (monocular maps have their own scale) is the Sim3 that maps the
// shared points of one onto the other (Umeyama); the only outliers are badly triangulated
// points, which a trimmed re-fit removes.
//
//   Expected<MapAlignment> a = AlignMaps(map_a, map_b, MapAlignmentOptions{});
//   if (a) MergeMapInto(&map_a, map_b, a->into_from_from);
//
// Thread-safety: functions on values; the caller holds the maps' locks.
#pragma once

#include <cstdint>
#include <optional>
#include <unordered_map>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/status.h"
#include "map/map_data.h"

namespace m2s::slam {

struct MapAlignmentOptions {
  // Fewer shared points than this: no alignment.
  int min_shared_points = 20;
  // After the first fit, points whose residual is above `trim_factor` times the median
  // residual (and above `min_trim_distance` in the target map's units) are left out and the
  // fit repeated, at most `max_rounds` times.
  double trim_factor = 4.0;
  double min_trim_distance = 1e-9;
  int max_rounds = 5;
  // Inliers needed, as a fraction of the shared points.
  double min_inlier_fraction = 0.5;
  // With a camera, the fit must also hold in the images (CheckAlignmentInImages, both ways):
  // this fraction of the keyframes' observations of shared points within max_image_error_px.
  std::optional<Camera> camera;
  double max_image_error_px = 3.0;
  double min_image_agreement = 0.8;

  Status Check() const;
};

struct MapAlignment {
  Sim3 into_from_from;  // x_into = into_from_from * x_from
  int shared_points = 0;
  int inliers = 0;
  double rms_residual = 0.0;  // over the inliers, in the `into` map's units
  // The inliers' RMS distance from their centroid in `into`: rms_residual / spread is the
  // misfit relative to the size of what is aligned.
  double spread = 0.0;
  // With MapAlignmentOptions::camera: the smaller of the two ways' agreeing fractions.
  double image_agreement = 0.0;
};

// The Sim3 from `from`'s world to `into`'s world, fitted on the points both maps hold.
// Errors: too few shared points, a degenerate (collinear) set, too few inliers, (with a
// camera) a fit the keyframes' images do not agree with.
Expected<MapAlignment> AlignMaps(const MapData& into, const MapData& from,
                                 const MapAlignmentOptions& options);

// The alignment checked in the images: `into`'s positions of the shared points, moved into
// `from`'s keyframes by the alignment, against the pixels those keyframes observed them at.
// A Sim3 fitted in 3D fits the depth errors of a map triangulated over a small baseline
// within those errors (every shared point "fits") and can still be wrong by degrees and by
// half the scale; the keyframes' images show it, since a keyframe's pose is determined by all
// its observations and does not share its points' depth errors.
struct ImageAgreement {
  int observations = 0;  // observations of shared points by `from`'s keyframes
  int agreeing = 0;      // reprojecting within the bound (in front of the camera)
  double fraction() const {
    return observations > 0 ? static_cast<double>(agreeing) / observations : 0.0;
  }
};
ImageAgreement CheckAlignmentInImages(const Camera& camera, const MapData& into,
                                      const MapData& from, const Sim3& into_from_from,
                                      double max_error_px);

// Copies `from` into `into`, moved by into_from_from. Keyframes keep their ids, or with
// `first_keyframe_id` get first_keyframe_id, first_keyframe_id + 1, ... in `from`'s id order
// (maps of one system draw ids from one counter and keep them; maps of different systems
// renumber). No resulting id may exist in `into`. The links of `from`'s removed keyframes come
// along (renumbered after the keyframes), so trajectories that refer to them stay resolvable.
// Points `into` lacks are added (with their uncertainty); a point both hold keeps `into`'s
// position and gains the observations of `from`'s keyframes. Returns the id map (`from` id ->
// `into` id) of the keyframes and links copied.
std::unordered_map<KeyframeId, KeyframeId> MergeMapInto(
    MapData* into, const MapData& from, const Sim3& into_from_from,
    std::optional<KeyframeId> first_keyframe_id = std::nullopt);

}  // namespace m2s::slam
