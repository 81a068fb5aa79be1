#include "m2s/render/offscreen_target.h"

#include <algorithm>
#include <cstring>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace m2s {

Expected<std::unique_ptr<OffscreenTarget>> OffscreenTarget::Create(int width, int height) {
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_size);
  if (width <= 0 || height <= 0 || width > max_size || height > max_size) {
    return Status::Error("OffscreenTarget: size " + std::to_string(width) + "x" +
                         std::to_string(height) + " must be in [1, " + std::to_string(max_size) +
                         "] (GL_MAX_RENDERBUFFER_SIZE; is a GL context current?)");
  }
  std::unique_ptr<OffscreenTarget> target(new OffscreenTarget());
  target->width_ = width;
  target->height_ = height;
  target->color_ = MakeGlRenderbuffer();
  target->depth_ = MakeGlRenderbuffer();
  target->framebuffer_ = MakeGlFramebuffer();
  glBindRenderbuffer(GL_RENDERBUFFER, target->color_.id());
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  glBindRenderbuffer(GL_RENDERBUFFER, target->depth_.id());
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, width, height);
  glBindRenderbuffer(GL_RENDERBUFFER, 0);
  GLint previous = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &previous);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, target->framebuffer_.id());
  glFramebufferRenderbuffer(GL_DRAW_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER,
                            target->color_.id());
  glFramebufferRenderbuffer(GL_DRAW_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                            target->depth_.id());
  const GLenum status = glCheckFramebufferStatus(GL_DRAW_FRAMEBUFFER);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, static_cast<GLuint>(previous));
  if (status != GL_FRAMEBUFFER_COMPLETE) {
    return Status::Error("OffscreenTarget: framebuffer incomplete (status " +
                         std::to_string(status) + ")");
  }
  if (Status s = CheckGlError("OffscreenTarget::Create"); !s) return s;
  return target;
}

void OffscreenTarget::Bind() const {
  glBindFramebuffer(GL_FRAMEBUFFER, framebuffer_.id());
  glViewport(0, 0, width_, height_);
}

Status OffscreenTarget::ReadPixels(RgbaImage* image) const {
  image->width = width_;
  image->height = height_;
  image->pixels.resize(static_cast<size_t>(width_) * height_ * 4);
  GLint previous = 0;
  glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &previous);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, framebuffer_.id());
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, image->pixels.data());
  glBindFramebuffer(GL_READ_FRAMEBUFFER, static_cast<GLuint>(previous));
  // GL's row 0 is the bottom one.
  const size_t row = static_cast<size_t>(width_) * 4;
  for (int y = 0; y < height_ / 2; ++y) {
    std::swap_ranges(image->pixels.begin() + y * row, image->pixels.begin() + (y + 1) * row,
                     image->pixels.begin() + (height_ - 1 - y) * row);
  }
  return CheckGlError("OffscreenTarget::ReadPixels");
}

Expected<RgbaImage> OffscreenTarget::ReadPixels() const {
  RgbaImage image;
  if (Status s = ReadPixels(&image); !s) return s;
  return image;
}

Status WritePng(const std::string& path, const RgbaImage& image) {
  if (image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != static_cast<size_t>(image.width) * image.height * 4) {
    return Status::Error("WritePng: image size and pixel count do not match");
  }
  const cv::Mat rgba(image.height, image.width, CV_8UC4, const_cast<uint8_t*>(image.pixels.data()));
  cv::Mat bgra;
  cv::cvtColor(rgba, bgra, cv::COLOR_RGBA2BGRA);
  bool ok = false;
  try {
    ok = cv::imwrite(path, bgra);
  } catch (const cv::Exception& e) {
    return Status::Error("WritePng: cannot write " + path + ": " + e.what());
  }
  if (!ok) return Status::Error("WritePng: cannot write " + path);
  return Status::Ok();
}

Expected<RgbaImage> ReadPng(const std::string& path) {
  const cv::Mat bgra = cv::imread(path, cv::IMREAD_UNCHANGED);
  if (bgra.empty()) return Expected<RgbaImage>::Error("ReadPng: cannot read " + path);
  cv::Mat rgba;
  switch (bgra.channels()) {
    case 1:
      cv::cvtColor(bgra, rgba, cv::COLOR_GRAY2RGBA);
      break;
    case 3:
      cv::cvtColor(bgra, rgba, cv::COLOR_BGR2RGBA);
      break;
    case 4:
      cv::cvtColor(bgra, rgba, cv::COLOR_BGRA2RGBA);
      break;
    default:
      return Expected<RgbaImage>::Error("ReadPng: unsupported channel count in " + path);
  }
  if (rgba.depth() != CV_8U)
    return Expected<RgbaImage>::Error("ReadPng: not an 8-bit image: " + path);
  RgbaImage image;
  image.width = rgba.cols;
  image.height = rgba.rows;
  image.pixels.resize(static_cast<size_t>(image.width) * image.height * 4);
  for (int y = 0; y < image.height; ++y) {
    std::memcpy(&image.pixels[static_cast<size_t>(y) * image.width * 4], rgba.ptr(y),
                static_cast<size_t>(image.width) * 4);
  }
  return image;
}

}  // namespace m2s
