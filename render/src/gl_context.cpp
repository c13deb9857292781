#include "flatland/render/gl_context.hpp"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/gl.h>
#include <GL/osmesa.h>
#include <dlfcn.h>

#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::render {

GlBackend parse_backend(const std::string& name) {
  if (name == "osmesa") return GlBackend::kOsmesa;
  if (name == "egl") return GlBackend::kEgl;
  throw std::invalid_argument("render.backend: unknown GL backend '" + name +
                              "' (expected osmesa or egl)");
}

std::string to_string(GlBackend b) { return b == GlBackend::kOsmesa ? "osmesa" : "egl"; }

namespace {

// `override_variable` names an environment variable that replaces the search list with one path
// (a custom Mesa build, or a test of the error path).
void* open_library(std::vector<const char*> names, const char* override_variable,
                   const std::string& what) {
  if (const char* path = std::getenv(override_variable); path && *path) names = {path};
  std::string errors;
  for (const char* n : names) {
    if (void* h = dlopen(n, RTLD_NOW | RTLD_LOCAL)) return h;
    errors += std::string(errors.empty() ? "" : "; ") + dlerror();
  }
  throw std::runtime_error(what + " (" + errors + ")");
}

template <class F>
F symbol(void* lib, const char* name, const std::string& backend) {
  void* p = dlsym(lib, name);
  if (!p) throw std::runtime_error("GL backend " + backend + ": missing symbol " + name);
  return reinterpret_cast<F>(p);
}

std::string describe(const GlContext& context) {
  using GetString = const GLubyte* (*)(GLenum);
  auto gs = reinterpret_cast<GetString>(context.proc_address("glGetString"));
  if (!gs) return "unknown";
  auto str = [&](GLenum e) {
    const GLubyte* s = gs(e);
    return s ? std::string(reinterpret_cast<const char*>(s)) : std::string("?");
  };
  return str(GL_RENDERER) + " | " + str(GL_VERSION);
}

// ---------------------------------------------------------------------------------------------
// OSMesa: Mesa's off-screen software context (llvmpipe). Rendering goes to framebuffer objects,
// so the context's own buffer is a 1x1 placeholder that MakeCurrent requires.
class OsmesaContext final : public GlContext {
 public:
  OsmesaContext() {
    lib_ = open_library({"libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so"},
                        "FLATLAND_OSMESA_LIBRARY",
                        "GL backend osmesa: cannot load libOSMesa (install the Debian package "
                        "libosmesa6; OSMesa was removed from Mesa >= 25.1, use --gl egl there)");
    using CreateAttribs = OSMesaContext (*)(const int*, OSMesaContext);
    create_ = symbol<CreateAttribs>(lib_, "OSMesaCreateContextAttribs", "osmesa");
    make_current_ = symbol<MakeCurrent>(lib_, "OSMesaMakeCurrent", "osmesa");
    destroy_ = symbol<Destroy>(lib_, "OSMesaDestroyContext", "osmesa");
    get_proc_ = symbol<GetProc>(lib_, "OSMesaGetProcAddress", "osmesa");
    const int attribs[] = {OSMESA_FORMAT,
                           OSMESA_BGRA,
                           OSMESA_DEPTH_BITS,
                           24,
                           OSMESA_PROFILE,
                           OSMESA_CORE_PROFILE,
                           OSMESA_CONTEXT_MAJOR_VERSION,
                           3,
                           OSMESA_CONTEXT_MINOR_VERSION,
                           3,
                           0};
    ctx_ = create_(attribs, nullptr);
    if (!ctx_)
      throw std::runtime_error(
          "GL backend osmesa: OSMesaCreateContextAttribs failed (no OpenGL 3.3 core context)");
    make_current();
  }
  ~OsmesaContext() override {
    if (ctx_) destroy_(ctx_);
    // The library stays loaded: llvmpipe's threads may outlive the context briefly.
  }
  void make_current() override {
    if (!make_current_(ctx_, placeholder_, GL_UNSIGNED_BYTE, 1, 1))
      throw std::runtime_error("GL backend osmesa: OSMesaMakeCurrent failed");
  }
  void* proc_address(const char* name) const override {
    return reinterpret_cast<void*>(get_proc_(name));
  }
  GlBackend backend() const override { return GlBackend::kOsmesa; }
  std::string description() const override { return describe(*this); }

 private:
  using MakeCurrent = GLboolean (*)(OSMesaContext, void*, GLenum, GLsizei, GLsizei);
  using Destroy = void (*)(OSMesaContext);
  using GetProc = OSMESAproc (*)(const char*);
  void* lib_ = nullptr;
  OSMesaContext (*create_)(const int*, OSMesaContext) = nullptr;
  MakeCurrent make_current_ = nullptr;
  Destroy destroy_ = nullptr;
  GetProc get_proc_ = nullptr;
  OSMesaContext ctx_ = nullptr;
  unsigned char placeholder_[4] = {0, 0, 0, 0};
};

// ---------------------------------------------------------------------------------------------
// EGL on Mesa's surfaceless platform: no display, no window, no GPU needed (llvmpipe).
class EglContext final : public GlContext {
 public:
  EglContext() {
    lib_ = open_library({"libEGL.so.1", "libEGL.so"}, "FLATLAND_EGL_LIBRARY",
                        "GL backend egl: cannot load libEGL (install the Debian packages libegl1 "
                        "and libegl-mesa0)");
    get_proc_ = symbol<GetProc>(lib_, "eglGetProcAddress", "egl");
    auto initialize =
        symbol<EGLBoolean (*)(EGLDisplay, EGLint*, EGLint*)>(lib_, "eglInitialize", "egl");
    auto bind_api = symbol<EGLBoolean (*)(EGLenum)>(lib_, "eglBindAPI", "egl");
    auto choose = symbol<EGLBoolean (*)(EGLDisplay, const EGLint*, EGLConfig*, EGLint, EGLint*)>(
        lib_, "eglChooseConfig", "egl");
    auto create = symbol<EGLContext (*)(EGLDisplay, EGLConfig, EGLContext, const EGLint*)>(
        lib_, "eglCreateContext", "egl");
    make_current_ = symbol<MakeCurrent>(lib_, "eglMakeCurrent", "egl");
    destroy_ = symbol<EGLBoolean (*)(EGLDisplay, EGLContext)>(lib_, "eglDestroyContext", "egl");
    auto get_platform_display =
        reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(get_proc_("eglGetPlatformDisplayEXT"));
    if (!get_platform_display)
      throw std::runtime_error("GL backend egl: eglGetPlatformDisplayEXT is not available");
    display_ = get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    EGLint major = 0, minor = 0;
    if (display_ == EGL_NO_DISPLAY || !initialize(display_, &major, &minor))
      throw std::runtime_error(
          "GL backend egl: cannot initialise Mesa's surfaceless platform (install the Debian "
          "package libegl-mesa0)");
    if (!bind_api(EGL_OPENGL_API))
      throw std::runtime_error("GL backend egl: eglBindAPI(EGL_OPENGL_API) failed");
    const EGLint config_attribs[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE,
                                     EGL_OPENGL_BIT, EGL_NONE};
    EGLConfig config = nullptr;
    EGLint count = 0;
    choose(display_, config_attribs, &config, 1, &count);
    const EGLint context_attribs[] = {EGL_CONTEXT_MAJOR_VERSION,
                                      3,
                                      EGL_CONTEXT_MINOR_VERSION,
                                      3,
                                      EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                      EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT,
                                      EGL_NONE};
    ctx_ = create(display_, count > 0 ? config : nullptr, EGL_NO_CONTEXT, context_attribs);
    if (ctx_ == EGL_NO_CONTEXT)
      throw std::runtime_error("GL backend egl: eglCreateContext failed (no OpenGL 3.3 core)");
    make_current();
  }
  ~EglContext() override {
    if (ctx_ != EGL_NO_CONTEXT) {
      make_current_(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
      destroy_(display_, ctx_);
    }
  }
  void make_current() override {
    if (!make_current_(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx_))
      throw std::runtime_error("GL backend egl: eglMakeCurrent failed");
  }
  void* proc_address(const char* name) const override {
    return reinterpret_cast<void*>(get_proc_(name));
  }
  GlBackend backend() const override { return GlBackend::kEgl; }
  std::string description() const override { return describe(*this); }

 private:
  using GetProc = __eglMustCastToProperFunctionPointerType (*)(const char*);
  using MakeCurrent = EGLBoolean (*)(EGLDisplay, EGLSurface, EGLSurface, EGLContext);
  void* lib_ = nullptr;
  GetProc get_proc_ = nullptr;
  MakeCurrent make_current_ = nullptr;
  EGLBoolean (*destroy_)(EGLDisplay, EGLContext) = nullptr;
  EGLDisplay display_ = EGL_NO_DISPLAY;
  EGLContext ctx_ = EGL_NO_CONTEXT;
};

}  // namespace

std::unique_ptr<GlContext> create_context(GlBackend backend) {
  if (backend == GlBackend::kOsmesa) return std::make_unique<OsmesaContext>();
  return std::make_unique<EglContext>();
}

}  // namespace flatland::render
