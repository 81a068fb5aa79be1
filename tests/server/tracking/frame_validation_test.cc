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

TEST(FrameValidator, SortsValidFramesById) {
  const Options options;
  FrameValidator v(options.camera, options.max_features_per_frame, options.image_margin_px);
  SortedFeatures out;
  EXPECT_EQ(v.Validate(MakeFrame(0, 0.0, {{9, {1, 2}}, {3, {4, 5}}, {5, {6, 7}}}), &out), "");
  EXPECT_EQ(out.ids, (std::vector<VertexId>{3, 5, 9}));
  EXPECT_EQ(out.uvs[2], Eigen::Vector2d(1, 2));
}

TEST(FrameValidator, RejectsBadFramesWithReasons) {
  const Options options;
  FrameValidator v(options.camera, /*max_features=*/100, options.image_margin_px);
  SortedFeatures out;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(v.Validate(MakeFrame(0, 0.0, {}), &out), "empty");
  EXPECT_EQ(v.Validate(MakeFrame(0, 0.0, {{1, {nan, 2}}}), &out), "non_finite_uv");
  EXPECT_EQ(v.Validate(MakeFrame(0, 0.0, {{1, {3, inf}}}), &out), "non_finite_uv");
  EXPECT_EQ(v.Validate(MakeFrame(0, 0.0, {{1, {3, 4}}, {1, {5, 6}}}), &out), "duplicate_id");
  EXPECT_EQ(v.Validate(MakeFrame(0, 0.0, {{1, {-100, 4}}}), &out), "out_of_image");
  EXPECT_EQ(v.Validate(MakeFrame(0, 0.0, {{1, {3, 4000}}}), &out), "out_of_image");
  Frame big = MakeFrame(0, 0.0, {});
  for (VertexId i = 0; i < 101; ++i) big.features.push_back({i, {1, 1}});
  EXPECT_EQ(v.Validate(big, &out), "too_many_features");
  EXPECT_EQ(v.Validate(MakeFrame(0, std::nan(""), {{1, {3, 4}}}), &out), "non_finite_timestamp");
  // Within the margin outside the image is accepted (noise near the border).
  EXPECT_EQ(v.Validate(MakeFrame(5, 1.0, {{1, {-3, 4}}}), &out), "");
  EXPECT_EQ(v.Validate(MakeFrame(5, 2.0, {{1, {3, 4}}}), &out), "seq_not_increasing");
  EXPECT_EQ(v.Validate(MakeFrame(6, 0.5, {{1, {3, 4}}}), &out), "timestamp_going_back");
  EXPECT_EQ(v.Validate(MakeFrame(6, 1.0, {{1, {3, 4}}}), &out), "");  // equal time is fine
}

}  // namespace
}  // namespace m2s::slam
