// A view that thins out to a few points bunched in one corner (a hand-held camera swept past the
// edge of the mapped part): with pixel noise, such points fit camera centres decimetres apart.
// A pose they leave undetermined is reported lost, never placed off.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/numeric.h"
#include "slam_sim.h"

namespace m2s::slam {
namespace {

using testing::DefaultOptions;
using testing::MakePointRoom;
using testing::ProjectFrames;
using testing::SimOptions;

constexpr double kFps = 30.0;
constexpr double kDurationS = 4.0;
// Frames [kThinFrom, kThinTo) keep only the features of a small dense object.
constexpr int kThinFrom = 90, kThinTo = 98;
constexpr int kRoomPoints = 3000;
constexpr int kObjectPoints = 15;
constexpr double kObjectRadius = 0.06;

TEST(SparseView, PosesTheFewPointsLeaveUndeterminedAreLost) {
  // The room, and a dense object (a 12 cm disc, slightly domed, of kObjectPoints points) in
  // view throughout, 1.5 m ahead.
  Scene scene = MakePointRoom(kRoomPoints);
  for (int i = 0; i < kObjectPoints; ++i) {
    const double angle = 2.399963 * i;  // golden-angle spiral: evenly spread
    const double r = kObjectRadius * std::sqrt((i + 0.5) / kObjectPoints);
    scene.positions.emplace_back(0.3 + r * std::cos(angle),
                                 1.5 + 0.3 * kObjectRadius * std::sin(3.0 * angle),
                                 1.6 + r * std::sin(angle));
  }
  const Camera camera;
  SimOptions sim;
  sim.budget = 0;
  sim.occlusion = false;
  sim.pixel_noise_sigma = 0.5;
  std::vector<TimedPose> poses;
  for (int i = 0; i < static_cast<int>(kDurationS * kFps); ++i) {
    const double t = i / kFps;
    const Eigen::Vector3d eye(-0.4 + 0.3 * t, 0.1 * std::sin(t), 1.4 + 0.05 * std::sin(2.0 * t));
    poses.push_back(
        {t, LookAt(eye, eye + Eigen::Vector3d(0.1, 1.0, 0.0), Eigen::Vector3d::UnitZ())});
  }
  auto truth = Trajectory::FromPoses(std::move(poses));
  ASSERT_TRUE(truth.ok()) << truth.error();
  std::vector<Frame> frames = ProjectFrames(scene, *truth, camera, sim);
  int fewest = 1 << 30;
  for (int f = kThinFrom; f < kThinTo; ++f) {
    Frame& frame = frames[f];
    std::vector<VertexFeature> kept;
    for (const VertexFeature& x : frame.features) {
      if (x.id >= kRoomPoints) kept.push_back(x);
    }
    frame.features = std::move(kept);
    fewest = std::min(fewest, static_cast<int>(frame.features.size()));
  }
  ASSERT_EQ(fewest, kObjectPoints);  // enough for a pose by count: the geometry must decide
  auto system = System::Create(DefaultOptions(camera));
  ASSERT_TRUE(system.ok()) << system.error();
  for (const Frame& frame : frames) (*system)->Track(frame);
  // In the truth's frame by the similarity of the frames before the thinning.
  const testing::ErrorsAfter tracked =
      testing::ErrorsAlignedBefore((*system)->Trajectory(), /*map_id=*/0, kThinFrom);
  ASSERT_GE(tracked.aligned_on, 20u);
  const double worst = tracked.worst();
  const int thin_tracked = static_cast<int>(std::count_if(
      tracked.entries.begin(), tracked.entries.end(),
      [](const TrajectoryEntry& e) { return e.seq >= kThinFrom && e.seq < kThinTo; }));
  std::printf("%d object points; worst tracked error %.4f m; %d of %d thin frames tracked\n",
              fewest, worst, thin_tracked, kThinTo - kThinFrom);
  // Measured: 4 mm, with every thin frame lost (placed, they are up to 12 cm off).
  EXPECT_LT(worst, 0.02);
  // Tracking comes back once the view is full again.
  EXPECT_TRUE(std::any_of(tracked.entries.begin(), tracked.entries.end(),
                          [](const TrajectoryEntry& e) { return e.seq >= kThinTo + 10; }));
}

}  // namespace
}  // namespace m2s::slam
