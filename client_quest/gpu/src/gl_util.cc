#include "m2s/gpu/gl_util.h"

#include <cstdio>
#include <vector>

namespace m2s {
namespace internal {
void DeleteGlProgram(GLuint id) { glDeleteProgram(id); }
void DeleteGlBuffer(GLuint id) { glDeleteBuffers(1, &id); }
void DeleteGlTexture(GLuint id) { glDeleteTextures(1, &id); }
void DeleteGlFramebuffer(GLuint id) { glDeleteFramebuffers(1, &id); }
void DeleteGlRenderbuffer(GLuint id) { glDeleteRenderbuffers(1, &id); }
void DeleteGlVertexArray(GLuint id) { glDeleteVertexArrays(1, &id); }
}  // namespace internal

GlBuffer MakeGlBuffer() {
  GLuint id = 0;
  glGenBuffers(1, &id);
  return GlBuffer(id);
}
GlTexture MakeGlTexture() {
  GLuint id = 0;
  glGenTextures(1, &id);
  return GlTexture(id);
}
GlFramebuffer MakeGlFramebuffer() {
  GLuint id = 0;
  glGenFramebuffers(1, &id);
  return GlFramebuffer(id);
}
GlRenderbuffer MakeGlRenderbuffer() {
  GLuint id = 0;
  glGenRenderbuffers(1, &id);
  return GlRenderbuffer(id);
}
GlVertexArray MakeGlVertexArray() {
  GLuint id = 0;
  glGenVertexArrays(1, &id);
  return GlVertexArray(id);
}

namespace {

const char* StageName(GLenum stage) {
  switch (stage) {
    case GL_COMPUTE_SHADER:
      return "compute";
    case GL_VERTEX_SHADER:
      return "vertex";
    case GL_FRAGMENT_SHADER:
      return "fragment";
    default:
      return "unknown";
  }
}

std::string ShaderLog(GLuint shader) {
  GLint length = 0;
  glGetShaderiv(shader, GL_INFO_LOG_LENGTH, &length);
  std::vector<char> log(static_cast<size_t>(length > 0 ? length : 1), '\0');
  glGetShaderInfoLog(shader, static_cast<GLsizei>(log.size()), nullptr, log.data());
  return log.data();
}

std::string ProgramLog(GLuint program) {
  GLint length = 0;
  glGetProgramiv(program, GL_INFO_LOG_LENGTH, &length);
  std::vector<char> log(static_cast<size_t>(length > 0 ? length : 1), '\0');
  glGetProgramInfoLog(program, static_cast<GLsizei>(log.size()), nullptr, log.data());
  return log.data();
}

}  // namespace

Expected<GlProgram> CompileProgram(std::initializer_list<ShaderSource> stages) {
  GlProgram program(glCreateProgram());
  if (!program) return Expected<GlProgram>::Error("glCreateProgram failed (no current context?)");
  std::vector<GLuint> shaders;
  auto cleanup = [&shaders] {
    for (GLuint s : shaders) glDeleteShader(s);
  };
  for (const ShaderSource& stage : stages) {
    const GLuint shader = glCreateShader(stage.stage);
    shaders.push_back(shader);
    const char* text = stage.source.c_str();
    glShaderSource(shader, 1, &text, nullptr);
    glCompileShader(shader);
    GLint ok = GL_FALSE;
    glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
    if (ok != GL_TRUE) {
      const std::string log = ShaderLog(shader);
      cleanup();
      return Expected<GlProgram>::Error(std::string(StageName(stage.stage)) +
                                        " shader failed to compile: " + log);
    }
    glAttachShader(program.id(), shader);
  }
  glLinkProgram(program.id());
  cleanup();  // shaders stay alive while attached; flagged for deletion now
  GLint ok = GL_FALSE;
  glGetProgramiv(program.id(), GL_LINK_STATUS, &ok);
  if (ok != GL_TRUE)
    return Expected<GlProgram>::Error("program failed to link: " + ProgramLog(program.id()));
  return program;
}

Status CheckGlError(const char* where) {
  GLenum first = glGetError();
  if (first == GL_NO_ERROR) return Status::Ok();
  for (int i = 0; i < 16 && glGetError() != GL_NO_ERROR; ++i) {
  }
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), ": GL error 0x%04x", static_cast<unsigned>(first));
  return Status::Error(std::string(where) + buffer);
}

}  // namespace m2s
