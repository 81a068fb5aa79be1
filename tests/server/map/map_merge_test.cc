// Aligning and merging maps by vertex id: two maps of one scene, the second in its own world
// and scale (a known Sim3 away), sharing some points; references are the true poses, points
// and Sim3 the maps were built from.
#include "map/map_merge.h"

#include <cmath>
#include <random>
#include <unordered_map>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace m2s::slam {
namespace {

struct World {
  std::vector<Eigen::Vector3d> points;  // id = index
  std::vector<Pose3> poses;             // world_from_camera of the keyframes
};

World MakeWorld() {
  World w;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> x(-2.0, 2.0), y(-1.5, 1.5), z(2.0, 5.0);
  for (int i = 0; i < 300; ++i) w.points.emplace_back(x(rng), y(rng), z(rng));
  for (int k = 0; k < 6; ++k) {
    const Eigen::Quaterniond r(Eigen::AngleAxisd(0.05 * k, Eigen::Vector3d::UnitY()));
    w.poses.emplace_back(r, Eigen::Vector3d(0.3 * k, 0.02 * k, 0.0));
  }
  return w;
}

// A map of points [first, last) seen by keyframes `poses`, all expressed in a world
// `map_from_world` away from the true one; keyframe ids from `first_keyframe`. The keyframes'
// pixels are the points' true projections in `camera` (the world's scale does not change them).
MapData BuildMap(const World& w, int first, int last, const std::vector<int>& keyframes,
                 const Sim3& map_from_world, KeyframeId first_keyframe,
                 const Camera& camera = Camera()) {
  MapData m;
  KeyframeId id = first_keyframe;
  for (const int k : keyframes) {
    Keyframe kf;
    kf.id = id++;
    kf.seq = k;
    kf.world_from_camera = map_from_world.TransformPose(w.poses[k]);
    for (int i = first; i < last; ++i) {
      kf.ids.push_back(static_cast<VertexId>(i));
      kf.uvs.push_back(camera.Project(w.poses[k].Inverse() * w.points[i]));
    }
    m.AddKeyframe(std::move(kf));
  }
  for (int i = first; i < last; ++i) {
    m.AddPoint(static_cast<VertexId>(i), map_from_world * w.points[i], first_keyframe);
    for (KeyframeId k = first_keyframe; k < id; ++k) m.AddObservation(static_cast<VertexId>(i), k);
  }
  return m;
}

double SimError(const Sim3& a, const Sim3& b) {
  return std::abs(a.scale() - b.scale()) + a.rotation().angularDistance(b.rotation()) +
         (a.translation() - b.translation()).norm();
}

const Sim3 kBFromWorld(0.37,
                       Eigen::Quaterniond(Eigen::AngleAxisd(0.8,
                                                            Eigen::Vector3d(1, 2, 3).normalized())),
                       Eigen::Vector3d(-1.0, 4.0, 0.5));

TEST(MapMerge, AlignmentRecoversTheKnownSim3AndLeavesOutBadPoints) {
  const World w = MakeWorld();
  const MapData a = BuildMap(w, 0, 200, {0, 1, 2}, Sim3(), 0);
  MapData b = BuildMap(w, 100, 300, {3, 4, 5}, kBFromWorld, 0);
  // Five shared points triangulated badly in b: 0.2 m (in b's units) off.
  for (VertexId id = 150; id < 155; ++id) {
    b.SetPointPosition(id, b.point(id)->position + Eigen::Vector3d(0.2, -0.1, 0.15));
  }
  const Expected<MapAlignment> aligned = AlignMaps(a, b, MapAlignmentOptions{});
  ASSERT_TRUE(aligned) << aligned.error();
  EXPECT_EQ(aligned->shared_points, 100);
  EXPECT_EQ(aligned->inliers, 95);
  EXPECT_LT(SimError(aligned->into_from_from, kBFromWorld.Inverse()), 1e-10);
  EXPECT_LT(aligned->rms_residual, 1e-10);
  // The inliers are uniform in a 4 x 3 x 3 m box: RMS distance from the centre
  // sqrt((16 + 9 + 9) / 12) = 1.68 m, up to the sampling of 95 points.
  EXPECT_NEAR(aligned->spread, std::sqrt(34.0 / 12.0), 0.25);
}

TEST(MapMerge, MergedMapHoldsBothInOneWorld) {
  const World w = MakeWorld();
  MapData a = BuildMap(w, 0, 200, {0, 1, 2}, Sim3(), 0);
  const MapData b = BuildMap(w, 100, 300, {3, 4, 5}, kBFromWorld, 0);
  const Expected<MapAlignment> aligned = AlignMaps(a, b, MapAlignmentOptions{});
  ASSERT_TRUE(aligned) << aligned.error();
  EXPECT_EQ(MergeMapInto(&a, b, aligned->into_from_from, /*first_keyframe_id=*/10).size(), 3u);
  ASSERT_EQ(a.keyframes().size(), 6u);
  ASSERT_EQ(a.points().size(), 300u);
  // b's keyframes 0, 1, 2 are a's 10, 11, 12, at the true poses of keyframes 3, 4, 5.
  for (int k = 0; k < 3; ++k) {
    const Keyframe* kf = a.keyframe(10 + k);
    ASSERT_NE(kf, nullptr);
    EXPECT_LT((kf->world_from_camera.translation() - w.poses[3 + k].translation()).norm(), 1e-10);
    EXPECT_LT(kf->world_from_camera.rotation().angularDistance(w.poses[3 + k].rotation()), 1e-10);
  }
  for (int i = 0; i < 300; ++i) {
    const MapPoint* p = a.point(static_cast<VertexId>(i));
    ASSERT_NE(p, nullptr) << i;
    EXPECT_LT((p->position - w.points[i]).norm(), 1e-10) << i;
    // Shared points are seen by both maps' keyframes, the others by their own map's.
    const std::vector<KeyframeId> expected =
        i < 100 ? std::vector<KeyframeId>{0, 1, 2}
                : (i < 200 ? std::vector<KeyframeId>{0, 1, 2, 10, 11, 12}
                           : std::vector<KeyframeId>{10, 11, 12});
    EXPECT_EQ(p->observers, expected) << i;
  }
}

TEST(MapMerge, KeepsKeyframeIdsAndCarriesLinksOfRemovedKeyframesThroughTheScale) {
  const World w = MakeWorld();
  MapData a = BuildMap(w, 0, 200, {0, 1, 2}, Sim3(), 0);
  // b draws its ids from the same counter (20...): merging keeps them.
  MapData b = BuildMap(w, 100, 300, {3, 4, 5}, kBFromWorld, 20);
  // Keyframe 21 (true pose 4) was culled in b: its trajectory entries resolve through 20.
  const Pose3 parent_from_camera =
      b.keyframe(20)->world_from_camera.Inverse() * b.keyframe(21)->world_from_camera;
  b.RemoveKeyframe(21, KeyframeLink{20, parent_from_camera});
  const Expected<MapAlignment> aligned = AlignMaps(a, b, MapAlignmentOptions{});
  ASSERT_TRUE(aligned) << aligned.error();
  const auto ids = MergeMapInto(&a, b, aligned->into_from_from);
  EXPECT_EQ(ids, (std::unordered_map<KeyframeId, KeyframeId>{{20, 20}, {21, 21}, {22, 22}}));
  EXPECT_NE(a.keyframe(20), nullptr);
  EXPECT_EQ(a.keyframe(21), nullptr);
  EXPECT_NE(a.keyframe(22), nullptr);
  for (const auto& [id, truth] : {std::pair{20, 3}, std::pair{21, 4}, std::pair{22, 5}}) {
    const std::optional<Pose3> pose = a.ResolveKeyframePose(id);
    ASSERT_TRUE(pose) << id;
    EXPECT_LT((pose->translation() - w.poses[truth].translation()).norm(), 1e-10) << id;
    EXPECT_LT(pose->rotation().angularDistance(w.poses[truth].rotation()), 1e-10) << id;
  }
}

TEST(MapMerge, ImagesAgreeWithTheTrueSim3AndNotWithOneThreeDegreesOff) {
  const World w = MakeWorld();
  const Camera camera;
  const MapData a = BuildMap(w, 0, 200, {0, 1, 2}, Sim3(), 0, camera);
  const MapData b = BuildMap(w, 100, 300, {3, 4, 5}, kBFromWorld, 0, camera);
  // 100 shared points, each seen by 3 keyframes of either map.
  const ImageAgreement exact = CheckAlignmentInImages(camera, a, b, kBFromWorld.Inverse(), 0.01);
  EXPECT_EQ(exact.observations, 300);
  EXPECT_EQ(exact.agreeing, 300);
  const ImageAgreement back = CheckAlignmentInImages(camera, b, a, kBFromWorld, 0.01);
  EXPECT_EQ(back.agreeing, 300);
  // Three degrees about the vertical through the scene's centre (0, 0, 3.5) move a point 1 m
  // from it by 52 mm, 7-26 px at these depths and focal length; points near the axis, or
  // moving along their ray, move less in the image and may stay within 3 px.
  const Pose3 turn(Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 60.0, Eigen::Vector3d::UnitY())),
                   Eigen::Vector3d::Zero());
  const Pose3 about_centre = Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 3.5)) *
                             turn *
                             Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, -3.5));
  const ImageAgreement off =
      CheckAlignmentInImages(camera, a, b, Sim3(about_centre) * kBFromWorld.Inverse(), 3.0);
  EXPECT_EQ(off.observations, 300);
  EXPECT_LT(off.fraction(), 0.25);
}

TEST(MapMerge, WithACameraRefusesAFitTheImagesContradict) {
  const World w = MakeWorld();
  const Camera camera;
  const MapData a = BuildMap(w, 0, 200, {0, 1, 2}, Sim3(), 0, camera);
  MapData b = BuildMap(w, 100, 300, {3, 4, 5}, kBFromWorld, 0, camera);
  MapAlignmentOptions with_images;
  with_images.camera = camera;
  const Expected<MapAlignment> right = AlignMaps(a, b, with_images);
  ASSERT_TRUE(right) << right.error();
  EXPECT_DOUBLE_EQ(right->image_agreement, 1.0);
  // b's structure wrong the way a small baseline leaves it: depths along the rays of its first
  // keyframe stretched by 30 % about 3.5 m (2 m -> 1.55 m, 5 m -> 5.45 m; its keyframes and
  // their pixels stay true). A Sim3 still fits the shared points in 3D, most of them inliers.
  const Pose3 b_from_camera = b.keyframe(0)->world_from_camera;
  const double b_scale = kBFromWorld.scale();
  for (VertexId id = 100; id < 300; ++id) {
    const Eigen::Vector3d in_camera = b_from_camera.Inverse() * b.point(id)->position;
    const double depth = in_camera.z() / b_scale;  // metres
    const double stretched = 1.3 * depth - 0.3 * 3.5;
    b.SetPointPosition(id, b_from_camera * (in_camera * (stretched / depth)));
  }
  const Expected<MapAlignment> in_3d = AlignMaps(a, b, MapAlignmentOptions{});
  ASSERT_TRUE(in_3d) << in_3d.error();
  EXPECT_GE(in_3d->inliers, 95);
  EXPECT_GT(SimError(in_3d->into_from_from, kBFromWorld.Inverse()), 0.05);
  const Expected<MapAlignment> checked = AlignMaps(a, b, with_images);
  ASSERT_FALSE(checked);
  EXPECT_NE(checked.error().find("observations in the keyframes"), std::string::npos)
      << checked.error();
}

TEST(MapMerge, RefusesTooFewSharedOrDegeneratePoints) {
  const World w = MakeWorld();
  const MapData a = BuildMap(w, 0, 200, {0, 1}, Sim3(), 0);
  const MapData few = BuildMap(w, 190, 300, {4, 5}, kBFromWorld, 0);  // 10 shared
  const Expected<MapAlignment> not_enough = AlignMaps(a, few, MapAlignmentOptions{});
  ASSERT_FALSE(not_enough);
  EXPECT_NE(not_enough.error().find("share 10 points"), std::string::npos) << not_enough.error();

  World line = w;
  for (int i = 0; i < 300; ++i)
    line.points[i] = Eigen::Vector3d(0.01 * i, 0.02 * i, 3.0 + 0.005 * i);
  const MapData la = BuildMap(line, 0, 200, {0, 1}, Sim3(), 0);
  const MapData lb = BuildMap(line, 100, 300, {4, 5}, kBFromWorld, 0);
  const Expected<MapAlignment> collinear = AlignMaps(la, lb, MapAlignmentOptions{});
  ASSERT_FALSE(collinear);
  EXPECT_NE(collinear.error().find("degenerate"), std::string::npos) << collinear.error();

  MapAlignmentOptions bad;
  bad.trim_factor = 0.5;
  EXPECT_FALSE(AlignMaps(a, few, bad));
}

}  // namespace
}  // namespace m2s::slam
