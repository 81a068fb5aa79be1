// Parsing of the scripted controls of the XR client.
#include <gtest/gtest.h>

#include "m2s/xr/xr_client.h"

namespace m2s::xr {
namespace {

TEST(ControlEvents, ParsesNamesAndFrames) {
  auto events = ParseControlEvents("reset@200,overlay@5,quit@0");
  ASSERT_TRUE(events.ok()) << events.error();
  ASSERT_EQ(events->size(), 3u);
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

}  // namespace
}  // namespace m2s::xr
