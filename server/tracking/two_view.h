// Two-view reconstruction for the monocular initialiser (tracking/initializer.h): the relative
// motion of two views from their shared vertex ids, by essential matrix and homography
// (RANSAC), the candidate motions checked by triangulation, and the gates that refuse views
// which fit a motion without determining it (docs/design/two_view_initialisation.md).
//
//   TwoViewRefusal refusal;
//   auto two_view = ReconstructTwoView(model, options.initializer, view0, view1, &refusal);
#pragma once

#include <functional>
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
  // Every motion the estimators proposed (the homography's decompositions, the essential
  // matrices' of RANSAC and of the second opinions' estimators), the translations unit length:
  // the initialiser adjusts the views from each too (a pair of views can hold several minima).
  // Computed when called: the second opinions' estimators may not have run yet, and they cost
  // as much as the reconstruction (exact data never needs them).
  std::function<std::vector<Pose3>()> candidate_motions;
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
  // For a kWeakGeometry refusal, the motions that explain the views about equally well (a
  // plane's twins), or the one motion they leave undetermined, the best first; the
  // translations unit length. More views can decide (Initializer::FromMoreViews).
  std::vector<Pose3> rivals;
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

// The uncertainty gate of InitializerOptions (max_rotation_sigma_deg, max_direction_sigma_deg).
bool WellDetermined(const std::optional<MotionUncertainty>& u, const InitializerOptions& options);

}  // namespace m2s::slam
