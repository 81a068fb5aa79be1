#include "system/system_common.h"

#include <algorithm>

#include "m2s/common/numeric.h"

namespace m2s::slam {

MapAlignmentOptions MergeAlignmentOptions(const Options& options) {
  MapAlignmentOptions align;
  align.min_shared_points = options.multi_map.merge_min_shared_points;
  align.min_inlier_fraction = options.multi_map.merge_min_inlier_fraction;
  align.camera = options.camera;
  align.max_image_error_px = kMergeImageErrorSigmas * options.pixel_sigma;
  align.min_image_agreement = kMergeMinImageAgreement;
  return align;
}

bool TakeFrame(const Frame& frame, bool shut_down, int feature_budget, const FeatureGrid& grid,
               FrameValidator* validator, SortedFeatures* features, TrackResult* result,
               SystemStats* stats) {
  result->seq = frame.seq;
  result->timestamp = frame.timestamp;
  result->num_features = static_cast<int>(frame.features.size());
  if (shut_down) {
    result->state = TrackingState::kRejected;
    result->reject_reason = "shut_down";
    return false;
  }
  ++stats->frames_processed;
  if (const Status valid = validator->Validate(frame, features); !valid) {
    const char* reason = ToString(*valid.reason());
    result->state = TrackingState::kRejected;
    result->reject_reason = reason;
    ++stats->frames_rejected;
    ++stats->rejected_by_reason[reason];
    return false;
  }
  stats->features_over_budget +=
      static_cast<int64_t>(ApplyFeatureBudget(feature_budget, grid, features));
  return true;
}

void MoveRecord(const Sim3& new_from_old, int new_map_id, TrajectoryRecord* record) {
  record->world_from_camera = new_from_old.TransformPose(record->world_from_camera);
  // A relative pose keeps its rotation; its translation takes the scale.
  record->reference_from_camera =
      Pose3(record->reference_from_camera.rotation(),
            new_from_old.scale() * record->reference_from_camera.translation());
  record->map_id = new_map_id;
}

namespace {

// Gives a record without a pose in another map the pose of the frame between the two views
// `f`, relative to the first keyframe; counts it in `marked`.
void MarkInbetween(const InitialInbetween& f, KeyframeId first, int map_id, int kept,
                   TrajectoryRecord* r, InitialFramesMarked* marked) {
  if (HasPose(r->state)) return;  // a pose in another map already
  ++marked->marked;
  marked->was_lost += r->state == TrackingState::kLost ? 1 : 0;
  r->state = TrackingState::kOk;
  r->reference = first;
  r->map_id = map_id;
  // The first keyframe is the initial map's world.
  r->world_from_camera = f.world_from_camera;
  r->reference_from_camera = f.world_from_camera;
  if (kept <= 0) return;
  const std::vector<size_t> keep =
      EvenlySpacedIndices(f.observed_ids.size(), static_cast<size_t>(kept));
  r->observed_ids.clear();
  r->observed_uvs.clear();
  for (const size_t i : keep) {
    r->observed_ids.push_back(f.observed_ids[i]);
    r->observed_uvs.push_back(f.observed_uvs[i].cast<float>());
  }
}

}  // namespace

InitialFramesMarked MarkInitialFrames(const InitialMap& initial, KeyframeId first,
                                      KeyframeId second, int map_id, int kept,
                                      std::vector<TrajectoryRecord>* records) {
  std::unordered_map<int64_t, const InitialInbetween*> inbetween;
  for (const InitialInbetween& f : initial.inbetween) inbetween.emplace(f.seq, &f);
  InitialFramesMarked marked;
  for (TrajectoryRecord& r : *records) {
    const bool is_first = r.seq == initial.first.seq;
    const bool is_second = r.seq == initial.second.seq;
    if (is_first || is_second) {
      if (is_second && HasPose(r.state)) continue;  // a pose in another map already
      ++marked.marked;
      marked.was_lost += r.state == TrackingState::kLost ? 1 : 0;
      r.state = TrackingState::kOk;
      r.reference = is_second ? second : first;
      r.map_id = map_id;
      r.reference_from_camera = Pose3::Identity();
      r.world_from_camera =
          is_first ? initial.first.world_from_camera : initial.second.world_from_camera;
      r.is_keyframe = true;
      continue;
    }
    const auto it = inbetween.find(r.seq);
    if (it != inbetween.end()) MarkInbetween(*it->second, first, map_id, kept, &r, &marked);
  }
  return marked;
}

InitialFramesMarked MarkInbetweenFrame(const InitialInbetween& frame, KeyframeId first, int map_id,
                                       int kept, std::vector<TrajectoryRecord>* records) {
  InitialFramesMarked marked;
  const auto r = std::find_if(records->rbegin(), records->rend(),
                              [&](const TrajectoryRecord& x) { return x.seq == frame.seq; });
  if (r != records->rend()) MarkInbetween(frame, first, map_id, kept, &*r, &marked);
  return marked;
}

void StartTracking(const InitialMap& initial, KeyframeId second, double timestamp,
                   Tracker* tracker) {
  tracker->Start(second, initial.second.world_from_camera, static_cast<int>(initial.points.size()),
                 timestamp,
                 MedianDepth(initial.second.world_from_camera.Inverse(), initial.points));
}

TrajectoryEntry ToEntry(const TrajectoryRecord& record, const MapData* map) {
  TrajectoryEntry e;
  e.seq = record.seq;
  e.timestamp = record.timestamp;
  e.state = record.state;
  e.world_from_camera = record.world_from_camera;
  if (record.reference && map != nullptr) {
    if (auto ref = map->ResolveKeyframePose(*record.reference))
      e.world_from_camera = *ref * record.reference_from_camera;
  }
  e.is_keyframe = record.is_keyframe;
  e.ground_truth_world_from_camera = record.ground_truth;
  e.map_id = record.map_id;
  return e;
}

void KeepObservations(const std::vector<VertexId>& ids, const std::vector<Eigen::Vector2d>& uvs,
                      int kept, TrajectoryRecord* record) {
  if (kept <= 0) return;  // EvenlySpacedIndices reads 0 as "every one"
  const std::vector<size_t> keep = EvenlySpacedIndices(ids.size(), static_cast<size_t>(kept));
  record->observed_ids.reserve(keep.size());
  record->observed_uvs.reserve(keep.size());
  for (const size_t i : keep) {
    record->observed_ids.push_back(ids[i]);
    record->observed_uvs.push_back(uvs[i].cast<float>());
  }
}

}  // namespace m2s::slam
