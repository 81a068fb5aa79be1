// Coalescing map deltas: applying the coalesced delta to a replica equals applying the deltas
// one by one. Reference: a plain replica (id -> position) written here.
#include "map/map_delta.h"

#include <map>

#include <gtest/gtest.h>

namespace m2s::slam {
namespace {

using Replica = std::map<VertexId, Eigen::Vector3f>;

void Apply(const MapDelta& d, Replica* replica, std::map<KeyframeId, double>* keyframes) {
  if (d.full) {
    replica->clear();
    keyframes->clear();
  }
  for (const VertexId id : d.removed_points) replica->erase(id);
  for (size_t i = 0; i < d.point_ids.size(); ++i) (*replica)[d.point_ids[i]] = d.point_positions[i];
  for (const KeyframeId id : d.removed_keyframes) keyframes->erase(id);
  for (const KeyframeState& kf : d.keyframes) (*keyframes)[kf.id] = kf.timestamp;
}

MapDelta Delta(uint64_t base, uint64_t revision, std::vector<std::pair<VertexId, float>> upserts,
               std::vector<VertexId> removed, std::vector<KeyframeId> keyframes = {},
               std::vector<KeyframeId> removed_keyframes = {}) {
  MapDelta d;
  d.base_revision = base;
  d.revision = revision;
  for (const auto& [id, x] : upserts) {
    d.point_ids.push_back(id);
    d.point_positions.emplace_back(x, 0.0f, 0.0f);
  }
  d.removed_points = removed;
  for (const KeyframeId id : keyframes) d.keyframes.push_back({id, 0.1 * id, Pose3(), true});
  d.removed_keyframes = removed_keyframes;
  return d;
}

TEST(AppendDelta, CoalescedEqualsAppliedInOrder) {
  const std::vector<MapDelta> deltas = {
      Delta(3, 5, {{1, 1.0f}, {2, 2.0f}, {7, 7.0f}}, {4}, {10, 11}),
      Delta(5, 6, {{2, 2.5f}}, {7, 9}, {12}, {10}),
      Delta(6, 9, {{7, 7.5f}, {4, 4.5f}}, {1}, {10}, {11}),
  };
  Replica one_by_one = {{1, Eigen::Vector3f(0.5f, 0, 0)},
                        {4, Eigen::Vector3f(4, 0, 0)},
                        {9, Eigen::Vector3f(9, 0, 0)}};
  std::map<KeyframeId, double> kf_one_by_one = {{11, 1.1}, {3, 0.3}};
  Replica coalesced = one_by_one;
  std::map<KeyframeId, double> kf_coalesced = kf_one_by_one;

  MapDelta acc;
  acc.base_revision = acc.revision = 3;
  for (const MapDelta& d : deltas) {
    Apply(d, &one_by_one, &kf_one_by_one);
    AppendDelta(&acc, d);
  }
  EXPECT_EQ(acc.base_revision, 3u);
  EXPECT_EQ(acc.revision, 9u);
  EXPECT_FALSE(acc.full);
  Apply(acc, &coalesced, &kf_coalesced);
  EXPECT_EQ(coalesced, one_by_one);
  EXPECT_EQ(kf_coalesced, kf_one_by_one);
  // Point 1 was upserted then removed: only its removal remains; 7 removed then upserted: only
  // the upsert.
  EXPECT_EQ(acc.removed_points, (std::vector<VertexId>{1, 9}));
  EXPECT_EQ(acc.point_ids, (std::vector<VertexId>{2, 4, 7}));
}

TEST(AppendDelta, AFullDeltaStartsOverAndStaysFull) {
  MapDelta acc = Delta(0, 4, {{1, 1.0f}}, {});
  acc.full = true;
  AppendDelta(&acc, Delta(4, 5, {{2, 2.0f}}, {1}));
  EXPECT_TRUE(acc.full);
  EXPECT_EQ(acc.base_revision, 0u);
  EXPECT_EQ(acc.point_ids, (std::vector<VertexId>{2}));
  EXPECT_TRUE(acc.removed_points.empty());  // a full delta lists what exists

  MapDelta full = Delta(0, 8, {{5, 5.0f}}, {});
  full.full = true;
  AppendDelta(&acc, full);
  EXPECT_EQ(acc.point_ids, (std::vector<VertexId>{5}));
  EXPECT_EQ(acc.revision, 8u);
}

}  // namespace
}  // namespace m2s::slam
