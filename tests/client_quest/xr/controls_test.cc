// The XR client's controls: scripted events, controller bindings, and the overlay's choice
// of keyframe colours.
#include <gtest/gtest.h>

#include <set>
#include <string>

#include "m2s/xr/xr_actions.h"
#include "m2s/xr/xr_client.h"
#include "overlay.h"

namespace m2s::xr {
namespace {

TEST(ControlEvents, ParsesNamesAndFrames) {
  auto events = ParseControlEvents("reset@200,overlay@5,quit@0,others@7");
  ASSERT_TRUE(events.ok()) << events.error();
  ASSERT_EQ(events->size(), 4u);
  EXPECT_EQ((*events)[3].kind, ControlEvent::Kind::kToggleOtherKeyframes);
  EXPECT_EQ((*events)[3].frame, 7);
  EXPECT_EQ((*events)[0].kind, ControlEvent::Kind::kReset);
  EXPECT_EQ((*events)[0].frame, 200);
  EXPECT_EQ((*events)[1].kind, ControlEvent::Kind::kToggleOverlay);
  EXPECT_EQ((*events)[2].kind, ControlEvent::Kind::kQuit);
  EXPECT_TRUE(ParseControlEvents("").ok());
}

TEST(ControlEvents, RejectsMalformedText) {
  for (const char* bad : {"jump@3", "reset", "reset@", "reset@-1", "reset@1x"}) {
    EXPECT_FALSE(ParseControlEvents(bad).ok()) << bad;
  }
}

TEST(XrClientOptions, CheckRejectsBadValues) {
  XrClientOptions options;
  Status why;
  EXPECT_TRUE((why = options.Check())) << why.message();
  options.align_every_frames = 0;
  EXPECT_FALSE((why = options.Check()));
  options = XrClientOptions();
  options.camera.width = -1;
  EXPECT_FALSE((why = options.Check()));
}

TEST(ControllerBindings, EveryActionBoundForBothProfiles) {
  for (const char* profile : {"/interaction_profiles/khr/simple_controller",
                              "/interaction_profiles/oculus/touch_controller"}) {
    std::set<ControllerAction> bound;
    std::set<std::string> inputs;
    for (const SuggestedBinding& b : ControllerBindings()) {
      if (std::string(b.interaction_profile) != profile) continue;
      bound.insert(b.action);
      EXPECT_TRUE(inputs.insert(b.input_path).second) << b.input_path << " bound twice";
    }
    EXPECT_EQ(bound.size(), 3u) << profile;
  }
}

// The overlay's colour choice: own keyframes in the keyframe colour, other agents' in theirs
// or not at all.
TEST(OverlayKeyframes, OwnAndOtherAgentsKeyframesAreDrawnApart) {
  std::vector<client::ReplicaKeyframe> keyframes(3);
  for (int i = 0; i < 3; ++i) {
    keyframes[i].id = i;
    keyframes[i].world_from_camera =
        Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(double(i), 0, 0));
  }
  keyframes[1].own = false;
  const KeyframeGroups shown = GroupKeyframes(keyframes, /*show_others=*/true);
  ASSERT_EQ(shown.own.size(), 2u);
  ASSERT_EQ(shown.others.size(), 1u);
  EXPECT_DOUBLE_EQ(shown.own[0].translation().x(), 0.0);
  EXPECT_DOUBLE_EQ(shown.own[1].translation().x(), 2.0);
  EXPECT_DOUBLE_EQ(shown.others[0].translation().x(), 1.0);
  const KeyframeGroups hidden = GroupKeyframes(keyframes, /*show_others=*/false);
  EXPECT_EQ(hidden.own.size(), 2u);
  EXPECT_TRUE(hidden.others.empty());
  // The two groups go to colours that differ.
  const MapRendererOptions colours;
  EXPECT_NE(colours.keyframe_color, colours.other_keyframe_color);
  EXPECT_TRUE(client::ReplicaKeyframe().own);  // a replica's keyframes are its own by default
}

}  // namespace
}  // namespace m2s::xr
