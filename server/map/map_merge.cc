#include "map/map_merge.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <unordered_map>
#include <vector>

#include "m2s/common/alignment.h"
#include "m2s/common/check.h"
#include "m2s/common/numeric.h"

namespace m2s::slam {

Status MapAlignmentOptions::Check() const {
  if (min_shared_points < 3) return Status::Error("min_shared_points must be at least 3");
  if (!(trim_factor > 1.0) || !std::isfinite(trim_factor)) {
    return Status::Error("trim_factor must be finite and > 1");
  }
  if (!(min_trim_distance >= 0.0)) return Status::Error("min_trim_distance must be >= 0");
  if (max_rounds < 1) return Status::Error("max_rounds must be at least 1");
  if (!(min_inlier_fraction > 0.0 && min_inlier_fraction <= 1.0)) {
    return Status::Error("min_inlier_fraction must be in (0, 1]");
  }
  if (!(max_image_error_px > 0.0) || !std::isfinite(max_image_error_px)) {
    return Status::Error("max_image_error_px must be positive and finite");
  }
  if (!(min_image_agreement > 0.0 && min_image_agreement <= 1.0)) {
    return Status::Error("min_image_agreement must be in (0, 1]");
  }
  return Status::Ok();
}

ImageAgreement CheckAlignmentInImages(const Camera& camera, const MapData& into,
                                      const MapData& from, const Sim3& into_from_from,
                                      double max_error_px) {
  // Each of from's keyframes as a camera in into's world (projection ignores the scale).
  std::unordered_map<KeyframeId, Pose3> camera_from_into;
  for (const auto& [id, kf] : from.keyframes()) {
    camera_from_into.emplace(id, into_from_from.TransformPose(kf.world_from_camera).Inverse());
  }
  ImageAgreement out;
  const double max_error_sq = max_error_px * max_error_px;
  for (const auto& [id, point] : from.points()) {
    const MapPoint* other = into.point(id);
    if (other == nullptr) continue;
    for (const KeyframeId observer : point.observers) {
      const Keyframe* kf = from.keyframe(observer);
      const Eigen::Vector2d* uv = kf != nullptr ? kf->Find(id) : nullptr;
      if (uv == nullptr) continue;
      ++out.observations;
      const Eigen::Vector3d p = camera_from_into.at(observer) * other->position;
      if (p.z() > 0.0 && (camera.Project(p) - *uv).squaredNorm() <= max_error_sq) ++out.agreeing;
    }
  }
  return out;
}

Expected<MapAlignment> AlignMaps(const MapData& into, const MapData& from,
                                 const MapAlignmentOptions& options) {
  if (Status valid = options.Check(); !valid) return valid.Prefixed("map alignment: ");
  std::vector<Eigen::Vector3d> source, target;  // from, into
  for (const auto& [id, point] : from.points()) {
    if (const MapPoint* other = into.point(id)) {
      source.push_back(point.position);
      target.push_back(other->position);
    }
  }
  const int shared = static_cast<int>(source.size());
  if (shared < options.min_shared_points) {
    return Expected<MapAlignment>::Error("maps share " + std::to_string(shared) +
                                         " points, fewer than " +
                                         std::to_string(options.min_shared_points));
  }
  std::vector<Eigen::Vector3d> src = source, dst = target;
  MapAlignment out;
  out.shared_points = shared;
  for (int round = 0; round < options.max_rounds; ++round) {
    const std::optional<Sim3> fit = AlignPoints(src, dst, /*with_scale=*/true);
    if (!fit) return Expected<MapAlignment>::Error("shared points are degenerate (collinear)");
    out.into_from_from = *fit;
    // Residuals of every shared point under this fit; the next fit uses the ones below the cut.
    std::vector<double> residuals(shared);
    for (int i = 0; i < shared; ++i) residuals[i] = ((*fit) * source[i] - target[i]).norm();
    const double cut =
        std::max(options.min_trim_distance, options.trim_factor * Percentile(residuals, 0.5));
    src.clear();
    dst.clear();
    double sum_sq = 0.0;
    for (int i = 0; i < shared; ++i) {
      if (residuals[i] > cut) continue;
      src.push_back(source[i]);
      dst.push_back(target[i]);
      sum_sq += residuals[i] * residuals[i];
    }
    const bool converged = static_cast<int>(src.size()) == out.inliers;
    out.inliers = static_cast<int>(src.size());
    out.rms_residual = out.inliers > 0 ? std::sqrt(sum_sq / out.inliers) : 0.0;
    if (converged || out.inliers < 3) break;
  }
  if (!dst.empty()) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& p : dst) centroid += p;
    centroid /= static_cast<double>(dst.size());
    double sum = 0.0;
    for (const Eigen::Vector3d& p : dst) sum += (p - centroid).squaredNorm();
    out.spread = std::sqrt(sum / static_cast<double>(dst.size()));
  }
  if (out.inliers < options.min_inlier_fraction * shared) {
    return Expected<MapAlignment>::Error(std::to_string(out.inliers) + " of " +
                                         std::to_string(shared) + " shared points agree");
  }
  if (options.camera) {
    const double px = options.max_image_error_px;
    out.image_agreement = std::min(
        CheckAlignmentInImages(*options.camera, into, from, out.into_from_from, px).fraction(),
        CheckAlignmentInImages(*options.camera, from, into, out.into_from_from.Inverse(), px)
            .fraction());
    if (out.image_agreement < options.min_image_agreement) {
      return Expected<MapAlignment>::Error(
          "the fit holds for " + std::to_string(out.inliers) + " of " + std::to_string(shared) +
          " shared points but for " + std::to_string(std::lround(100.0 * out.image_agreement)) +
          " % of their observations in the keyframes");
    }
  }
  return out;
}

std::unordered_map<KeyframeId, KeyframeId> MergeMapInto(
    MapData* into, const MapData& from, const Sim3& into_from_from,
    std::optional<KeyframeId> first_keyframe_id) {
  M2S_CHECK(into != nullptr);
  std::unordered_map<KeyframeId, KeyframeId> new_id;
  KeyframeId next = first_keyframe_id.value_or(0);
  auto assign = [&](KeyframeId id) {
    const KeyframeId target = first_keyframe_id ? next++ : id;
    M2S_CHECK(into->keyframe(target) == nullptr && into->links().count(target) == 0)
        << "keyframe id " << target << " already in use";
    new_id[id] = target;
    return target;
  };
  for (const auto& [id, kf] : from.keyframes()) {
    Keyframe copy = kf;
    copy.id = assign(id);
    copy.world_from_camera = into_from_from.TransformPose(kf.world_from_camera);
    into->AddKeyframe(std::move(copy));
  }
  std::vector<KeyframeId> linked;
  for (const auto& [id, link] : from.links()) linked.push_back(id);
  std::sort(linked.begin(), linked.end());
  for (const KeyframeId id : linked) assign(id);
  for (const KeyframeId id : linked) {
    // A relative pose keeps its rotation; its translation takes the Sim3's scale.
    const KeyframeLink& link = from.links().at(id);
    const auto parent = new_id.find(link.parent);
    M2S_CHECK(parent != new_id.end()) << "link of keyframe " << id << " to a missing parent";
    into->SetLink(
        new_id.at(id),
        {parent->second, Pose3(link.parent_from_camera.rotation(),
                               into_from_from.scale() * link.parent_from_camera.translation())});
  }
  for (const auto& [id, point] : from.points()) {
    if (into->point(id) == nullptr) {
      const auto ref = new_id.find(point.reference_keyframe);
      M2S_CHECK(ref != new_id.end()) << "point " << id << " refers to a missing keyframe";
      into->AddPoint(id, into_from_from * point.position, ref->second);
      // Relative to depth, so a Sim3 leaves it as it is.
      into->SetPointUncertainty(id, point.uncertainty, point.constrained);
    }
    for (const KeyframeId observer : point.observers) {
      into->AddObservation(id, new_id.at(observer));
    }
  }
  return new_id;
}

}  // namespace m2s::slam
