#include "map_image.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "m2s/gpu/gl_context.h"
#include "m2s/render/map_renderer.h"
#include "m2s/render/offscreen_target.h"

namespace m2s::reporting {
namespace {

constexpr int kWidth = 1280;
constexpr int kHeight = 720;
constexpr double kViewFovDeg = 100.0;

Camera ViewCamera() { return Camera::FromHorizontalFov(kWidth, kHeight, kViewFovDeg, 0.05, 100.0); }

Status RenderWithGl(const std::string& path, const MapImageInput& input, const Pose3& view) {
  auto context = GlContext::CreateHeadless();
  if (!context) return context.status();
  auto target = OffscreenTarget::Create(kWidth, kHeight);
  if (!target) return target.status();
  MapRendererOptions options;
  options.point_size_px = 3.f;
  options.frustum_depth_m = 0.15;
  auto renderer = MapRenderer::Create(options);
  if (!renderer) return renderer.status();
  if (Status s = (*renderer)->SetMesh(input.scene->positions, input.scene->triangles); !s) {
    return s;
  }
  std::vector<Eigen::Vector3f> points;
  points.reserve(input.points.size());
  for (const auto& p : input.points) points.push_back(p.cast<float>());
  (*renderer)->SetMapPoints(points);
  (*renderer)->SetKeyframes(input.keyframes);
  (*renderer)->SetFrustumCamera(input.camera);
  (*renderer)->SetGroundTruthPose(input.ground_truth_last);
  (*target)->Bind();
  const Eigen::Matrix4f projection = ViewCamera().GlProjection().cast<float>();
  if (Status s = (*renderer)->Draw(MapRenderer::ViewMatrix(view), projection); !s) return s;
  auto image = (*target)->ReadPixels();
  if (!image) return image.status();
  Status written = WritePng(path, *image);
  renderer->reset();
  target->reset();
  return written;
}

Status RenderWithOpenCv(const std::string& path, const MapImageInput& input, const Pose3& view) {
  const Camera camera = ViewCamera();
  const Pose3 camera_from_world = view.Inverse();
  cv::Mat image(kHeight, kWidth, CV_8UC3, cv::Scalar(26, 20, 20));
  auto draw = [&](const Eigen::Vector3d& world, const cv::Scalar& color, int radius) {
    const Eigen::Vector3d p = camera_from_world * world;
    if (p.z() < camera.near) return;
    const Eigen::Vector2d uv = camera.Project(p);
    if (!camera.InImage(uv.x(), uv.y())) return;
    cv::circle(image, cv::Point(static_cast<int>(uv.x()), static_cast<int>(uv.y())), radius, color,
               cv::FILLED);
  };
  for (const auto& v : input.scene->positions) draw(v.cast<double>(), cv::Scalar(150, 150, 150), 0);
  for (const auto& p : input.points) draw(p, cv::Scalar(40, 40, 255), 1);
  for (const auto& k : input.keyframes) draw(k.translation(), cv::Scalar(255, 115, 50), 3);
  try {
    if (!cv::imwrite(path, image)) return Status::Error("cannot write " + path);
  } catch (const cv::Exception& e) {
    return Status::Error("cannot write " + path + ": " + e.what());
  }
  return Status::Ok();
}

}  // namespace

Pose3 MapViewpoint(const Scene& scene) {
  Eigen::AlignedBox3d box;
  for (const auto& p : scene.positions) box.extend(p.cast<double>());
  if (box.isEmpty()) return Pose3();
  const Eigen::Vector3d size = box.sizes();
  const Eigen::Vector3d centre = box.center();
  const Eigen::Vector3d eye =
      centre + Eigen::Vector3d(-0.42 * size.x(), -0.42 * size.y(), 0.4 * size.z());
  const Eigen::Vector3d target = centre - Eigen::Vector3d(0, 0, 0.25 * size.z());
  const Eigen::Vector3d forward = (target - eye).normalized();
  Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ());
  if (right.norm() < 1e-6) right = Eigen::Vector3d::UnitX();
  right.normalize();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d rotation;
  rotation << right, down, forward;
  return Pose3(rotation, eye);
}

Status WriteMapPng(const std::string& path, const MapImageInput& input) {
  if (!input.scene) return Status::Error("no scene to draw");
  const Pose3 view = MapViewpoint(*input.scene);
  if (GlContext::AnyEglDisplayAvailable()) {
    Status rendered = RenderWithGl(path, input, view);
    if (rendered) return rendered;
  }
  return RenderWithOpenCv(path, input, view);
}

}  // namespace m2s::reporting
