// Drift correction on a loop: a map built along a circle of keyframes with a growing Sim3 drift
// (locally consistent, like a drifting SLAM estimate). The last keyframe re-observes points of
// the first ones; after LocalMapper::Process the keyframe trajectory error must shrink.
#include <cmath>

#include <gtest/gtest.h>

#include "m2s/common/alignment.h"
#include "mapping/local_mapper.h"
#include "slam_sim.h"

namespace m2s::slam {
namespace {

constexpr int kKeyframes = 40;
constexpr double kTurn = 2.0 * M_PI + 0.6;  // a bit more than one turn

Pose3 CirclePose(double theta) {
  const Eigen::Vector3d forward(std::cos(theta), std::sin(theta), 0.0), down(0, 0, -1);
  Eigen::Matrix3d r;
  r.col(0) = down.cross(forward);
  r.col(1) = down;
  r.col(2) = forward;
  return Pose3(r, Eigen::Vector3d(0.8 * std::cos(theta), 0.8 * std::sin(theta), 1.5));
}

Sim3 Drift(int i) {
  const double f = static_cast<double>(i) / kKeyframes;
  return Sim3(
      1.0 + 0.03 * f,
      Eigen::Quaterniond(Eigen::AngleAxisd(4.0 * M_PI / 180.0 * f, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(0.06 * f, 0.03 * f, 0.0));
}

double KeyframeAte(const Map& map, const std::vector<Pose3>& truth) {
  std::vector<Eigen::Vector3d> est, gt;
  map.Read([&](const MapData& m) {
    for (const auto& [id, kf] : m.keyframes()) {
      est.push_back(kf.world_from_camera.translation());
      gt.push_back(truth[id].translation());
    }
  });
  const auto s = AlignPoints(est, gt, true);
  double sse = 0;
  for (size_t i = 0; i < est.size(); ++i) sse += ((*s) * est[i] - gt[i]).squaredNorm();
  return std::sqrt(sse / static_cast<double>(est.size()));
}

TEST(DriftCorrection, LoopClosureShrinksTheTrajectoryError) {
  const Scene room = testing::MakePointRoom(8000);
  Options options;
  options.camera = Camera();
  Map map;
  std::vector<Pose3> truth;
  std::vector<SortedFeatures> features;
  for (int i = 0; i <= kKeyframes; ++i) {
    truth.push_back(CirclePose(kTurn * i / kKeyframes));
    SortedFeatures f;
    const Pose3 cfw = truth.back().Inverse();
    for (size_t v = 0; v < room.positions.size(); ++v) {
      const Eigen::Vector3d pc = cfw * room.positions[v].cast<double>();
      if (pc.z() < 0.2) continue;
      const Eigen::Vector2d uv = options.camera.Project(pc);
      if (!options.camera.InImage(uv.x(), uv.y())) continue;
      f.ids.push_back(static_cast<VertexId>(v));
      f.uvs.push_back(uv);
    }
    features.push_back(std::move(f));
  }
  // The drifted map of keyframes 0..kKeyframes-1; the second half of the loop does not
  // observe points first seen in the first quarter (they become dormant).
  std::vector<int> first_seen(room.positions.size(), -1);
  for (int i = 0; i < kKeyframes; ++i) {
    for (const VertexId v : features[i].ids) {
      if (first_seen[v] < 0) first_seen[v] = i;
    }
  }
  map.Write([&](MapData& m) {
    for (int i = 0; i < kKeyframes; ++i) {
      Keyframe kf;
      kf.id = static_cast<KeyframeId>(i);
      kf.seq = i;
      kf.timestamp = i;
      kf.world_from_camera = Drift(i).TransformPose(truth[i]);
      kf.ids = features[i].ids;
      kf.uvs = features[i].uvs;
      m.AddKeyframe(std::move(kf));
    }
    for (size_t v = 0; v < room.positions.size(); ++v) {
      const int first = first_seen[v];
      if (first < 0) continue;
      std::vector<KeyframeId> observers;
      for (int i = first; i < kKeyframes; ++i) {
        if (i >= kKeyframes / 2 && first < kKeyframes / 4) continue;
        if (std::binary_search(features[i].ids.begin(), features[i].ids.end(),
                               static_cast<VertexId>(v))) {
          observers.push_back(static_cast<KeyframeId>(i));
        }
      }
      if (observers.size() < 2) continue;
      m.AddPoint(static_cast<VertexId>(v), Drift(first) * room.positions[v].cast<double>(), first);
      for (const KeyframeId o : observers) m.AddObservation(static_cast<VertexId>(v), o);
    }
  });
  for (int i = 0; i < kKeyframes; ++i) map.NextKeyframeId();
  const double before = KeyframeAte(map, truth);

  KeyframeCandidate c;
  c.id = map.NextKeyframeId();
  ASSERT_EQ(c.id, static_cast<KeyframeId>(kKeyframes));
  c.seq = kKeyframes;
  c.timestamp = kKeyframes;
  c.world_from_camera = Drift(kKeyframes).TransformPose(truth[kKeyframes]);
  c.features = features[kKeyframes];
  map.Read([&](const MapData& m) {
    for (const VertexId v : c.features.ids) {
      const MapPoint* p = m.point(v);
      if (p == nullptr) continue;
      if (static_cast<int>(p->last_observer()) < kKeyframes - options.loop_min_keyframe_gap) {
        c.dormant_points.push_back(v);
      } else {
        c.tracked_points.push_back(v);
      }
    }
  });
  ASSERT_GE(static_cast<int>(c.dormant_points.size()), options.loop_min_points);
  truth.push_back(truth[kKeyframes]);
  LocalMapper mapper(options, &map);
  const uint64_t epoch = map.correction().epoch;
  mapper.Process(c);
  const double after = KeyframeAte(map, truth);
  std::printf("keyframe ATE before %.4f m, after %.4f m (%zu dormant points)\n", before, after,
              c.dormant_points.size());
  EXPECT_EQ(mapper.stats().loop_corrections, 1);
  EXPECT_GT(map.correction().epoch, epoch);  // the tracker is told
  EXPECT_LT(after, 0.5 * before);
  // The dormant points are ordinary observations now.
  map.Read([&](const MapData& m) {
    for (const VertexId v : c.dormant_points) {
      const MapPoint* p = m.point(v);
      if (p != nullptr) {
        EXPECT_EQ(p->last_observer(), c.id);
      }
    }
  });
}

}  // namespace
}  // namespace m2s::slam
