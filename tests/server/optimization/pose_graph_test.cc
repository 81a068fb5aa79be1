// OptimizePoseGraph: a loop with injected drift is corrected by consistent relative edges;
// fixed nodes are unchanged; bad input is rejected.
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "optimization/problems.h"
#include "synthetic_scene.h"

namespace m2s::slam {
namespace {

constexpr int kNodes = 24;

// True world_from_camera poses around a circle, and a drifted copy: each node accumulates a
// growing rotation, translation and scale error, as monocular odometry does.
std::vector<Sim3> TruePoses() {
  std::vector<Sim3> poses;
  for (const Pose3& pose : testing::CirclePoses(kNodes, 4.0, 2 * M_PI * (kNodes - 1) / kNodes)) {
    poses.emplace_back(pose);
  }
  return poses;
}

std::vector<PoseGraphNode> DriftedNodes(const std::vector<Sim3>& truth) {
  std::vector<PoseGraphNode> nodes;
  for (int i = 0; i < kNodes; ++i) {
    const Sim3 drift(std::pow(1.01, i),
                     Eigen::Quaterniond(Eigen::AngleAxisd(0.004 * i, Eigen::Vector3d::UnitZ())),
                     Eigen::Vector3d(0.01 * i, -0.005 * i, 0.002 * i));
    nodes.push_back({static_cast<KeyframeId>(i), drift * truth[i], false});
  }
  return nodes;
}

// Odometry edges i -> i+1 and one loop edge last -> first, all from the truth (consistent).
std::vector<PoseGraphEdge> LoopEdges(const std::vector<Sim3>& truth) {
  std::vector<PoseGraphEdge> edges;
  for (int i = 0; i + 1 < kNodes; ++i)
    edges.push_back({i, i + 1, truth[i].Inverse() * truth[i + 1], 1.0});
  edges.push_back({kNodes - 1, 0, truth[kNodes - 1].Inverse() * truth[0], 10.0});
  return edges;
}

double NodeError(const Sim3& a, const Sim3& b) { return (a.Matrix() - b.Matrix()).norm(); }

TEST(PoseGraphTest, CorrectsDriftOnALoop) {
  const std::vector<Sim3> truth = TruePoses();
  std::vector<PoseGraphNode> nodes = DriftedNodes(truth);
  nodes[0].fixed = true;  // drift(0) is the identity: node 0 is at the truth
  const double before = NodeError(nodes[kNodes - 1].world_from_camera, truth[kNodes - 1]);
  ASSERT_GT(before, 0.1);
  PoseGraphOptions options;
  options.max_iterations = 100;
  const PoseGraphResult result = OptimizePoseGraph(options, &nodes, LoopEdges(truth));
  ASSERT_TRUE(result.success);
  EXPECT_GT(result.initial_cost, 1e-3);
  EXPECT_LT(result.final_cost, 1e-16);
  for (int i = 0; i < kNodes; ++i) {
    EXPECT_LT(NodeError(nodes[i].world_from_camera, truth[i]), 1e-7) << i;
  }
  EXPECT_NEAR(nodes[kNodes - 1].world_from_camera.scale(), 1.0, 1e-8);
}

TEST(PoseGraphTest, FixedNodesAreUnchangedAndTheGaugeDefaultsToTheFirstNode) {
  const std::vector<Sim3> truth = TruePoses();
  std::vector<PoseGraphNode> nodes = DriftedNodes(truth);
  nodes[0].world_from_camera = truth[0];
  nodes[12].fixed = true;  // fixed at a drifted (wrong) pose: must not move
  const Sim3 held = nodes[12].world_from_camera;
  PoseGraphResult result = OptimizePoseGraph(PoseGraphOptions(), &nodes, LoopEdges(truth));
  ASSERT_TRUE(result.success);
  EXPECT_EQ(nodes[12].world_from_camera.Matrix(), held.Matrix());
  EXPECT_LT(result.final_cost, result.initial_cost);

  // No fixed node: the first one holds the gauge, so with it at the truth all is recovered.
  nodes = DriftedNodes(truth);
  PoseGraphOptions options;
  options.max_iterations = 100;
  result = OptimizePoseGraph(options, &nodes, LoopEdges(truth));
  ASSERT_TRUE(result.success);
  EXPECT_LT(NodeError(nodes[0].world_from_camera, truth[0]), 1e-12);
  for (int i = 0; i < kNodes; ++i)
    EXPECT_LT(NodeError(nodes[i].world_from_camera, truth[i]), 1e-7) << i;
}

TEST(PoseGraphTest, BadInputIsRejectedAndNodesUnchanged) {
  const std::vector<Sim3> truth = TruePoses();
  std::vector<PoseGraphNode> nodes = DriftedNodes(truth);
  const std::vector<PoseGraphNode> before = nodes;
  auto unchanged = [&] {
    for (int i = 0; i < kNodes; ++i) {
      if (nodes[i].world_from_camera.Matrix() != before[i].world_from_camera.Matrix()) return false;
    }
    return true;
  };
  std::vector<PoseGraphEdge> edges = LoopEdges(truth);
  edges.push_back({0, kNodes, Sim3(), 1.0});
  EXPECT_FALSE(OptimizePoseGraph(PoseGraphOptions(), &nodes, edges).success);
  EXPECT_TRUE(unchanged());
  edges = LoopEdges(truth);
  edges[3].weight = -1.0;
  EXPECT_FALSE(OptimizePoseGraph(PoseGraphOptions(), &nodes, edges).success);
  edges = LoopEdges(truth);
  edges[4].from_from_to = Sim3(0.0, Eigen::Quaterniond::Identity(), Eigen::Vector3d::Zero());
  EXPECT_FALSE(OptimizePoseGraph(PoseGraphOptions(), &nodes, edges).success);
  nodes[2].world_from_camera = Sim3(std::numeric_limits<double>::quiet_NaN(),
                                    Eigen::Quaterniond::Identity(), Eigen::Vector3d::Zero());
  EXPECT_FALSE(OptimizePoseGraph(PoseGraphOptions(), &nodes, LoopEdges(truth)).success);
  nodes = before;
  PoseGraphOptions bad;
  bad.max_iterations = 0;
  Status why;
  EXPECT_FALSE((why = bad.Check()));
  EXPECT_FALSE(why.message().empty());
  EXPECT_FALSE(OptimizePoseGraph(bad, &nodes, LoopEdges(truth)).success);
  EXPECT_FALSE(OptimizePoseGraph(PoseGraphOptions(), nullptr, LoopEdges(truth)).success);
  EXPECT_TRUE(unchanged());
}

}  // namespace
}  // namespace m2s::slam
