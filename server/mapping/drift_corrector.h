// Drift correction. With global vertex ids, re-observing points mapped long ago is an exact
// loop detection: no place recognition is needed. The question is only whether the old map and
// the drifted current estimate agree. Check answers it in steps, and says which way it went:
//  1. In the image: when the stored positions of the re-observed ("dormant") points reproject
//     into the current keyframe within the noise (median under 2.45 sigma), they agree,
//     whatever their 3-D disagreement (short-baseline points carry depth errors of tens of
//     percent, which are not drift): kAgree.
//  2. Re-triangulation from the keyframes after each point's last observer (the drifted
//     frame). Too few recent views yet: kDeferred; enough views but too few points
//     triangulate: kInconclusive.
//  3. The 3-D disagreement, as a fraction of the median depth: under DriftOptions::min_error,
//     kAgree. When at least as many other old points in the keyframe (first observed no later
//     than the dormant ones were last) reproject within the noise, the old map agrees with the
//     current estimate around them: the dormant points moved (an object moved while out of
//     view), it is not drift: kAgree (the caller forgets the points that reproject far off).
//     Right after a correction, or implausibly large for drift (a broken recent estimate),
//     kDeferred.
//  4. A Sim3 (Umeyama, outliers trimmed) aligning them to their stored positions; none:
//     kInconclusive. When it does not halve the 3-D disagreement, or does not halve the old
//     points' reprojection error in the current keyframe, the disagreement is noise, not
//     drift: kAgree.
//  5. Otherwise the map is corrected (kCorrected): Sim3 pose graph over the keyframes
//     (sequential + covisibility edges from the current estimate, loop edges from the
//     alignment, old keyframes fixed), points moved with their reference keyframe, the
//     correction published for the tracker.
// The caller merges the dormant observations on kAgree and kCorrected (then runs a global BA
// after a correction); on kInconclusive and kDeferred the points stay dormant.
//
// Thread-safety: called from the mapping thread only (the map's writer).
//
//   DriftCorrector drift(options.measurement(), options.drift, &map);
//   DriftOutcome outcome = drift.Check(keyframe_id, dormant_ids);
//   if (outcome == DriftOutcome::kCorrected) mapper.GlobalBundleAdjust(...);
#pragma once

#include <optional>
#include <vector>

#include "m2s/common/geometry.h"
#include "m2s/slam/options.h"
#include "map/map.h"

namespace m2s::slam {

enum class DriftOutcome {
  kAgree,         // the old map and the current estimate agree: merge the observations
  kInconclusive,  // the check could not decide (too few points re-triangulate or align)
  kCorrected,     // the map was corrected: merge the observations, then global BA
  kDeferred,      // not decidable yet (too few recent views, a recent correction, an
                  // implausible error): the next keyframe checks again
};
const char* ToString(DriftOutcome outcome);

class DriftCorrector {
 public:
  DriftCorrector(const MeasurementModel& model, const DriftOptions& options, Map* map)
      : model_(model), options_(options), map_(map) {}

  DriftOutcome Check(KeyframeId keyframe, const std::vector<VertexId>& dormant);
  // The last alignment error (fraction of median depth), for logs and tests.
  double last_error() const { return last_error_; }

 private:
  // The dormant points the keyframe measures: stored positions and measurements (step 1).
  struct OldPointsInView {
    Pose3 world_from_camera;  // the keyframe's
    std::vector<Eigen::Vector3d> positions;
    std::vector<Eigen::Vector2d> uvs;
  };
  // The dormant points re-triangulated from their recent views (step 2).
  struct Retriangulation {
    std::vector<Eigen::Vector3d> old_positions, new_positions;
    double median_depth = 0.0;    // of the new positions in the keyframe
    KeyframeId newest_old = 0;    // newest last observer of a re-triangulated point
    size_t max_recent_views = 0;  // most recent views of a dormant point
  };

  OldPointsInView GatherOldPoints(KeyframeId keyframe, const std::vector<VertexId>& dormant) const;
  // Median reprojection error of the old points in the keyframe posed as world_from_camera.
  double MedianReprojection(const OldPointsInView& view, const Pose3& world_from_camera) const;
  Retriangulation Retriangulate(KeyframeId keyframe, const std::vector<VertexId>& dormant) const;
  // The keyframe's points that are not dormant, were first observed at or before
  // `newest_old`, and reproject into it within the noise (step 3).
  int CountOldPointsInAgreement(KeyframeId keyframe, const std::vector<VertexId>& dormant,
                                KeyframeId newest_old) const;
  void Correct(KeyframeId keyframe, const Sim3& old_from_new, KeyframeId newest_old_keyframe);

  MeasurementModel model_;
  DriftOptions options_;
  Map* map_;
  double last_error_ = 0.0;
  std::optional<KeyframeId> last_correction_;  // keyframe of the last correction
};

}  // namespace m2s::slam
