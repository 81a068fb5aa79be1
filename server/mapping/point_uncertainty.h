// How well a map point's position is known: the covariance of a point measured by its observers
// under isotropic pixel noise, with the observers' poses taken as exact.
//
// Each observer k contributes J_k = d project(camera_from_world_k * X) / dX (2x3, pixels per
// unit length); the information per unit pixel variance is H = sum_k J_k^T J_k, and with noise
// sigma the covariance is sigma^2 H^-1. Its largest standard deviation, sigma / sqrt of the
// smallest eigenvalue of H, lies along the rays when they are nearly parallel: that is the depth
// a small baseline leaves open. The point's relative uncertainty is that deviation over its
// mean depth in the observers (monocular scale is arbitrary; the ratio is not).
//
// Pure functions, thread-safe; UpdatePointUncertainty writes to the MapData it is given (call it
// inside Map::Write).
//
//   double u = RelativePointUncertainty(camera, 1.0, {cfw_a, cfw_b}, point);
//   map.Write([&](MapData& m) { UpdatePointUncertainty(camera, PointGate(), ids, &m); });
#pragma once

#include <vector>

#include <Eigen/Core>

#include "m2s/common/camera.h"
#include "m2s/common/geometry.h"
#include "m2s/common/types.h"
#include "map/map_data.h"

namespace m2s::slam {

// sum_k J_k^T J_k over the observers; `*mean_depth` (optional) gets the mean depth of the point
// in them. Returns false when the point is not in front of every observer.
bool PointInformation(const Camera& camera, const std::vector<Pose3>& camera_from_world,
                      const Eigen::Vector3d& point_world, Eigen::Matrix3d* information,
                      double* mean_depth = nullptr);

// pixel_sigma / sqrt(lambda_min(H)) / mean depth; +inf for fewer than two observers, a point
// behind one, or a singular H.
double RelativePointUncertainty(const Camera& camera, double pixel_sigma,
                                const std::vector<Pose3>& camera_from_world,
                                const Eigen::Vector3d& point_world);

// When a map point counts as well constrained.
struct PointGate {
  double pixel_sigma = 1.0;           // the measurement model's feature noise
  double max_uncertainty = 0.01;      // MapperOptions::max_point_uncertainty
  double max_reprojection_px = 2.45;  // every observation agrees with the position
};

// Recomputes the relative uncertainty of the points `ids` of `map` (missing ones are skipped)
// from their observers' current poses, and marks them constrained when it is at most
// gate.max_uncertainty and every observation reprojects within gate.max_reprojection_px. A
// position its observations disagree with is no estimate, however many rays meet there
// (measured: such points are most of those more than 5 cm off).
void UpdatePointUncertainty(const Camera& camera, const PointGate& gate,
                            const std::vector<VertexId>& ids, MapData* map);

// The same in two steps, so that the work runs under Map::Read and only the result under
// Map::Write (tracking waits for the write lock, not for the evaluation).
struct PointQuality {
  VertexId id = 0;
  double uncertainty = -1.0;
  bool constrained = false;
};
std::vector<PointQuality> EvaluatePointUncertainty(const Camera& camera, const PointGate& gate,
                                                   const std::vector<VertexId>& ids,
                                                   const MapData& map);
// Points that no longer exist are skipped.
void ApplyPointQuality(const std::vector<PointQuality>& quality, MapData* map);

}  // namespace m2s::slam
