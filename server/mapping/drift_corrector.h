// Drift correction. With global vertex ids, re-observing points mapped long ago is an exact
// loop detection: no place recognition is needed. The question is only whether the old map and
// the drifted current estimate agree. First in the image: when the stored positions of the
// re-observed ("dormant") points reproject into the current keyframe within the noise (median
// under 2.45 sigma), they agree, whatever their 3-D disagreement (short-baseline points carry
// depth errors of tens of percent, which are not drift). Otherwise the corrector re-triangulates
// them from recent keyframes (the drifted frame), aligns them to their stored positions with a
// Sim3 (Umeyama, with outlier trimming), and when they disagree by more than
// Options::loop_min_error of the median depth, and the Sim3 at least halves the old points'
// reprojection error in the current keyframe, it corrects the map: Sim3 pose graph over the
// keyframes (sequential + covisibility edges from the current estimate, loop edges from the
// alignment, old keyframes fixed), points moved with their reference keyframe, the correction
// published for the tracker. The caller then adds the dormant observations and runs a global BA.
//
// Thread-safety: called from the mapping thread only (the map's writer).
//
//   DriftCorrector drift(options, &map);
//   DriftDecision d = drift.Check(keyframe_id, dormant_ids);
//   if (d == DriftDecision::kCorrected) mapper.GlobalBundleAdjust(...);
#pragma once

#include <optional>

#include <vector>

#include "m2s/slam/system.h"
#include "map/map.h"

namespace m2s::slam {

enum class DriftDecision {
  kConsistent,  // old and new estimates agree: add the observations
  kCorrected,   // the map was corrected: add the observations, then global BA
  kDeferred,    // not enough recent views yet to compare (try again on the next keyframe)
};

class DriftCorrector {
 public:
  DriftCorrector(const Options& options, Map* map) : options_(options), map_(map) {}

  DriftDecision Check(KeyframeId keyframe, const std::vector<VertexId>& dormant);
  // The last alignment error (fraction of median depth), for logs and tests.
  double last_error() const { return last_error_; }

 private:
  void Correct(KeyframeId keyframe, const Sim3& old_from_new, KeyframeId newest_old_keyframe);

  Options options_;
  Map* map_;
  double last_error_ = 0.0;
  std::optional<KeyframeId> last_correction_;  // keyframe of the last correction
};

}  // namespace m2s::slam
