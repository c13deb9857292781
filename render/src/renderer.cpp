#include "flatland/render/renderer.hpp"

#include "flatland/camera/board.hpp"
#include "flatland/render/distortion_maps.hpp"
#include "flatland/sim/curve.hpp"

#include "gl_programs.hpp"
#include "lighting.hpp"
#include "meshes.hpp"

#include <opencv2/aruco/charuco.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

namespace flatland::render {

namespace {

constexpr double kRingWidth = 0.08;    // O-ring seen from above, fraction of the radius
constexpr double kMarkerOffset = 0.5;  // marker centre from the disk centre, fraction of radius
constexpr double kMarkerRadius = 0.12;

}  // namespace

SceneState SceneState::from_spatial_sample(const sim::SpatialSample& s,
                                           const sim::HandPose3& hand) {
  SceneState st;
  st.t = s.t;
  SpatialPose pose;
  const Eigen::Matrix3d Ro = s.state.orientation.normalized().toRotationMatrix();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      pose.hand_rotation(r, c) = hand.rotation(r, c);
      pose.object_rotation(r, c) = Ro(r, c);
    }
    pose.hand_position[r] = hand.position[r];
    pose.object_position[r] = s.state.position[r];
  }
  st.spatial = pose;
  return st;
}

SceneState SceneState::from_sample(const sim::Sample& s) {
  SceneState st;
  st.t = s.t;
  st.hand_angle = s.theta;
  st.disk_center = {s.object_position.x(), s.object_position.y()};
  st.disk_angle = s.object_angle;
  st.s_h = s.s_h;
  st.force_normal_ratio = s.fn_ratio;
  st.force_tangential_ratio = s.ft_ratio;
  st.mode = s.mode;
  return st;
}

// ---------------------------------------------------------------------------------------------
struct Renderer::Impl {
  struct Drawable {
    unsigned vao = 0, vbo = 0, texture = 0;
    int count = 0;
    cv::Matx44d model = cv::Matx44d::eye();
    bool behind = false;  // drawn with a polygon offset: coplanar geometry drawn later wins
    unsigned char id = kMaskBackground;  // the segmentation mask's id (MaskId)
  };
  // What a GL pass draws: the image, or the segmentation mask's flat ids.
  enum class Pass { kImage, kMask };
  // A rolling readout's band of sensor rows [v0, v1), read at t + time_offset, and the rows of
  // the ideal (supersampled, undistorted) image its pixels are made from.
  struct Band {
    int v0 = 0, v1 = 0;
    double time_offset = 0;  // s
    int ideal_r0 = 0, ideal_r1 = 0;
  };

  using StateAt = Renderer::StateAt;
  RenderSetup setup;
  camera::CameraModel& camera = setup.camera;
  DistortionMaps maps;
  int supersample = 1;
  double disk_radius = 0;    // m, the object's outline as the camera sees it (a ball's R)
  double hole_radius = 0;    // m, a ring's hole
  double marker_offset = 0;  // marker centre from the object's centre, fraction of its radius
  std::unique_ptr<GlContext> context;
  std::unique_ptr<Gl> gl;
  unsigned program = 0, textured_program = 0, disk_program = 0, fbo = 0, color_rb = 0, depth_rb = 0;
  // The scene's lamp (setup.lighting): its programs, and the lit table with its boards, drawn once
  // into a framebuffer of its own (neither moves) and copied into each frame.
  std::unique_ptr<LitPrograms> lit;
  unsigned background_fbo = 0, background_color_rb = 0, background_depth_rb = 0;
  int fbo_width = 0, fbo_height = 0;
  Drawable table, hand, hand_walls, disk, disk_top;
  Drawable spatial_hand, spatial_object;  // a spatial scene's bodies
  std::vector<Drawable> targets;
  bool textured_targets = false;
  bool table_fills_view = false;
  struct Locations {
    int model, specular;
  };
  std::map<unsigned, Locations> locations;  // per program
  cv::Vec3f table_color;
  EffectsRng rng;
  cv::Mat readback;  // CV_8UC4 (RGBA), reused
  // render_linear's intermediates at the supersampled size, capture's sub-frame and its float
  // image before quantisation: reused.
  cv::Mat ideal_bgr, ideal_f32, distorted_f32, subframe, linear_scratch;
  cv::Mat downsampled_rgba;  // render_8u's supersampled readback averaged down, reused
  // render_8u's frames, each reused once nothing else holds it (a closed loop lets go of a frame
  // once it is tracked). A fresh 640 x 480 frame costs 225 page faults wherever malloc hands large
  // blocks back to the system (AddressSanitizer's allocator always; the Python module's, measured:
  // 0.8 ms more per frame).
  std::array<cv::Mat, 4> frame_pool;
  std::size_t frame_pool_next = 0;
  // The readout (setup.readout): interlaced fields, or a rolling shutter's bands of rows.
  bool interlaced = false, rolling = false;
  double line_time = 0;     // s, a rolling readout's time from one row to the next
  std::vector<Band> bands;  // a rolling readout's, top to bottom
  cv::Mat second_field, band_subframe,
      band_distorted;  // interlaced: the second field's image; blur's sub-frame
  // The mask: its program (built at the first mask), its ideal image of ids, and where each
  // sensor pixel's centre lies in it (empty when the ideal image is the sensor's: no
  // supersampling, no distortion).
  unsigned mask_program = 0;
  int mask_id_location = -1, mask_round_location = -1, mask_model_location = -1;
  cv::Mat ideal_ids, mask_map_x, mask_map_y;

  Impl(const RenderSetup& given, GlBackend backend) : setup(given), rng(given.effects.seed) {
    const RenderSetup& s = setup;
    supersample = s.effects.supersample;
    if (supersample < 1 || supersample > 8)
      throw std::invalid_argument("effects.supersample: must be between 1 and 8");
    if (!s.spatial && !s.object.round())
      throw std::invalid_argument(
          "object.type: ellipse: the renderer draws disks, rings and balls");
    if (!s.spatial) {
      // A ball is drawn as its equatorial disk seen from above (radius R, the face's texture),
      // not a shaded sphere; a ring as the annulus of its face.
      disk_radius = s.object.seen_radius();
      if (s.object.kind == sim::ObjectSpec::Kind::kRing) hole_radius = s.object.inner_radius;
      // The marker on the face between the hole and the O-ring band.
      marker_offset = std::max(kMarkerOffset, 0.5 * (hole_radius / disk_radius + 1.0 - kRingWidth));
    }
    maps = make_distortion_maps(camera, supersample);
    fbo_width = maps.ideal_width;
    fbo_height = maps.ideal_height;
    context = create_context(backend);
    gl = std::make_unique<Gl>(*context);
    build_program();
    build_framebuffer();
    if (s.spatial) {
      if (!s.spatial->hand || !s.spatial->object)
        throw std::invalid_argument("render: a spatial scene needs its hand and object surfaces");
      constexpr int kHandQuads = 96, kBodyQuads = 48;
      spatial_hand = upload(
          surface_mesh(*s.spatial->hand, drawn_range(*s.spatial->hand, s.spatial->hand_extent),
                       kHandQuads, kHandQuads, kAluminium, 12, kAluminium * 0.8f));
      // The whole object: every longitude, the latitudes up to its poles.
      const double half_pi = std::numbers::pi / 2;
      spatial_object = upload(surface_mesh(
          *s.spatial->object, {{-std::numbers::pi, -half_pi}, {std::numbers::pi, half_pi}},
          kBodyQuads, kBodyQuads / 2, kBall, 8, kBallCell));
    }
    table = upload(table_mesh(s.render.table_extent));
    if (s.hand) {
      const Mesh plate = hand_mesh(*s.hand, s.render.hand_thickness, s.render.table_extent);
      hand = upload(plate);
      // Under a lamp, the walls alone cast the hand's shadow (draw_shadows).
      if (s.lighting) hand_walls = upload(walls_of(plate));
    }
    disk = upload(disk_side_mesh(disk_radius, s.render.disk_thickness, hole_radius));
    disk_top = upload(disk_top_quad(disk_radius, s.render.disk_thickness));
    table.id = kMaskTable;
    hand.id = kMaskHand;
    disk.id = disk_top.id = kMaskDisk;
    upload_boards();
    readback.create(fbo_height, fbo_width, CV_8UC4);
    const float shade = static_cast<float>(kAmbient + (1.0 - kAmbient) * std::max(kLight[2], 0.0));
    table_color = kTable * shade;
    table_fills_view = view_inside_table(s.render.table_extent);
    // The camera and the light never change: their uniforms are set once, and each frame only
    // uploads the moving parts' model matrices (llvmpipe re-validates state on every change).
    for (unsigned p : {program, textured_program, disk_program}) set_frame_uniforms(p);
    for (unsigned p : {program, textured_program, disk_program})
      locations[p] = {gl->glGetUniformLocation(p, "model"),
                      gl->glGetUniformLocation(p, "specular")};
    if (s.lighting) build_lighting(*s.lighting);
    build_readout(s.readout);
  }

  // setup.boards as drawables (a chessboard is two: its background and its squares).
  void upload_boards() {
    for (std::size_t i = 0; i < setup.boards.size(); ++i) {
      const std::size_t first = targets.size();
      targets.push_back(make_target(setup.boards[i]));
      // Beyond kMaxMaskBoards render_mask refuses; the id only has to fit.
      const auto id = static_cast<unsigned char>(std::min<std::size_t>(kMaskFirstBoard + i, 255));
      for (std::size_t j = first; j < targets.size(); ++j) targets[j].id = id;
    }
    textured_targets = false;
    for (const Drawable& t : targets) textured_targets = textured_targets || t.texture != 0;
  }

  void set_boards(std::vector<camera::PlacedBoard> boards) {
    // A board the scene file could not name is refused before anything changes.
    for (std::size_t i = 0; i < boards.size(); ++i) {
      const std::string field = "boards[" + std::to_string(i) + "]";
      camera::Board::parse(boards[i].board.notation(), field);
      if (!cv::checkRange(boards[i].position) || !cv::checkRange(boards[i].rotation))
        throw std::invalid_argument(field + ": position and rotation must be finite");
    }
    context->make_current();
    for (Drawable& d : targets) release(d);
    targets.clear();
    setup.boards = std::move(boards);
    upload_boards();
    if (lit) draw_lit_background();
  }

  // The readout's fields or bands. The scene's rules (camera_problem) are checked again here for
  // a setup put together by hand.
  void build_readout(const ReadoutSpec& readout) {
    CameraSpec spec;
    spec.height = camera.height;
    spec.fps = camera.fps;
    spec.exposure = camera.exposure;
    spec.readout = readout;
    if (auto problem = camera_problem(spec))
      throw std::invalid_argument("camera." + problem->field + ": " + problem->reason);
    if (readout.global()) return;
    if (setup.spatial)
      throw std::invalid_argument("camera.readout: a spatial scene's frames are read globally");
    interlaced = readout.mode == "interlaced";
    rolling = readout.mode == "rolling";
    if (!rolling) return;
    line_time = readout.time / camera.height;
    for (int v0 = 0; v0 < camera.height; v0 += readout.band_rows) {
      Band b;
      b.v0 = v0;
      b.v1 = std::min(v0 + readout.band_rows, camera.height);
      b.time_offset = 0.5 * (b.v0 + b.v1 - 1) * line_time;
      if (camera.distorted()) {
        std::tie(b.ideal_r0, b.ideal_r1) =
            ideal_rows_read(maps.map_y.rowRange(b.v0 * supersample, b.v1 * supersample));
      } else {
        b.ideal_r0 = b.v0 * supersample;
        b.ideal_r1 = b.v1 * supersample;
      }
      bands.push_back(b);
    }
  }

  // The rows [r0, r1) of the ideal image that a remap through these rows of a map of row
  // coordinates reads (bilinear: the row below each coordinate and the next; one more each side
  // for the fixed-point rounding of the coordinates).
  std::pair<int, int> ideal_rows_read(const cv::Mat& map_rows) const {
    double lo = 0, hi = 0;
    cv::minMaxLoc(map_rows, &lo, &hi);
    const int r0 = static_cast<int>(std::floor(lo)) - 1, r1 = static_cast<int>(std::floor(hi)) + 3;
    // At least one row, for GL, where every coordinate lies outside the image.
    const int first = std::clamp(r0, 0, fbo_height - 1);
    return {first, std::clamp(r1, first + 1, fbo_height)};
  }

  void build_lighting(const LightingSpec& lighting) {
    if (setup.spatial)
      throw std::invalid_argument("lighting: a spatial scene is drawn without a lamp");
    if (auto problem = lighting_problem(lighting, setup.render))
      throw std::invalid_argument("lighting." + problem->field + ": " + problem->reason);
    lit = std::make_unique<LitPrograms>(*gl, lighting, to_gl(rigid(camera.R, camera.t)),
                                        to_gl(projection()), camera.position_in_table(), kTable);
    set_disk_top_uniforms(lit->program(LitPrograms::Kind::kDiskTop));
    make_framebuffer(background_fbo, background_color_rb, background_depth_rb);
    draw_lit_background();
  }

  // Whether every ray through the ideal image's corners meets the table plane inside the table.
  bool view_inside_table(double extent) const {
    const cv::Vec3d c = camera.position_in_table();
    const cv::Matx33d Kinv = maps.ideal_K.inv();
    for (double u : {-0.5, fbo_width - 0.5})
      for (double v : {-0.5, fbo_height - 0.5}) {
        const cv::Vec3d d = camera.R.t() * (Kinv * cv::Vec3d(u, v, 1));
        if (!(d[2] < 0)) return false;
        const double lambda = -c[2] / d[2];
        const cv::Vec3d p = c + lambda * d;
        if (std::abs(p[0]) > extent || std::abs(p[1]) > extent) return false;
      }
    return true;
  }

  ~Impl() {
    if (!gl) return;
    context->make_current();
    for (Drawable* d :
         {&table, &hand, &hand_walls, &disk, &disk_top, &spatial_hand, &spatial_object})
      release(*d);
    for (Drawable& d : targets) release(d);
    gl->glDeleteFramebuffers(1, &fbo);
    gl->glDeleteRenderbuffers(1, &color_rb);
    gl->glDeleteRenderbuffers(1, &depth_rb);
    if (lit) {
      lit.reset();
      gl->glDeleteFramebuffers(1, &background_fbo);
      gl->glDeleteRenderbuffers(1, &background_color_rb);
      gl->glDeleteRenderbuffers(1, &background_depth_rb);
    }
    gl->glDeleteProgram(program);
    gl->glDeleteProgram(textured_program);
    gl->glDeleteProgram(disk_program);
    if (mask_program) gl->glDeleteProgram(mask_program);
  }

  void release(Drawable& d) {
    gl->glDeleteBuffers(1, &d.vbo);
    gl->glDeleteVertexArrays(1, &d.vao);
    if (d.texture) gl->glDeleteTextures(1, &d.texture);
  }

  void build_program() {
    program = link_program(*gl, kPlainFragmentShader);
    textured_program = link_program(*gl, kTexturedFragmentShader);
    disk_program = link_program(*gl, kDiskFragmentShader);
    set_disk_top_uniforms(disk_program);
  }

  // The disk's face, O-ring band and marker, for the unlit and the lit disk program alike.
  void set_disk_top_uniforms(unsigned p) {
    gl->glUseProgram(p);
    auto set3 = [&](const char* name, const cv::Vec3f& c) {
      gl->glUniform3f(gl->glGetUniformLocation(p, name), c[0], c[1], c[2]);
    };
    set3("face_color", kDiskFace);
    set3("ring_color", kRubber);
    set3("marker_color", kMarker);
    gl->glUniform1f(gl->glGetUniformLocation(p, "ring_inner"), float(1.0 - kRingWidth));
    gl->glUniform1f(gl->glGetUniformLocation(p, "marker_radius"), float(kMarkerRadius));
    gl->glUniform2f(gl->glGetUniformLocation(p, "marker_center"), float(marker_offset), 0.0f);
    gl->glUniform1f(gl->glGetUniformLocation(p, "hole"),
                    float(disk_radius > 0 ? hole_radius / disk_radius : 0.0));
  }

  void build_framebuffer() { make_framebuffer(fbo, color_rb, depth_rb); }

  // A framebuffer of the ideal image's size: RGBA colour, and depth; with a lamp, depth and a
  // stencil (each pixel of a shadow is darkened once).
  void make_framebuffer(unsigned& framebuffer, unsigned& color, unsigned& depth) {
    gl->glGenFramebuffers(1, &framebuffer);
    gl->glBindFramebuffer(GL_FRAMEBUFFER, framebuffer);
    gl->glGenRenderbuffers(1, &color);
    gl->glBindRenderbuffer(GL_RENDERBUFFER, color);
    gl->glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, fbo_width, fbo_height);
    gl->glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color);
    gl->glGenRenderbuffers(1, &depth);
    gl->glBindRenderbuffer(GL_RENDERBUFFER, depth);
    const bool stencil = setup.lighting.has_value();
    gl->glRenderbufferStorage(GL_RENDERBUFFER, stencil ? GL_DEPTH24_STENCIL8 : GL_DEPTH_COMPONENT24,
                              fbo_width, fbo_height);
    gl->glFramebufferRenderbuffer(GL_FRAMEBUFFER,
                                  stencil ? GL_DEPTH_STENCIL_ATTACHMENT : GL_DEPTH_ATTACHMENT,
                                  GL_RENDERBUFFER, depth);
    if (gl->glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      throw std::runtime_error("render: framebuffer " + std::to_string(fbo_width) + "x" +
                               std::to_string(fbo_height) + " is incomplete (too large?)");
  }

  Drawable upload(const Mesh& mesh) {
    Drawable d;
    gl->glGenVertexArrays(1, &d.vao);
    gl->glBindVertexArray(d.vao);
    gl->glGenBuffers(1, &d.vbo);
    gl->glBindBuffer(GL_ARRAY_BUFFER, d.vbo);
    gl->glBufferData(GL_ARRAY_BUFFER, static_cast<long>(mesh.size() * sizeof(Vertex)), mesh.data(),
                     GL_STATIC_DRAW);
    const int stride = sizeof(Vertex);
    gl->glEnableVertexAttribArray(0);
    gl->glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride,
                              reinterpret_cast<void*>(offsetof(Vertex, p)));
    gl->glEnableVertexAttribArray(1);
    gl->glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride,
                              reinterpret_cast<void*>(offsetof(Vertex, n)));
    gl->glEnableVertexAttribArray(2);
    gl->glVertexAttribPointer(2, 3, GL_FLOAT, GL_FALSE, stride,
                              reinterpret_cast<void*>(offsetof(Vertex, c)));
    gl->glEnableVertexAttribArray(3);
    gl->glVertexAttribPointer(3, 2, GL_FLOAT, GL_FALSE, stride,
                              reinterpret_cast<void*>(offsetof(Vertex, uv)));
    d.count = static_cast<int>(mesh.size());
    return d;
  }

  Drawable make_target(const camera::PlacedBoard& placed) {
    cv::Matx33d R;
    cv::Rodrigues(placed.rotation, R);
    const cv::Vec3d p = placed.position;
    const camera::Board& t = placed.board;
    if (t.kind == camera::Board::Kind::kChessboard) {
      Drawable back = upload(chessboard_background(t));
      back.model = rigid(R, p);
      back.behind = true;
      targets.push_back(back);
      Drawable squares = upload(chessboard_squares(t));
      squares.model = rigid(R, p);
      return squares;
    }
    // ChArUco: OpenCV draws the board (white margin of one square drawn by us as the quad's own
    // border is not needed: the board image covers exactly cols x rows squares).
    const int px_per_square = 40;
    const auto dict = cv::aruco::getPredefinedDictionary(
        cv::aruco::PREDEFINED_DICTIONARY_NAME(*camera::aruco_dictionary_id(t.dictionary)));
    const auto board = cv::aruco::CharucoBoard::create(
        t.squares_x, t.squares_y, static_cast<float>(t.square), static_cast<float>(t.marker), dict);
    cv::Mat image;
    board->draw(cv::Size(t.squares_x * px_per_square, t.squares_y * px_per_square), image, 0, 1);
    cv::Mat rgba;
    cv::cvtColor(image, rgba, cv::COLOR_GRAY2RGBA);
    Drawable d = upload(textured_quad(t.squares_x * t.square, t.squares_y * t.square));
    gl->glGenTextures(1, &d.texture);
    gl->glBindTexture(GL_TEXTURE_2D, d.texture);
    gl->glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    gl->glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, rgba.cols, rgba.rows, 0, GL_RGBA, GL_UNSIGNED_BYTE,
                     rgba.data);
    gl->glGenerateMipmap(GL_TEXTURE_2D);
    gl->glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
    gl->glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    gl->glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    gl->glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    d.model = rigid(R, p);
    return d;
  }

  // Projection of the ideal pinhole camera, OpenCV pixel convention (centres at integers), with
  // image row v mapped to window row v so that glReadPixels returns rows top-down.
  cv::Matx44d projection() const {
    const double W = fbo_width, H = fbo_height, n = 0.01, f = 50.0;
    const cv::Matx33d& K = maps.ideal_K;
    return {2 * K(0, 0) / W,
            0,
            (2 * K(0, 2) + 1) / W - 1,
            0,
            0,
            2 * K(1, 1) / H,
            (2 * K(1, 2) + 1) / H - 1,
            0,
            0,
            0,
            (f + n) / (f - n),
            -2 * f * n / (f - n),
            0,
            0,
            1,
            0};
  }

  // Uniforms fixed for the renderer's life (camera, light), set on each program.
  void set_frame_uniforms(unsigned p) {
    gl->glUseProgram(p);
    const cv::Matx44f view = to_gl(rigid(camera.R, camera.t));
    const cv::Matx44f proj = to_gl(projection());
    gl->glUniformMatrix4fv(gl->glGetUniformLocation(p, "view"), 1, GL_FALSE, view.val);
    gl->glUniformMatrix4fv(gl->glGetUniformLocation(p, "projection"), 1, GL_FALSE, proj.val);
    gl->glUniform3f(gl->glGetUniformLocation(p, "light_direction"), float(kLight[0]),
                    float(kLight[1]), float(kLight[2]));
    const cv::Vec3d eye = camera.position_in_table();
    gl->glUniform3f(gl->glGetUniformLocation(p, "eye"), float(eye[0]), float(eye[1]),
                    float(eye[2]));
    gl->glUniform1f(gl->glGetUniformLocation(p, "ambient"), float(kAmbient));
  }

  void draw(const Drawable& d, float specular = 0.0f, unsigned use_program = 0) {
    const unsigned p = use_program ? use_program : d.texture ? textured_program : program;
    gl->glUseProgram(p);
    const Locations& loc = locations.at(p);
    const cv::Matx44f m = to_gl(d.model);
    gl->glUniformMatrix4fv(loc.model, 1, GL_FALSE, m.val);
    gl->glUniform1f(loc.specular, specular);
    draw_with_current_program(d, p);
  }

  // The drawable's triangles with the program `p` in use (its uniforms set): its board texture
  // bound, pushed behind what shares its depth when it is a backing.
  void draw_with_current_program(const Drawable& d, unsigned p) {
    if (d.texture) {
      gl->glUniform1i(gl->glGetUniformLocation(p, "board"), 0);
      gl->glActiveTexture(GL_TEXTURE0);
      gl->glBindTexture(GL_TEXTURE_2D, d.texture);
    }
    if (d.behind) {
      gl->glEnable(GL_POLYGON_OFFSET_FILL);
      gl->glPolygonOffset(1.0f, 4.0f);
    }
    gl->glBindVertexArray(d.vao);
    gl->glDrawArrays(GL_TRIANGLES, 0, d.count);
    if (d.behind) gl->glDisable(GL_POLYGON_OFFSET_FILL);
  }

  // Render the ideal (undistorted, supersampled) image into `readback` (RGBA, top row first): its
  // rows [r0, r1) only (a scissored pass, the rest of `readback` left as it was), all by default.
  void render_ideal(const SceneState& st, Pass pass = Pass::kImage, int r0 = 0, int r1 = -1) {
    if (r1 < 0) r1 = fbo_height;
    const bool band = r0 > 0 || r1 < fbo_height;
    context->make_current();
    gl->glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    gl->glViewport(0, 0, fbo_width, fbo_height);
    gl->glEnable(GL_DEPTH_TEST);
    // The projection maps image rows top-down, which mirrors the window: counter-clockwise
    // triangles arrive clockwise.
    gl->glEnable(GL_CULL_FACE);
    gl->glFrontFace(GL_CW);
    // Where the table fills the whole view it is a uniformly lit plane: clearing to its colour
    // gives the same pixels as drawing it, without a full-screen fill.
    if (table_fills_view)
      gl->glClearColor(table_color[0], table_color[1], table_color[2], 1);
    else
      gl->glClearColor(0, 0, 0, 1);
    // Window row v is image row v (projection), so a band of image rows is a band of the window.
    if (band) {
      gl->glEnable(GL_SCISSOR_TEST);
      gl->glScissor(0, r0, fbo_width, r1 - r0);
    }
    if (pass == Pass::kMask) {
      draw_mask_scene(st);
    } else if (setup.spatial) {
      draw_spatial(st);
    } else if (lit) {
      draw_lit_table_scene(st);
    } else {
      draw_table_scene(st);
    }
    if (band) gl->glDisable(GL_SCISSOR_TEST);
    gl->glPixelStorei(GL_PACK_ALIGNMENT, 4);
    // RGBA is llvmpipe's fastest read format (BGRA and BGR go through slower paths).
    gl->glReadPixels(0, r0, fbo_width, r1 - r0, GL_RGBA, GL_UNSIGNED_BYTE, readback.ptr(r0));
  }

  // ---- the segmentation mask ----

  // Each body in its flat id, nearest sample (the framebuffer has one sample per pixel).
  void draw_mask_scene(const SceneState& st) {
    const float background = table_fills_view ? static_cast<float>(kMaskTable) / 255.0f : 0.0f;
    gl->glClearColor(background, 0, 0, 1);
    gl->glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    gl->glUseProgram(mask_program);
    if (!table_fills_view) draw_id(table);
    for (const Drawable& t : targets) draw_id(t);
    disk.model = rigid(rot_z(st.disk_angle), {st.disk_center.x, st.disk_center.y, 0});
    draw_id(disk);
    disk_top.model = disk.model;
    draw_id(disk_top, true);
    hand.model = rigid(rot_z(st.hand_angle), {0, 0, 0});
    draw_id(hand);
  }

  void draw_id(const Drawable& d, bool round_cut = false) {
    const cv::Matx44f m = to_gl(d.model);
    gl->glUniformMatrix4fv(mask_model_location, 1, GL_FALSE, m.val);
    gl->glUniform1f(mask_id_location, static_cast<float>(d.id));
    gl->glUniform1f(mask_round_location, round_cut ? 1.0f : 0.0f);
    draw_with_current_program(d, mask_program);
  }

  // The mask's program and maps, made at the first mask: renderers that never draw one pay
  // nothing.
  void prepare_mask() {
    if (setup.spatial)
      throw std::invalid_argument("render: a spatial scene has no segmentation mask");
    if (setup.boards.size() > static_cast<std::size_t>(kMaxMaskBoards))
      throw std::invalid_argument("targets: " + std::to_string(setup.boards.size()) +
                                  " boards; a mask's 8-bit ids tell at most " +
                                  std::to_string(kMaxMaskBoards) + " apart");
    if (mask_program) return;
    context->make_current();
    mask_program = link_program(*gl, kMaskFragmentShader);
    set_frame_uniforms(mask_program);
    mask_model_location = gl->glGetUniformLocation(mask_program, "model");
    mask_id_location = gl->glGetUniformLocation(mask_program, "object_id");
    mask_round_location = gl->glGetUniformLocation(mask_program, "round_cut");
    gl->glUniform1f(gl->glGetUniformLocation(mask_program, "hole"),
                    float(disk_radius > 0 ? hole_radius / disk_radius : 0.0));
    ideal_ids.create(fbo_height, fbo_width, CV_8UC1);
    if (!camera.distorted() && supersample == 1) return;
    // A sensor pixel's centre in the ideal image: the mean of its s x s samples' positions.
    if (camera.distorted()) {
      downsample(maps.map_x, supersample, mask_map_x);
      downsample(maps.map_y, supersample, mask_map_y);
      mask_map_x = mask_map_x.clone();  // factor 1 hands back the cached maps themselves
      mask_map_y = mask_map_y.clone();
      return;
    }
    mask_map_x.create(camera.height, camera.width, CV_32FC1);
    mask_map_y.create(camera.height, camera.width, CV_32FC1);
    const float centre = 0.5f * static_cast<float>(supersample - 1);
    for (int v = 0; v < camera.height; ++v)
      for (int u = 0; u < camera.width; ++u) {
        mask_map_x.at<float>(v, u) = static_cast<float>(u * supersample) + centre;
        mask_map_y.at<float>(v, u) = static_cast<float>(v * supersample) + centre;
      }
  }

  // Sensor rows [v0, v1) of `mask` (CV_8UC1, the camera's size): the ids of the state.
  void render_mask_rows(const SceneState& st, int v0, int v1, cv::Mat& mask) {
    prepare_mask();
    int r0 = v0, r1 = v1;
    if (!mask_map_y.empty()) std::tie(r0, r1) = ideal_rows_read(mask_map_y.rowRange(v0, v1));
    render_ideal(st, Pass::kMask, r0, r1);
    cv::Mat ids = ideal_ids.rowRange(r0, r1);
    cv::extractChannel(readback.rowRange(r0, r1), ids, 0);
    cv::Mat out = mask.rowRange(v0, v1);
    if (mask_map_y.empty()) {
      ids.copyTo(out);
      return;
    }
    cv::remap(ideal_ids, out, mask_map_x.rowRange(v0, v1), mask_map_y.rowRange(v0, v1),
              cv::INTER_NEAREST, cv::BORDER_CONSTANT, cv::Scalar(kMaskBackground));
  }

  cv::Mat render_mask(const SceneState& st) {
    cv::Mat mask(camera.height, camera.width, CV_8UC1);
    render_mask_rows(st, 0, camera.height, mask);
    return mask;
  }

  // A spatial scene: the hand's surface and the object at their poses, on a dark background.
  void draw_spatial(const SceneState& st) {
    if (!st.spatial) throw std::invalid_argument("render: a spatial scene's frame needs its poses");
    gl->glClearColor(kBackground[0], kBackground[1], kBackground[2], 1);
    gl->glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    spatial_hand.model = rigid(st.spatial->hand_rotation, st.spatial->hand_position);
    draw(spatial_hand, 0.25f);
    spatial_object.model = rigid(st.spatial->object_rotation, st.spatial->object_position);
    draw(spatial_object, 0.3f);
  }

  void draw_table_scene(const SceneState& st) {
    gl->glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    if (!table_fills_view) draw(table);
    for (const Drawable& t : targets) draw(t);
    disk.model = rigid(rot_z(st.disk_angle), {st.disk_center.x, st.disk_center.y, 0});
    draw(disk);
    disk_top.model = disk.model;
    draw(disk_top, 0.0f, disk_program);
    hand.model = rigid(rot_z(st.hand_angle), {0, 0, 0});
    draw(hand, 0.25f);  // brushed aluminium: a soft highlight
  }

  // ---- the scene's lamp ----

  void draw_lit(const Drawable& d, LitPrograms::Kind kind, const MaterialSpec& material) {
    lit->use(kind, to_gl(d.model), material);
    draw_with_current_program(d, lit->program(kind));
  }

  // The table and its boards under the lamp, once: they do not move. Every fragment is lit (the
  // lamp's light changes across the table), which costs llvmpipe a full-screen shader; copying
  // the result into each frame costs a memory copy.
  void draw_lit_background() {
    context->make_current();
    gl->glBindFramebuffer(GL_FRAMEBUFFER, background_fbo);
    gl->glViewport(0, 0, fbo_width, fbo_height);
    gl->glEnable(GL_DEPTH_TEST);
    gl->glEnable(GL_CULL_FACE);
    gl->glFrontFace(GL_CW);
    gl->glClearColor(0, 0, 0, 1);
    gl->glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT | GL_STENCIL_BUFFER_BIT);
    const LightingSpec& lighting = *setup.lighting;
    draw_lit(table, LitPrograms::Kind::kPlain, lighting.table);
    for (const Drawable& t : targets)
      draw_lit(t, t.texture ? LitPrograms::Kind::kTextured : LitPrograms::Kind::kPlain,
               lighting.table);
  }

  // A frame under the lamp: the lit table copied in (with its depth when boards lie on it, which
  // may hide the hand where they stand above it), the shadows, then the disk and the hand.
  void draw_lit_table_scene(const SceneState& st) {
    const LightingSpec& lighting = *setup.lighting;
    gl->glBindFramebuffer(GL_READ_FRAMEBUFFER, background_fbo);
    gl->glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo);
    const bool with_depth = !targets.empty();
    gl->glBlitFramebuffer(0, 0, fbo_width, fbo_height, 0, 0, fbo_width, fbo_height,
                          GL_COLOR_BUFFER_BIT | (with_depth ? GL_DEPTH_BUFFER_BIT : 0u),
                          GL_NEAREST);
    gl->glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    gl->glClear(GL_STENCIL_BUFFER_BIT | (with_depth ? 0u : GL_DEPTH_BUFFER_BIT));
    disk.model = rigid(rot_z(st.disk_angle), {st.disk_center.x, st.disk_center.y, 0});
    disk_top.model = disk.model;
    hand.model = hand_walls.model = rigid(rot_z(st.hand_angle), {0, 0, 0});
    if (lighting.shadows) draw_shadows(lighting);
    draw_lit(disk, LitPrograms::Kind::kPlain, lighting.band);  // the rubber wall
    draw_lit(disk_top, LitPrograms::Kind::kDiskTop, lighting.face);
    draw_lit(hand, LitPrograms::Kind::kPlain, lighting.hand);
  }

  // The hand and the disk flattened onto the table from the lamp (planar_shadow_matrix). The
  // table is a plane, so this shadow is exact (no shadow map's texels, bias or acne): a table
  // point is in shadow when the ray to the lamp passes through a body, that is when it lies in
  // the projection of the body's walls (a ray from outside a body into it crosses a wall; its own
  // footprint is hidden under it). Faces flip when flattened, so none is culled; the stencil
  // darkens each pixel once where the projections overlap. The tops are not drawn here: the
  // hand's would shade its whole flattened outline, mostly under the hand (measured: 0.9 ms of
  // the 640 x 480 frame's 2.4 ms), and the disk's is a square whose circle the fragment stage cuts
  // out; their walls already cast the whole shadows.
  void draw_shadows(const LightingSpec& lighting) {
    gl->glDepthMask(GL_FALSE);  // tested against the table and boards (LitPrograms' depth_lift)
    gl->glDisable(GL_CULL_FACE);
    gl->glEnable(GL_STENCIL_TEST);
    gl->glStencilFunc(GL_EQUAL, 0, 0xFF);
    gl->glStencilOp(GL_KEEP, GL_KEEP, GL_INCR);
    gl->glEnable(GL_BLEND);
    gl->glBlendFunc(GL_ZERO, GL_SRC_COLOR);
    draw_lit(hand_walls, LitPrograms::Kind::kShadow, lighting.table);
    draw_lit(disk, LitPrograms::Kind::kShadow, lighting.table);
    gl->glDisable(GL_BLEND);
    gl->glDisable(GL_STENCIL_TEST);
    gl->glEnable(GL_CULL_FACE);
    gl->glDepthMask(GL_TRUE);
  }

  // The geometric image: supersampled ideal render -> distortion remap -> area downsample.
  // The geometric image into `out`, reusing its memory when its size and type fit. The
  // supersampled intermediates are members and keep theirs too: fresh multi-megabyte buffers every
  // frame cost page faults (every allocation under AddressSanitizer, whose allocator maps each
  // large block anew, and any that glibc hands back to the system).
  void render_linear(const SceneState& st, cv::Mat& out) {
    render_ideal(st);
    cv::cvtColor(readback, ideal_bgr, cv::COLOR_RGBA2BGR);
    const bool distorted = camera.distorted();
    if (!distorted && supersample == 1) {
      ideal_bgr.convertTo(out, CV_32FC3);
      return;
    }
    ideal_bgr.convertTo(ideal_f32, CV_32FC3);
    if (!distorted) {
      downsample(ideal_f32, supersample, out);
      return;
    }
    cv::Mat& remapped = supersample == 1 ? out : distorted_f32;
    cv::remap(ideal_f32, remapped, maps.map_x, maps.map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    if (supersample > 1) downsample(distorted_f32, supersample, out);
  }

  cv::Mat render_linear(const SceneState& st) {
    cv::Mat out;
    render_linear(st, out);
    return out;
  }

  // A rolling band's sensor rows of the geometric image into `out` (CV_32FC3, the camera's size,
  // allocated): the same pixels as render_linear's rows, from a scissored pass over the ideal rows
  // they are made of.
  void render_linear_rows(const SceneState& st, const Band& b, cv::Mat& out) {
    render_ideal(st, Pass::kImage, b.ideal_r0, b.ideal_r1);
    ideal_bgr.create(fbo_height, fbo_width, CV_8UC3);
    cv::Mat bgr = ideal_bgr.rowRange(b.ideal_r0, b.ideal_r1);
    cv::cvtColor(readback.rowRange(b.ideal_r0, b.ideal_r1), bgr, cv::COLOR_RGBA2BGR);
    cv::Mat rows = out.rowRange(b.v0, b.v1);
    const bool distorted = camera.distorted();
    if (!distorted && supersample == 1) {
      bgr.convertTo(rows, CV_32FC3);
      return;
    }
    ideal_f32.create(fbo_height, fbo_width, CV_32FC3);
    cv::Mat f32 = ideal_f32.rowRange(b.ideal_r0, b.ideal_r1);
    bgr.convertTo(f32, CV_32FC3);
    if (!distorted) {
      downsample(f32, supersample, rows);
      return;
    }
    const int s0 = b.v0 * supersample, s1 = b.v1 * supersample;
    cv::Mat& remapped = supersample == 1 ? rows : band_distorted;
    cv::remap(ideal_f32, remapped, maps.map_x.rowRange(s0, s1), maps.map_y.rowRange(s0, s1),
              cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    if (supersample > 1) downsample(remapped, supersample, rows);
  }

  // A frame buffer of this size and type that no one but the pool holds (its reference count,
  // read atomically as OpenCV updates it), else a new one in the pool's next slot.
  cv::Mat pooled_frame(int rows, int cols, int type) {
    for (cv::Mat& m : frame_pool)
      if (m.u && CV_XADD(&m.u->refcount, 0) == 1 && m.rows == rows && m.cols == cols &&
          m.type() == type)
        return m;
    cv::Mat& slot = frame_pool[frame_pool_next];
    frame_pool_next = (frame_pool_next + 1) % frame_pool.size();
    slot.release();  // held elsewhere still: the holder keeps it, the slot takes a new buffer
    slot.create(rows, cols, type);
    return slot;
  }

  // Fast path for 8-bit frames without effects: no float conversion when nothing resamples.
  cv::Mat render_8u(const SceneState& st) {
    if (!camera.distorted()) {
      // Anti-aliasing by area averaging works as well on 8-bit samples (rounded once), and avoids
      // converting the supersampled image to float.
      // The returned frame is the only buffer written that is not the renderer's own scratch,
      // and it comes from the pool (pooled_frame).
      render_ideal(st);
      const cv::Mat* small = &readback;
      if (supersample > 1) {
        cv::resize(readback, downsampled_rgba,
                   cv::Size(fbo_width / supersample, fbo_height / supersample), 0, 0,
                   cv::INTER_AREA);
        small = &downsampled_rgba;
      }
      cv::Mat bgr = pooled_frame(small->rows, small->cols, CV_8UC3);
      cv::cvtColor(*small, bgr, cv::COLOR_RGBA2BGR);
      return bgr;
    }
    return quantize(render_linear(st));
  }

  // ---- the readout: interlaced fields, rolling bands ----

  // Sensor rows `rows` of `out` (CV_32FC3, allocated) exposed about time t: one render, or the
  // exposure blur's sub-frames averaged as FrameMean averages a whole frame's.
  void expose(const StateAt& state_at, double t, const Band& rows, cv::Mat& out) {
    const double exposure = camera.exposure;
    const int n = setup.effects.blur_subframes;
    if (!(n > 1 && exposure > 0)) {
      render_linear_rows(state_at(t), rows, out);
      return;
    }
    cv::Mat sum = out.rowRange(rows.v0, rows.v1);
    sum.setTo(0);
    band_subframe.create(out.size(), CV_32FC3);
    for (int i = 0; i < n; ++i) {
      render_linear_rows(state_at(t - 0.5 * exposure + (i + 0.5) * exposure / n), rows,
                         band_subframe);
      sum += band_subframe.rowRange(rows.v0, rows.v1);
    }
    sum *= 1.0 / static_cast<double>(n);
  }

  // The geometric frame of an interlaced or rolling readout whose first row is taken at t into
  // `linear` (and the mask, at the same rows' times, into `mask` if given).
  void expose_readout(const StateAt& state_at, double t, cv::Mat& linear, cv::Mat* mask) {
    const int H = camera.height;
    linear.create(H, camera.width, CV_32FC3);
    if (mask) mask->create(H, camera.width, CV_8UC1);
    if (rolling) {
      for (const Band& b : bands) {
        expose(state_at, t + b.time_offset, b, linear);
        if (mask) render_mask_rows(state_at(t + b.time_offset), b.v0, b.v1, *mask);
      }
      return;
    }
    // Two whole frames, one per field, and the second field's rows copied over the first's.
    const Band all{0, H, 0.0, 0, fbo_height};
    const double t_second = t + field_interval();
    const int second_rows = setup.readout.field_order == "even_first" ? 1 : 0;
    expose(state_at, t, all, linear);
    second_field.create(linear.size(), CV_32FC3);
    expose(state_at, t_second, all, second_field);
    for (int v = second_rows; v < H; v += 2) second_field.row(v).copyTo(linear.row(v));
    if (!mask) return;
    render_mask_rows(state_at(t), 0, H, *mask);
    const cv::Mat second_mask = render_mask(state_at(t_second));
    for (int v = second_rows; v < H; v += 2) second_mask.row(v).copyTo(mask->row(v));
  }

  double field_interval() const { return 0.5 / camera.fps; }

  double readout_duration() const {
    if (interlaced) return field_interval();
    return rolling ? setup.readout.time : 0.0;
  }

  // When the truth's state holds for a frame whose first row is taken at t (FrameTruth::t_state).
  // Rolling: the time of the row where the disk's centre is, a fixed point (the row depends on
  // where the disk is then); it contracts by the disk's image speed times the line time (px per
  // row), far below 1, so a few steps reach it.
  double state_time(const StateAt& state_at, double t) const {
    if (interlaced) return t + 0.5 * field_interval();
    if (!rolling) return t;
    double ts = t;
    for (int i = 0; i < 64; ++i) {
      const double v = truth(state_at(ts)).disk_center_px.y;
      if (!std::isfinite(v)) return ts;
      const double next = t + row_time_offset(std::clamp(v, 0.0, camera.height - 1.0));
      if (std::abs(next - ts) <= 1e-12) return next;
      ts = next;
    }
    return ts;
  }

  // A rolling readout's time of image row v (continuous): v line times, or its band's time.
  double row_time_offset(double v) const {
    if (setup.readout.band_rows == 1) return v * line_time;
    const auto row = static_cast<std::size_t>(std::lround(v));
    return bands[row / static_cast<std::size_t>(setup.readout.band_rows)].time_offset;
  }

  FrameTruth truth(const SceneState& st) const {
    FrameTruth tr;
    tr.t = st.t;
    tr.theta = st.hand_angle;
    tr.s_h = st.s_h;
    if (st.spatial) {  // the object's centre (no marker: both are the centre)
      const cv::Vec3d c = st.spatial->object_position;
      tr.disk_center_table = tr.marker_table = {c[0], c[1], c[2]};
      tr.disk_center_px = tr.marker_px = camera.project(tr.disk_center_table);
      return tr;
    }
    const double z = setup.render.disk_thickness;
    tr.disk_center_table = {st.disk_center.x, st.disk_center.y, z};
    tr.marker_table = {st.disk_center.x + marker_offset * disk_radius * std::cos(st.disk_angle),
                       st.disk_center.y + marker_offset * disk_radius * std::sin(st.disk_angle), z};
    const auto px = camera.project(std::vector<cv::Point3d>{tr.disk_center_table, tr.marker_table});
    tr.disk_center_px = px[0];
    tr.marker_px = px[1];
    return tr;
  }
};

Renderer::Renderer(const RenderSetup& setup, std::optional<GlBackend> backend) {
  if (!setup.hand && !setup.spatial) throw std::invalid_argument("render: no hand to draw");
  const GlBackend chosen = backend ? *backend : parse_backend(setup.render.backend);
  impl_ = std::make_unique<Impl>(setup, chosen);
}

Renderer::~Renderer() = default;

void Renderer::set_boards(std::vector<camera::PlacedBoard> boards) {
  impl_->set_boards(std::move(boards));
}

const camera::CameraModel& Renderer::camera() const { return impl_->camera; }
std::string Renderer::gl_description() const { return impl_->context->description(); }
cv::Mat Renderer::render_linear(const SceneState& state) { return impl_->render_linear(state); }
cv::Mat Renderer::render_8u(const SceneState& state) { return impl_->render_8u(state); }
FrameTruth Renderer::truth(const SceneState& state) const { return impl_->truth(state); }

Frame Renderer::capture(const sim::Trajectory& trajectory, double t,
                        const CaptureOptions& options) {
  return capture(
      [&](double ts) {
        return SceneState::from_sample(
            trajectory.sample(std::clamp(ts, trajectory.t_begin(), trajectory.t_end())));
      },
      t, options);
}

double Renderer::readout_duration() const { return impl_->readout_duration(); }
cv::Mat Renderer::render_mask(const SceneState& state) { return impl_->render_mask(state); }

Frame Renderer::capture(const StateAt& state_at, double t, const CaptureOptions& options) {
  const EffectsSpec& fx = impl_->setup.effects;
  EffectsRng& rng = impl_->rng;
  Frame frame;
  const double t_capture = jittered_time(t, fx.jitter_s, rng);
  const SceneState mid = state_at(t_capture);
  const double t_state = impl_->state_time(state_at, t_capture);
  frame.truth = impl_->truth(t_state == t_capture ? mid : state_at(t_state));
  frame.truth.t = t_capture;
  frame.truth.t_state = t_state;
  if (dropped(fx.drop_probability, rng)) {
    frame.truth.dropped = true;
    return frame;
  }
  if (!impl_->setup.readout.global()) {
    cv::Mat unquantized;
    cv::Mat& linear = fx.quantize ? impl_->linear_scratch : unquantized;
    impl_->expose_readout(state_at, t_capture, linear, options.mask ? &frame.mask : nullptr);
    finish_frame(linear, frame);
    return frame;
  }
  if (options.mask) frame.mask = impl_->render_mask(mid);
  const double exposure = impl_->camera.exposure;
  const bool one_render = !(fx.blur_subframes > 1 && exposure > 0);
  const bool plain = fx.blur_subframes <= 1 && fx.noise_read_dn == 0 && fx.noise_shot_gain == 0 &&
                     fx.vignetting == 0 && fx.quantize;
  // Without anything that makes a render's pixels fractional (blur, vignetting, supersampling,
  // distortion), the float frame holds whole numbers, and the noise goes straight onto the 8-bit
  // render: the same frame, bit for bit, without a float frame (apply_noise_8u).
  const bool whole_numbers = one_render && fx.vignetting == 0 && fx.quantize &&
                             impl_->supersample == 1 && !impl_->camera.distorted();
  if (plain || whole_numbers) {
    frame.image = impl_->render_8u(mid);
    apply_noise_8u(frame.image, fx.noise_read_dn, fx.noise_shot_gain, rng);
    return frame;
  }
  // The float image is the frame only when it is not quantised; otherwise it is scratch that the
  // renderer keeps from frame to frame (see render_linear).
  cv::Mat unquantized;
  cv::Mat& linear = fx.quantize ? impl_->linear_scratch : unquantized;
  if (!one_render) {
    // Exposure blur: equally weighted sub-frames over the exposure centred on the capture time,
    // each rendered into the same buffer and added to the running mean.
    FrameMean mean;
    for (int i = 0; i < fx.blur_subframes; ++i) {
      const double ts = t_capture - 0.5 * exposure + (i + 0.5) * exposure / fx.blur_subframes;
      impl_->render_linear(state_at(ts), impl_->subframe);
      mean.add(impl_->subframe);
    }
    linear = mean.finish();
  } else {
    impl_->render_linear(mid, linear);
  }
  finish_frame(linear, frame);
  return frame;
}

void Renderer::finish_frame(cv::Mat& linear, Frame& frame) {
  const EffectsSpec& fx = impl_->setup.effects;
  if (fx.vignetting > 0)
    apply_vignetting(linear, fx.vignetting, {impl_->camera.K(0, 2), impl_->camera.K(1, 2)});
  apply_noise(linear, fx.noise_read_dn, fx.noise_shot_gain, impl_->rng);
  frame.image = fx.quantize ? quantize(linear) : linear;
}

}  // namespace flatland::render