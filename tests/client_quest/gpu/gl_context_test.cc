#include "m2s/gpu/gl_context.h"

#include <EGL/egl.h>
#include <GLES3/gl31.h>
#include <gtest/gtest.h>

#include "gpu_test_util.h"

namespace m2s {
namespace {

TEST(GlContextTest, CreatesHeadlessGles31) {
  M2S_SKIP_WITHOUT_EGL();
  auto context = GlContext::CreateHeadless();
  ASSERT_TRUE(context) << context.error();
  GlContext& c = **context;
  EXPECT_TRUE(c.owned());
  EXPECT_TRUE(c.IsCurrent());
  EXPECT_FALSE(c.renderer().empty());
  EXPECT_FALSE(c.vendor().empty());
  EXPECT_EQ(c.version().rfind("OpenGL ES", 0), 0u) << c.version();
  EXPECT_TRUE(c.major_version() > 3 || (c.major_version() == 3 && c.minor_version() >= 1));
  EXPECT_NE(c.egl_display(), nullptr);
  EXPECT_NE(c.egl_context(), nullptr);
  EXPECT_FALSE(c.HasExtension("GL_M2S_no_such_extension"));
  // A compute-capable context reports a non-zero work group limit.
  GLint max_invocations = 0;
  glGetIntegerv(GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS, &max_invocations);
  EXPECT_GE(max_invocations, 128);
}

TEST(GlContextTest, ReleaseAndMakeCurrent) {
  M2S_SKIP_WITHOUT_EGL();
  auto context = GlContext::CreateHeadless();
  ASSERT_TRUE(context) << context.error();
  ASSERT_TRUE((*context)->ReleaseCurrent());
  EXPECT_FALSE((*context)->IsCurrent());
  EXPECT_EQ(eglGetCurrentContext(), EGL_NO_CONTEXT);
  ASSERT_TRUE((*context)->MakeCurrent());
  EXPECT_TRUE((*context)->IsCurrent());
}

TEST(GlContextTest, TwoContextsSwitch) {
  M2S_SKIP_WITHOUT_EGL();
  auto a = GlContext::CreateHeadless();
  auto b = GlContext::CreateHeadless();
  ASSERT_TRUE(a && b);
  EXPECT_TRUE((*b)->IsCurrent());
  ASSERT_TRUE((*a)->MakeCurrent());
  EXPECT_TRUE((*a)->IsCurrent());
  EXPECT_FALSE((*b)->IsCurrent());
}

TEST(GlContextTest, AdoptsTheCurrentContextWithoutOwningIt) {
  M2S_SKIP_WITHOUT_EGL();
  auto host = GlContext::CreateHeadless();
  ASSERT_TRUE(host) << host.error();
  {
    auto adopted = GlContext::Adopt();
    ASSERT_TRUE(adopted) << adopted.error();
    EXPECT_FALSE((*adopted)->owned());
    EXPECT_EQ((*adopted)->platform(), "adopted");
    EXPECT_EQ((*adopted)->egl_context(), (*host)->egl_context());
    EXPECT_EQ((*adopted)->renderer(), (*host)->renderer());
  }
  // Destroying the adopted wrapper leaves the host's context alive and current.
  EXPECT_TRUE((*host)->IsCurrent());
  EXPECT_NE(glGetString(GL_VERSION), nullptr);
}

TEST(GlContextTest, AdoptWithoutCurrentContextFails) {
  M2S_SKIP_WITHOUT_EGL();
  auto host = GlContext::CreateHeadless();
  ASSERT_TRUE(host);
  ASSERT_TRUE((*host)->ReleaseCurrent());
  auto adopted = GlContext::Adopt();
  ASSERT_FALSE(adopted);
  EXPECT_NE(adopted.error().find("no EGL context is current"), std::string::npos)
      << adopted.error();
}

TEST(GlContextTest, UnavailableVersionIsAClearError) {
  M2S_SKIP_WITHOUT_EGL();
  GlContext::Options options;
  options.min_major = 9;  // no such GLES
  auto context = GlContext::CreateHeadless(options);
  ASSERT_FALSE(context);
  EXPECT_NE(context.error().find("GLES 9"), std::string::npos) << context.error();
}

}  // namespace
}  // namespace m2s
