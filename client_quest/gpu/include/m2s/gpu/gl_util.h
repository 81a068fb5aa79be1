// Small GLES helpers shared by the projector and the renderer: owning handles for GL objects,
// shader compilation with the driver's log in the error, and glGetError as a Status.
// All functions need a current GLES 3.1+ context (see gl_context.h); handles must be destroyed
// with that context current (or after it is gone, in which case GL already freed them).
//
//   Expected<GlProgram> program = CompileProgram({{GL_COMPUTE_SHADER, source}});
//   if (!program) return program.status();
//   glUseProgram(program->id());
#pragma once

#include <GLES3/gl32.h>

#include <initializer_list>
#include <string>
#include <utility>

#include "m2s/common/status.h"

namespace m2s {

// Owns one GL object name; Deleter is a function deleting `count` names.
template <void (*Deleter)(GLuint)>
class GlHandle {
 public:
  GlHandle() = default;
  explicit GlHandle(GLuint id) : id_(id) {}
  ~GlHandle() { Reset(); }
  GlHandle(GlHandle&& other) noexcept : id_(std::exchange(other.id_, 0)) {}
  GlHandle& operator=(GlHandle&& other) noexcept {
    if (this != &other) {
      Reset();
      id_ = std::exchange(other.id_, 0);
    }
    return *this;
  }
  GlHandle(const GlHandle&) = delete;
  GlHandle& operator=(const GlHandle&) = delete;

  GLuint id() const { return id_; }
  explicit operator bool() const { return id_ != 0; }
  void Reset() {
    if (id_ != 0) Deleter(id_);
    id_ = 0;
  }

 private:
  GLuint id_ = 0;
};

namespace internal {
void DeleteGlProgram(GLuint id);
void DeleteGlBuffer(GLuint id);
void DeleteGlTexture(GLuint id);
void DeleteGlFramebuffer(GLuint id);
void DeleteGlRenderbuffer(GLuint id);
void DeleteGlVertexArray(GLuint id);
}  // namespace internal

using GlProgram = GlHandle<&internal::DeleteGlProgram>;
using GlBuffer = GlHandle<&internal::DeleteGlBuffer>;
using GlTexture = GlHandle<&internal::DeleteGlTexture>;
using GlFramebuffer = GlHandle<&internal::DeleteGlFramebuffer>;
using GlRenderbuffer = GlHandle<&internal::DeleteGlRenderbuffer>;
using GlVertexArray = GlHandle<&internal::DeleteGlVertexArray>;

GlBuffer MakeGlBuffer();
GlTexture MakeGlTexture();
GlFramebuffer MakeGlFramebuffer();
GlRenderbuffer MakeGlRenderbuffer();
GlVertexArray MakeGlVertexArray();

struct ShaderSource {
  GLenum stage;  // GL_COMPUTE_SHADER, GL_VERTEX_SHADER, GL_FRAGMENT_SHADER
  std::string source;
};

// Compiles and links the stages into a program; the error carries the driver's info log.
Expected<GlProgram> CompileProgram(std::initializer_list<ShaderSource> stages);

// OK when glGetError() reports nothing; otherwise "<where>: GL error 0x...." (all pending
// errors are drained).
Status CheckGlError(const char* where);

}  // namespace m2s
