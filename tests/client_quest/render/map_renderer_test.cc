// MapRenderer and OffscreenTarget on llvmpipe: known geometry lands on known pixels.
#include "m2s/render/map_renderer.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <set>

#include "m2s/common/scene.h"
#include "m2s/gpu/gl_context.h"
#include "m2s/render/offscreen_target.h"

namespace m2s {
namespace {

constexpr int kWidth = 640, kHeight = 480;

std::array<int, 4> Rgba(const Eigen::Vector4f& c) {
  return {int(std::lround(c[0] * 255)), int(std::lround(c[1] * 255)), int(std::lround(c[2] * 255)),
          int(std::lround(c[3] * 255))};
}

bool PixelIs(const RgbaImage& image, int x, int y, const Eigen::Vector4f& color) {
  const uint8_t* p = image.at(x, y);
  const auto want = Rgba(color);
  for (int k = 0; k < 4; ++k) {
    if (std::abs(int(p[k]) - want[k]) > 1) return false;
  }
  return true;
}

// True when some pixel of the (2r+1)^2 neighbourhood has the colour.
bool NearPixelIs(const RgbaImage& image, int x, int y, int r, const Eigen::Vector4f& color) {
  for (int yy = y - r; yy <= y + r; ++yy)
    for (int xx = x - r; xx <= x + r; ++xx)
      if (xx >= 0 && yy >= 0 && xx < image.width && yy < image.height &&
          PixelIs(image, xx, yy, color))
        return true;
  return false;
}

class MapRendererTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!GlContext::AnyEglDisplayAvailable()) GTEST_SKIP() << "no EGL display on this machine";
    auto context = GlContext::CreateHeadless();
    ASSERT_TRUE(context) << context.error();
    context_ = std::move(*context);
    auto target = OffscreenTarget::Create(kWidth, kHeight);
    ASSERT_TRUE(target) << target.error();
    target_ = std::move(*target);
    camera_.width = kWidth;
    camera_.height = kHeight;  // fx = fy = 500, cx = 320, cy = 240
  }

  RgbaImage Render(MapRenderer& renderer, const Pose3& viewpoint) {
    target_->Bind();
    EXPECT_TRUE(
        renderer.Draw(MapRenderer::ViewMatrix(viewpoint), camera_.GlProjection().cast<float>()));
    auto image = target_->ReadPixels();
    EXPECT_TRUE(image) << image.error();
    return image ? *image : RgbaImage{};
  }

  std::unique_ptr<GlContext> context_;
  std::unique_ptr<OffscreenTarget> target_;
  Camera camera_;
};

TEST_F(MapRendererTest, PointLandsOnItsProjectedPixel) {
  MapRendererOptions options;
  options.point_size_px = 5;
  auto renderer = MapRenderer::Create(options);
  ASSERT_TRUE(renderer) << renderer.error();
  // Camera at the origin looking along +z: (0.5, -0.25, 2) projects to u = 445, v = 177.5.
  (*renderer)->SetMapPoints({{0.5f, -0.25f, 2.f}, {0.f, 0.f, -2.f}});
  const RgbaImage image = Render(**renderer, Pose3::Identity());
  ASSERT_EQ(image.width, kWidth);
  EXPECT_TRUE(PixelIs(image, 445, 177, options.point_color));
  EXPECT_TRUE(PixelIs(image, 444, 178, options.point_color));
  // Five pixels wide and round: two pixels off on both axes is background.
  EXPECT_TRUE(PixelIs(image, 448, 177, options.background));
  EXPECT_TRUE(PixelIs(image, 445, 181, options.background));
  // The point behind the camera is not drawn anywhere: count point-coloured pixels.
  int count = 0;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) count += PixelIs(image, x, y, options.point_color);
  EXPECT_GE(count, 12);
  EXPECT_LE(count, 25);
}

TEST_F(MapRendererTest, FrustumLinesCrossExpectedPixels) {
  MapRendererOptions options;
  options.frustum_depth_m = 0.5;
  auto renderer = MapRenderer::Create(options);
  ASSERT_TRUE(renderer) << renderer.error();
  (*renderer)->SetFrustumCamera(camera_);
  // A keyframe 2 m ahead looking the same way: its image rectangle at 0.5 m is the box
  // x in [-0.32, 0.32], y in [-0.24, 0.24] at z = 2.5, seen at u in [256, 384], v in [192, 288].
  (*renderer)->SetKeyframes({Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 2))});
  // The estimate 1 m to the right of it: rectangle edges at u = 384 + 200 = 584 (right edge).
  (*renderer)->SetEstimatedPose(Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 0, 2)));
  (*renderer)->SetGroundTruthPose(Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(-1, 0, 2)));
  const RgbaImage image = Render(**renderer, Pose3::Identity());
  EXPECT_TRUE(NearPixelIs(image, 384, 240, 1, options.keyframe_color));  // right edge
  EXPECT_TRUE(NearPixelIs(image, 256, 240, 1, options.keyframe_color));  // left edge
  EXPECT_TRUE(NearPixelIs(image, 320, 192, 1, options.keyframe_color));  // top edge
  EXPECT_TRUE(NearPixelIs(image, 584, 240, 1, options.estimate_color));
  EXPECT_TRUE(NearPixelIs(image, 56, 240, 1, options.ground_truth_color));
  EXPECT_TRUE(NearPixelIs(image, 320, 240, 1, options.keyframe_color));  // the apex
  EXPECT_TRUE(PixelIs(image, 320, 200, options.background));  // inside, between the lines
}

TEST_F(MapRendererTest, OtherAgentsKeyframesHaveTheirOwnColour) {
  MapRendererOptions options;
  options.frustum_depth_m = 0.5;
  ASSERT_NE(Rgba(options.keyframe_color), Rgba(options.other_keyframe_color));
  auto renderer = MapRenderer::Create(options);
  ASSERT_TRUE(renderer) << renderer.error();
  (*renderer)->SetFrustumCamera(camera_);
  // As above: this agent's keyframe 2 m ahead, another agent's 1 m to the right of it.
  (*renderer)->SetKeyframes({Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, 2))});
  (*renderer)->SetOtherKeyframes({Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 0, 2))});
  RgbaImage image = Render(**renderer, Pose3::Identity());
  EXPECT_TRUE(NearPixelIs(image, 384, 240, 1, options.keyframe_color));
  EXPECT_FALSE(NearPixelIs(image, 384, 240, 1, options.other_keyframe_color));
  EXPECT_TRUE(NearPixelIs(image, 584, 240, 1, options.other_keyframe_color));
  EXPECT_FALSE(NearPixelIs(image, 584, 240, 1, options.keyframe_color));
  (*renderer)->SetOtherKeyframes({});
  image = Render(**renderer, Pose3::Identity());
  EXPECT_TRUE(PixelIs(image, 584, 240, options.background));
}

TEST_F(MapRendererTest, ShadedAndWireframeMesh) {
  // A quad 3 m ahead spanning x, y in [-1, 1]: u, v in [153.3, 486.7] x [73.3, 406.7].
  const std::vector<Eigen::Vector3f> positions = {{-1, -1, 3}, {1, -1, 3}, {1, 1, 3}, {-1, 1, 3}};
  const std::vector<uint32_t> triangles = {0, 1, 2, 0, 2, 3};
  MapRendererOptions options;
  auto shaded = MapRenderer::Create(options);
  ASSERT_TRUE(shaded) << shaded.error();
  ASSERT_TRUE((*shaded)->SetMesh(positions, triangles));
  (*shaded)->SetMapPoints({{0.f, 0.5f, 3.f}});  // on the surface: the polygon offset shows it
  RgbaImage image = Render(**shaded, Pose3::Identity());
  EXPECT_TRUE(PixelIs(image, 100, 240, options.background));
  const uint8_t* centre = image.at(250, 300);
  EXPECT_FALSE(PixelIs(image, 250, 300, options.background));
  EXPECT_GT(centre[0], 60);  // lit grey, facing the camera
  EXPECT_NEAR(centre[0], centre[1], 3);
  EXPECT_TRUE(PixelIs(image, 320, 323, options.point_color));  // v = 240 + 500 * 0.5 / 3

  options.mesh_style = MapRendererOptions::MeshStyle::kWireframe;
  auto wire = MapRenderer::Create(options);
  ASSERT_TRUE(wire) << wire.error();
  ASSERT_TRUE((*wire)->SetMesh(positions, triangles));
  image = Render(**wire, Pose3::Identity());
  EXPECT_TRUE(NearPixelIs(image, 487, 240, 1, options.wireframe_color));  // right edge
  EXPECT_TRUE(NearPixelIs(image, 320, 240, 1, options.wireframe_color));  // the diagonal
  EXPECT_TRUE(PixelIs(image, 400, 150, options.background));              // off the edges
}

TEST_F(MapRendererTest, PngRoundTrip) {
  auto renderer = MapRenderer::Create(MapRendererOptions{});
  ASSERT_TRUE(renderer);
  (*renderer)->SetMapPoints({{0.f, 0.f, 1.f}});
  const RgbaImage image = Render(**renderer, Pose3::Identity());
  const std::string path =
      (std::filesystem::temp_directory_path() / "m2s_map_renderer_test.png").string();
  ASSERT_TRUE(WritePng(path, image));
  auto read = ReadPng(path);
  ASSERT_TRUE(read) << read.error();
  EXPECT_EQ(read->width, image.width);
  EXPECT_EQ(read->height, image.height);
  EXPECT_EQ(read->pixels, image.pixels);
  std::filesystem::remove(path);
  EXPECT_FALSE(WritePng("/nonexistent-dir/x.png", image));
  EXPECT_FALSE(ReadPng("/nonexistent-dir/x.png"));
}

TEST_F(MapRendererTest, DefaultSceneOverviewLooksLikeARoom) {
  // What the headless client's map.png shows: the room from a corner, shaded, with a few
  // "map points" (every 50th vertex) and keyframes along a line.
  const Scene scene = MakeDefaultScene();
  MapRendererOptions options;
  options.frustum_depth_m = 0.25;
  auto renderer = MapRenderer::Create(options);
  ASSERT_TRUE(renderer) << renderer.error();
  ASSERT_TRUE((*renderer)->SetMesh(scene.positions, scene.triangles));
  std::vector<Eigen::Vector3f> points;
  for (size_t i = 0; i < scene.positions.size(); i += 50) points.push_back(scene.positions[i]);
  (*renderer)->SetMapPoints(points);
  std::vector<Pose3> keyframes;
  for (int k = 0; k < 6; ++k) {
    const Eigen::Vector3d eye(-1.5 + 0.6 * k, 0.0, 1.6);
    const Eigen::Matrix3d r =
        Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
    keyframes.emplace_back(r, eye);  // looking along +y, image y down = world -z
  }
  (*renderer)->SetKeyframes(keyframes);
  (*renderer)->SetFrustumCamera(camera_);
  const Eigen::Vector3d eye(-2.8, -2.3, 2.5), target(0.5, 0.5, 0.6);
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  Eigen::Matrix3d r;
  r << x, z.cross(x), z;
  const RgbaImage image = Render(**renderer, Pose3(r, eye));
  int background = 0, points_drawn = 0, keyframe_pixels = 0;
  std::set<int> greys;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      background += PixelIs(image, x, y, options.background);
      points_drawn += PixelIs(image, x, y, options.point_color);
      keyframe_pixels += PixelIs(image, x, y, options.keyframe_color);
      greys.insert(image.at(x, y)[0] / 8);
    }
  EXPECT_LT(background, kWidth * kHeight / 20) << "inside the room, walls fill the view";
  EXPECT_GT(points_drawn, 500);
  EXPECT_GT(keyframe_pixels, 100);
  EXPECT_GT(greys.size(), 8u) << "shading should separate the faces";
  if (const char* dir = std::getenv("M2S_TEST_OUTPUT_DIR")) {
    EXPECT_TRUE(WritePng(std::string(dir) + "/map_renderer_overview.png", image));
  }
}

TEST_F(MapRendererTest, RejectsBadInput) {
  MapRendererOptions options;
  options.point_size_px = 0;
  EXPECT_FALSE(MapRenderer::Create(options));
  auto renderer = MapRenderer::Create(MapRendererOptions{});
  ASSERT_TRUE(renderer);
  EXPECT_FALSE((*renderer)->SetMesh({{0, 0, 0}}, {0, 0, 1}));
  EXPECT_FALSE((*renderer)->SetMesh({{0, 0, 0}}, {0, 0}));
  EXPECT_FALSE(OffscreenTarget::Create(0, 10));
}

}  // namespace
}  // namespace m2s
