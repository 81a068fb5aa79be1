// Tracker recovery: relocalisation by PnP + RANSAC on exact associations, rotation-only
// tracking while the camera turns towards unmapped space, the inliers a view needs, and whether
// they determine the pose.
#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "m2s/common/logging.h"
#include "tracking/motion_uncertainty.h"
#include "tracking/rotation_only.h"
#include "tracking/tracker_internal.h"

namespace m2s::slam {

using tracker_internal::kMaxCentreSigmaFraction;
using tracker_internal::kMinRotationOnlyInliers;
using tracker_internal::kMinTrackedInliers;
using tracker_internal::kSparseViewInlierFraction;
using tracker_internal::MakePoseOptions;

namespace {

constexpr int kMaxPnpPoints = 500;  // RANSAC input, subsampled evenly beyond this
constexpr int kPnpIterations = 200;
constexpr double kPnpThresholdSigmas = 4.0;
// Rotation-only tracking: a keyframe when the frame shares less than this fraction of the
// reference keyframe's features (the view has turned away from it).
constexpr double kRotationKeyframeOverlap = 0.5;
// Rotation-only tracking: at most this shift of the camera from the reference keyframe's centre
// (fraction of the keyframe's median depth). A head turning in place moves its eyes by
// centimetres; a drone yawing in flight leaves its centre at once.
constexpr double kRotationOnlyMaxShift = 0.02;

// camera_from_world by PnP + RANSAC (OpenCV); nullopt when RANSAC finds no pose or OpenCV
// throws on degenerate input (logged: a failed relocalisation, never a thrown frame).
std::optional<Pose3> SolvePnpRansac(const Camera& camera, double threshold_px,
                                    const std::vector<cv::Point3d>& object,
                                    const std::vector<cv::Point2d>& image,
                                    std::vector<int>* inliers) {
  try {
    cv::Mat k_cv, rvec, tvec;
    cv::eigen2cv(camera.K(), k_cv);
    if (!cv::solvePnPRansac(object, image, k_cv, cv::noArray(), rvec, tvec, false, kPnpIterations,
                            threshold_px, 0.999, *inliers, cv::SOLVEPNP_AP3P)) {
      return std::nullopt;
    }
    cv::Mat r_cv;
    cv::Rodrigues(rvec, r_cv);
    Eigen::Matrix3d r;
    Eigen::Vector3d t;
    cv::cv2eigen(r_cv, r);
    cv::cv2eigen(tvec, t);
    return Pose3(r, t);
  } catch (const cv::Exception& e) {
    M2S_LOG(kWarning) << "relocalisation: OpenCV error: " << e.what();
    inliers->clear();
    return std::nullopt;
  }
}

}  // namespace

std::optional<Pose3> tracker_internal::PnpRansac(const Camera& camera, double threshold_px,
                                                 const std::vector<Eigen::Vector3d>& points,
                                                 const std::vector<Eigen::Vector2d>& uvs,
                                                 std::vector<int>* inliers) {
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  for (const size_t i : EvenlySpacedIndices(std::min(points.size(), uvs.size()), kMaxPnpPoints)) {
    object.emplace_back(points[i].x(), points[i].y(), points[i].z());
    image.emplace_back(uvs[i].x(), uvs[i].y());
  }
  return SolvePnpRansac(camera, threshold_px, object, image, inliers);
}

bool Tracker::Relocalise(const Association& a, Pose3* camera_from_world,
                         std::vector<bool>* inlier) {
  const int n = static_cast<int>(a.ids.size());
  const int required = RequiredInliers(n, kMinTrackedInliers);
  if (n < required) return false;
  std::vector<cv::Point3d> object;
  std::vector<cv::Point2d> image;
  const std::vector<size_t> usable = PoseSolvingPoints(a, /*skip_dormant=*/false);
  if (static_cast<int>(usable.size()) < required) return false;
  for (const size_t k : EvenlySpacedIndices(usable.size(), kMaxPnpPoints)) {
    const size_t i = usable[k];
    object.emplace_back(a.points[i].x(), a.points[i].y(), a.points[i].z());
    image.emplace_back(a.uvs[i].x(), a.uvs[i].y());
  }
  std::vector<int> pnp_inliers;
  const std::optional<Pose3> solved = SolvePnpRansac(
      model_.camera, kPnpThresholdSigmas * model_.pixel_sigma, object, image, &pnp_inliers);
  if (!solved || static_cast<int>(pnp_inliers.size()) < required / 2) return false;
  Pose3 pose = *solved;
  // Refine on the PnP inliers, then classify every associated point.
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> uvs;
  for (const int i : pnp_inliers) {
    points.emplace_back(object[i].x, object[i].y, object[i].z);
    uvs.emplace_back(image[i].x, image[i].y);
  }
  const PoseOnlyResult refined =
      OptimizePose(model_.camera, MakePoseOptions(model_), points, uvs, &pose);
  if (!pose.AllFinite() || refined.num_inliers < required / 2) return false;
  *camera_from_world = pose;
  const int classified = Classify(a, pose, /*skip_dormant=*/false, inlier);
  // Exact association: every associated point is the vertex the frame sees, so a pose that
  // leaves most of them unexplained is an ambiguity of a weak point set (a distant or bunched
  // object fits a wrong pose within the RANSAC bound), not the camera's pose.
  return classified >= required && 2 * classified >= n;
}

bool Tracker::TrackRotationOnly(double timestamp, const SortedFeatures& features,
                                const Association& a, Pose3* camera_from_world,
                                std::vector<bool>* inlier, bool* keyframe) {
  if (!reference_kf_ || !a.reference_pose) return false;
  const double max_error_px = std::sqrt(kChi2TwoDof95) * model_.pixel_sigma;
  // The rotation is fitted as if the camera were at the reference keyframe's centre: off by how
  // far the last measured pose was from it, and by how far the camera has moved since, at its
  // last measured speed.
  if (measured_.empty()) return false;
  const double since = std::max(0.0, timestamp - measured_.back().timestamp);
  const double moved = (measured_.back().centre - a.reference_pose->translation()).norm() +
                       measured_velocity_.norm() * since;
  if (moved > kRotationOnlyMaxShift * last_keyframe_median_depth_) return false;
  std::optional<RotationOnlyPose> r;
  size_t keyframe_features = 0;
  map_->Read([&](const MapData& m) {
    const Keyframe* kf = m.keyframe(*reference_kf_);
    const std::vector<VertexId>& ids = kf != nullptr ? kf->ids : reference_features_.ids;
    const std::vector<Eigen::Vector2d>& uvs = kf != nullptr ? kf->uvs : reference_features_.uvs;
    keyframe_features = ids.size();
    r = SolveRotationOnly(model_.camera, max_error_px, *a.reference_pose, ids, uvs, features);
  });
  if (!r || r->inliers < kMinRotationOnlyInliers ||
      r->inliers < kSparseViewInlierFraction * static_cast<double>(r->shared)) {
    return false;
  }
  *keyframe = r->inliers < kRotationKeyframeOverlap * static_cast<double>(keyframe_features);
  // The bearings fit the rotation, not the centre. Two hypotheses for it: the camera stopped
  // where it was last measured and only turns (a head looking around), or it moved on at the
  // measured velocity (a drone yawing in flight). The map points in view, however few, decide;
  // without any, the camera is taken to have stopped (a head's turns end its steps).
  const Eigen::Matrix3d rotation = r->camera_from_world.RotationMatrix();
  auto at = [&](const Eigen::Vector3d& centre) { return Pose3(rotation, -(rotation * centre)); };
  const Pose3 stopped = at(measured_.back().centre);
  const Pose3 moved_on = at(measured_.back().centre + measured_velocity_ * since);
  int unused = 0;
  r->camera_from_world =
      RecentPointsCost(a, moved_on, &unused) < RecentPointsCost(a, stopped, &unused) ? moved_on
                                                                                     : stopped;
  // The map points in view must agree with the rotation, when there are enough to judge (a
  // handful of fresh, noisy points does not outvote a thousand bearings).
  const int fitting = Classify(a, r->camera_from_world, /*skip_dormant=*/false, inlier);
  if (static_cast<int>(a.ids.size()) >= kMinRotationOnlyInliers &&
      fitting < kSparseViewInlierFraction * static_cast<double>(a.ids.size())) {
    return false;
  }
  *camera_from_world = r->camera_from_world;
  return true;
}

bool Tracker::PoseDetermined(const Association& a, const std::vector<bool>& inlier,
                             const Pose3& camera_from_world) const {
  std::vector<size_t> used;
  for (size_t i = 0; i < inlier.size(); ++i) {
    if (inlier[i]) used.push_back(i);
  }
  if (used.empty()) return false;
  // Dense views: an even subset, its information scaled up to the whole. The points' own
  // uncertainty is left out: shared by the points of one map, it moves the pose with them, and
  // young maps would lose every frame.
  const std::optional<ViewCentreUncertainty> u = CentreUncertaintyOfView(
      model_.camera, model_.pixel_sigma, camera_from_world, a.points, used, options_.max_points);
  return u && u->sigma <= kMaxCentreSigmaFraction * u->median_depth;
}

int Tracker::RequiredInliers(int num_points, int floor) const {
  // Exact association has no ambiguous matches: a sparse view's pose rests on most of the
  // points it sees, not on a fixed count it may never reach.
  const int from_view =
      static_cast<int>(std::ceil(kSparseViewInlierFraction * static_cast<double>(num_points)));
  return std::clamp(from_view, std::min(floor, options_.min_inliers), options_.min_inliers);
}

}  // namespace m2s::slam
