// The GL 3.3 core functions the renderer uses (fetched through the context: no libGL linked), and
// its shader programs.
#pragma once

#include "flatland/render/gl_context.hpp"

// Prototypes only, for decltype: every function is fetched from the context at run time.
#define GL_GLEXT_PROTOTYPES 1
#include <GL/gl.h>
#include <GL/glext.h>
#include <opencv2/core.hpp>

#include <stdexcept>
#include <string>

namespace flatland::render {

// The GL 3.3 core functions the renderer uses, fetched through the context (no libGL linked).
#define FLATLAND_GL_FUNCTIONS(X) \
  X(glClear)                     \
  X(glClearColor)                \
  X(glEnable)                    \
  X(glDisable)                   \
  X(glFrontFace)                 \
  X(glPolygonOffset)             \
  X(glViewport)                  \
  X(glReadPixels)                \
  X(glPixelStorei)               \
  X(glGetError)                  \
  X(glFinish)                    \
  X(glDrawArrays)                \
  X(glGenTextures)               \
  X(glBindTexture)               \
  X(glTexImage2D)                \
  X(glTexParameteri)             \
  X(glDeleteTextures)            \
  X(glActiveTexture)             \
  X(glGenerateMipmap)            \
  X(glGenFramebuffers)           \
  X(glBindFramebuffer)           \
  X(glFramebufferRenderbuffer)   \
  X(glCheckFramebufferStatus)    \
  X(glDeleteFramebuffers)        \
  X(glGenRenderbuffers)          \
  X(glBindRenderbuffer)          \
  X(glRenderbufferStorage)       \
  X(glDeleteRenderbuffers)       \
  X(glGenBuffers)                \
  X(glBindBuffer)                \
  X(glBufferData)                \
  X(glDeleteBuffers)             \
  X(glGenVertexArrays)           \
  X(glBindVertexArray)           \
  X(glDeleteVertexArrays)        \
  X(glEnableVertexAttribArray)   \
  X(glVertexAttribPointer)       \
  X(glCreateShader)              \
  X(glShaderSource)              \
  X(glCompileShader)             \
  X(glGetShaderiv)               \
  X(glGetShaderInfoLog)          \
  X(glDeleteShader)              \
  X(glCreateProgram)             \
  X(glAttachShader)              \
  X(glLinkProgram)               \
  X(glGetProgramiv)              \
  X(glGetProgramInfoLog)         \
  X(glUseProgram)                \
  X(glDeleteProgram)             \
  X(glGetUniformLocation)        \
  X(glUniformMatrix4fv)          \
  X(glUniform3f)                 \
  X(glUniform1f)                 \
  X(glUniform2f)                 \
  X(glUniform1i)                 \
  X(glBlitFramebuffer)           \
  X(glBlendFunc)                 \
  X(glStencilFunc)               \
  X(glStencilOp)                 \
  X(glDepthMask)                 \
  X(glScissor)

struct Gl {
#define FLATLAND_GL_MEMBER(name) decltype(&::name) name = nullptr;
  FLATLAND_GL_FUNCTIONS(FLATLAND_GL_MEMBER)
#undef FLATLAND_GL_MEMBER
  explicit Gl(const GlContext& c) {
#define FLATLAND_GL_LOAD(name)                                        \
  name = reinterpret_cast<decltype(&::name)>(c.proc_address(#name));  \
  if (!name)                                                          \
    throw std::runtime_error("GL backend " + to_string(c.backend()) + \
                             ": no " #name " (OpenGL 3.3 core required)");
    FLATLAND_GL_FUNCTIONS(FLATLAND_GL_LOAD)
#undef FLATLAND_GL_LOAD
  }
};

// Shading: Lambert plus an optional Blinn-Phong highlight (the brushed aluminium hand) under one
// directional light, evaluated per vertex. Every face is planar, so Lambert shading is exact per
// vertex, and the fragment stage only passes the colour on: llvmpipe runs a fragment shader for
// every pixel, and a lit or textured one there costs several times the whole frame budget.
extern const char* const kVertexShader;
extern const char* const kPlainFragmentShader;
// The disk's top face: face, O-ring band and marker evaluated per fragment.
extern const char* const kDiskFragmentShader;
// The segmentation mask's flat ids.
extern const char* const kMaskFragmentShader;
// Only ChArUco boards (their marker bits) need a texture.
extern const char* const kTexturedFragmentShader;

constexpr double kAmbient = 0.35;
const cv::Vec3d kLight =
    cv::normalize(cv::Vec3d(0.25, 0.35, 1.0));  // table frame, towards the light

/// A compiled shader; std::runtime_error with the compiler's log when it does not compile.
unsigned compile_shader(const Gl& gl, unsigned type, const char* source);
/// `vertex_source` linked with `fragment_source`; std::runtime_error when it does not link.
unsigned link_program(const Gl& gl, const char* fragment_source,
                      const char* vertex_source = kVertexShader);

}  // namespace flatland::render
