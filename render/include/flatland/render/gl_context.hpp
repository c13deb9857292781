// Headless OpenGL contexts. Both backends are loaded at run time (dlopen) and every GL function
// is fetched through the backend's GetProcAddress, so no libGL/libOpenGL stub can shadow OSMesa
// and a missing backend is an error naming its Debian package, not a link failure.
#pragma once

#include <memory>
#include <string>

namespace flatland::render {

enum class GlBackend { kOsmesa, kEgl };
GlBackend parse_backend(const std::string& name);  ///< "osmesa" | "egl"; invalid_argument otherwise
std::string to_string(GlBackend b);

/// One context, current on the creating thread (one context per thread).
class GlContext {
 public:
  virtual ~GlContext() = default;
  virtual void make_current() = 0;
  virtual void* proc_address(const char* name) const = 0;
  virtual GlBackend backend() const = 0;
  /// GL_RENDERER and GL_VERSION, e.g. "llvmpipe (LLVM 15.0.6, 256 bits) | 4.5 Mesa 22.3.6".
  virtual std::string description() const = 0;
};

/// Create a context (OpenGL >= 3.3) for offscreen rendering into framebuffer objects. Throws
/// std::runtime_error naming the backend that failed and the Debian package that provides it
/// (libosmesa6 for OSMesa, libegl1 + libegl-mesa0 for EGL).
std::unique_ptr<GlContext> create_context(GlBackend backend);

}  // namespace flatland::render
