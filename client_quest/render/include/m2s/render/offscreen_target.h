// OffscreenTarget: a framebuffer object with an RGBA8 colour and a 24-bit depth attachment of
// a given size, to render headless (map.png of the headless client, tests) and read back.
// RgbaImage and WritePng/ReadPng: plain pixels with the top row first, PNG through OpenCV.
//
// Needs a current GLES 3.0+ context for Create(), Bind() and ReadPixels(); destroy it with
// that context current. Not thread-safe.
//
//   auto target = OffscreenTarget::Create(1280, 720);
//   (*target)->Bind();                       // framebuffer + viewport
//   renderer->Draw(view, projection);
//   Expected<RgbaImage> image = (*target)->ReadPixels();
//   Status s = WritePng("map.png", *image);
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "m2s/common/status.h"
#include "m2s/gpu/gl_util.h"

namespace m2s {

// 8-bit RGBA pixels, row-major, the image's top row first.
struct RgbaImage {
  int width = 0;
  int height = 0;
  std::vector<uint8_t> pixels;  // width * height * 4

  const uint8_t* at(int x, int y) const {
    return &pixels[(static_cast<size_t>(y) * width + x) * 4];
  }
};

class OffscreenTarget {
 public:
  // Error when the size is not positive or above GL_MAX_RENDERBUFFER_SIZE, or the framebuffer
  // is incomplete.
  static Expected<std::unique_ptr<OffscreenTarget>> Create(int width, int height);

  // Binds the framebuffer for drawing and sets the viewport to the whole target.
  void Bind() const;
  // Reads the colour attachment (waits for rendering to finish), flipping rows so the image's
  // top row comes first. Restores the read framebuffer binding.
  Expected<RgbaImage> ReadPixels() const;
  Status ReadPixels(RgbaImage* image) const;

  int width() const { return width_; }
  int height() const { return height_; }
  GLuint framebuffer() const { return framebuffer_.id(); }

 private:
  OffscreenTarget() = default;
  int width_ = 0;
  int height_ = 0;
  GlFramebuffer framebuffer_;
  GlRenderbuffer color_, depth_;
};

// Writes an RGBA image as PNG (alpha kept). Clear error when the image is inconsistent or the
// file cannot be written.
Status WritePng(const std::string& path, const RgbaImage& image);
// Reads a PNG (or any format OpenCV decodes) into RGBA.
Expected<RgbaImage> ReadPng(const std::string& path);

}  // namespace m2s
