#include "tracking/frame_validation.h"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace m2s::slam {
namespace {

Frame MakeFrame(int64_t seq, double t, std::vector<std::pair<VertexId, Eigen::Vector2f>> f) {
  Frame frame;
  frame.seq = seq;
  frame.timestamp = t;
  for (const auto& [id, uv] : f) frame.features.push_back({id, uv});
  return frame;
}

// The reason code of a rejection; kAccepted when the frame passed.
constexpr DropReason kAccepted = DropReason::kCount;
DropReason Reason(const Status& status) { return status ? kAccepted : *status.reason(); }

TEST(FrameValidator, SortsValidFramesById) {
  const Options options;
  FrameValidator v(options.camera, options.max_features_per_frame, options.image_margin_px);
  SortedFeatures out;
  EXPECT_EQ(Reason(v.Validate(MakeFrame(0, 0.0, {{9, {1, 2}}, {3, {4, 5}}, {5, {6, 7}}}), &out)),
            kAccepted);
  EXPECT_EQ(out.ids, (std::vector<VertexId>{3, 5, 9}));
  EXPECT_EQ(out.uvs[2], Eigen::Vector2d(1, 2));
}

TEST(FrameValidator, RejectsBadFramesWithReasons) {
  const Options options;
  FrameValidator v(options.camera, /*max_features=*/100, options.image_margin_px);
  SortedFeatures out;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(Reason(v.Validate(MakeFrame(0, 0.0, {}), &out)), DropReason::kEmptyFrame);
  EXPECT_EQ(Reason(v.Validate(MakeFrame(0, 0.0, {{1, {nan, 2}}}), &out)), DropReason::kNonFiniteUv);
  EXPECT_EQ(Reason(v.Validate(MakeFrame(0, 0.0, {{1, {3, inf}}}), &out)), DropReason::kNonFiniteUv);
  EXPECT_EQ(Reason(v.Validate(MakeFrame(0, 0.0, {{1, {3, 4}}, {1, {5, 6}}}), &out)),
            DropReason::kDuplicateId);
  EXPECT_EQ(Reason(v.Validate(MakeFrame(0, 0.0, {{1, {-100, 4}}}), &out)), DropReason::kOutOfImage);
  EXPECT_EQ(Reason(v.Validate(MakeFrame(0, 0.0, {{1, {3, 4000}}}), &out)), DropReason::kOutOfImage);
  Frame big = MakeFrame(0, 0.0, {});
  for (VertexId i = 0; i < 101; ++i) big.features.push_back({i, {1, 1}});
  EXPECT_EQ(Reason(v.Validate(big, &out)), DropReason::kTooManyFeatures);
  EXPECT_EQ(Reason(v.Validate(MakeFrame(0, std::nan(""), {{1, {3, 4}}}), &out)),
            DropReason::kNonFiniteTimestamp);
  // Within the margin outside the image is accepted (noise near the border).
  EXPECT_EQ(Reason(v.Validate(MakeFrame(5, 1.0, {{1, {-3, 4}}}), &out)), kAccepted);
  EXPECT_EQ(Reason(v.Validate(MakeFrame(5, 2.0, {{1, {3, 4}}}), &out)),
            DropReason::kSeqNotIncreasing);
  EXPECT_EQ(Reason(v.Validate(MakeFrame(6, 0.5, {{1, {3, 4}}}), &out)),
            DropReason::kTimestampGoingBack);
  EXPECT_EQ(Reason(v.Validate(MakeFrame(6, 1.0, {{1, {3, 4}}}), &out)),
            kAccepted);  // equal time is fine
}

}  // namespace
}  // namespace m2s::slam
