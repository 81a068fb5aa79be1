// Helpers shared by the end-of-session refinement's two files (trajectory_refinement.cc,
// loose_frames.cc); not part of its interface (trajectory_refinement.h).
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/geometry.h"
#include "m2s/slam/options.h"
#include "map/map_data.h"
#include "system/system_common.h"

namespace m2s::slam::refinement_internal {

// The record's observations that are points of `map` (with observers), with their pixels and,
// with `uncertainties`, each point's relative uncertainty (MapPoint::uncertainty, 0 where
// unknown).
void MappedObservations(const MapData& map, const TrajectoryRecord& record,
                        std::vector<Eigen::Vector3d>* points, std::vector<Eigen::Vector2d>* uvs,
                        std::vector<double>* uncertainties = nullptr);

// Whether `points` reprojection errors whose squares sum to `squared_error` are exact data:
// their variance factor (2 per point, 6 for the pose) below kExactDataVarianceFactor.
bool ExactData(const MeasurementModel& model, double squared_error, size_t points);

// The pose (world_from_camera) of a record with one in map `map_id` of `map`.
std::optional<Pose3> RecordPose(const MapData& map, int map_id, const TrajectoryRecord& record);

}  // namespace m2s::slam::refinement_internal
