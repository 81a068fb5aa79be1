// Monocular initialisation from two frames with enough parallax (ORB-SLAM2's scheme on
// OpenCV solvers): essential matrix and homography by RANSAC, model selection by score ratio
// (planar scenes pick the homography), triangulation of the candidate motions with cheirality,
// reprojection and parallax checks, a unique best motion required, then a full bundle
// adjustment of the two views and the scale fixed by median depth 1 in the first camera.
// Pure rotation or too little parallax: no map (keep waiting, never a broken map). The views
// must also determine the motion, not merely fit it (docs/design/two_view_initialisation.md):
// the chosen motion must explain nearly all shared features (association is by id); no distinct
// motion of the other model may fit about as well (a plane's twin), nor, for a loosely determined
// rotation, a motion of two other estimators (a valley of motions); and the motion's standard
// deviations for pixel_sigma noise (TwoViewMotionUncertainty) must be within
// InitializerOptions' bounds, before and after the bundle adjustment. Bunched or distant points
// fail that with exact data too (TwoViewRefusal::Kind::kWeakGeometry), and the initialiser
// waits for more baseline.
// A refused attempt costs milliseconds (two RANSACs): after one, the next attempt waits until the
// parallax, growing with the time since the reference frame, should be near the bound (at most
// kMaxInitRetryDelayS later), so waiting frames stay cheap.
//
// OpenCV's solvers run behind one boundary: an exception they throw (degenerate input) is a
// refused attempt with the reason, never an exception out of the initialiser.
//
// Not thread-safe (one per tracking thread).
//
//   Initializer init(options.measurement(), options.initializer, options.mapper.num_ba_threads);
//   if (auto map = init.Process(seq, timestamp, features)) { /* two keyframes + points */ }
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "m2s/slam/system.h"
#include "tracking/frame_validation.h"
#include "tracking/motion_uncertainty.h"

namespace m2s::slam {

struct TwoViewReconstruction {
  Pose3 camera1_from_camera0;  // world = camera 0
  std::vector<VertexId> ids;
  std::vector<Eigen::Vector3d> points;  // camera 0 frame
  double median_parallax_deg = 0.0;
  bool used_homography = false;
};

// Why two views were not reconstructed: the kind decides what the initialiser does next, the
// message is for the log.
struct TwoViewRefusal {
  enum class Kind {
    kTooFewShared,     // fewer shared ids than InitializerOptions::min_points
    kTooLittleMotion,  // the image motion cannot give the parallax needed
    kNoModel,          // the RANSACs ran and no motion explains the views well enough
    kWeakGeometry,     // a motion explains the views but they do not determine it (bunched or
                       // distant points, a plane's twin motion): more baseline needed
    kSolverError,      // an OpenCV solver refused the input (degenerate configuration)
  };
  Kind kind = Kind::kNoModel;
  std::string message;
  bool by_second_opinion = false;  // a kWeakGeometry twin found by another estimator
};

// Two-view reconstruction from matched features (matched by id). nullopt, with the reason in
// `refusal` (optional), when the views cannot be reconstructed reliably; `median_parallax_deg`
// (optional) receives the parallax of the best motion when one was triangulated (else 0). Points
// need half the model's min_triangulation_parallax_deg (the initial map is refined by a full bundle
// adjustment). With `second_opinions`, the essential matrices of two more robust estimators
// are candidate twins too: a valley of motions that fit within the noise refuses the views
// (kWeakGeometry) where RANSAC alone would have picked a point of it.
std::optional<TwoViewReconstruction> ReconstructTwoView(
    const MeasurementModel& model, const InitializerOptions& options, const SortedFeatures& view0,
    const SortedFeatures& view1, TwoViewRefusal* refusal, double* median_parallax_deg = nullptr,
    bool second_opinions = true);

struct InitialFrame {
  int64_t seq = 0;
  double timestamp = 0.0;
  SortedFeatures features;
  Pose3 world_from_camera;
};

struct InitialMap {
  InitialFrame first;  // world_from_camera = identity
  InitialFrame second;
  std::vector<VertexId> point_ids;
  std::vector<Eigen::Vector3d> points;  // world; median depth in the first camera is 1
  bool used_homography = false;
};

class Initializer {
 public:
  // `num_ba_threads`: threads of the two-view bundle adjustment.
  Initializer(const MeasurementModel& model, const InitializerOptions& options, int num_ba_threads)
      : model_(model), options_(options), num_ba_threads_(num_ba_threads) {}

  // Feeds one valid frame. Returns the initial map once two frames (the reference and this
  // one) reconstruct; otherwise nullopt (last_failure() says why).
  std::optional<InitialMap> Process(int64_t seq, double timestamp, const SortedFeatures& features);
  void Reset() {
    reference_.reset(), frames_since_reference_ = 0, next_attempt_time_.reset();
    second_opinion_refusals_ = 0;
  }
  const std::string& last_failure() const { return last_failure_; }
  // The reference frame's seq, when one is held.
  std::optional<int64_t> reference_seq() const {
    return reference_ ? std::optional<int64_t>(reference_->seq) : std::nullopt;
  }

 private:
  MeasurementModel model_;
  InitializerOptions options_;
  int num_ba_threads_;
  std::optional<InitialFrame> reference_;
  int frames_since_reference_ = 0;
  std::optional<double> next_attempt_time_;  // no full attempt before this capture time
  int second_opinion_refusals_ = 0;          // since the last map or Reset
  std::string last_failure_;
};

}  // namespace m2s::slam
