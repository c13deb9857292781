// Camera model (pose, projection, validation, distortion maps) and image effects of the renderer.
#include "flatland/camera/camera_model.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/render/distortion_maps.hpp"
#include "flatland/render/effects.hpp"

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

namespace camera = flatland::camera;
namespace model = flatland::model;
using flatland::CameraSpec;
using flatland::render::DistortionMaps;
using flatland::render::EffectsRng;

/// A tilted camera looking at the table from the side and above, with the given distortion.
CameraSpec oblique_spec(std::array<double, 5> distortion = {}) {
  CameraSpec spec;
  spec.width = 800;
  spec.height = 600;
  spec.fx = 820;
  spec.fy = 810;
  spec.cx = 405.3;
  spec.cy = 296.8;
  spec.distortion = distortion;
  spec.position = {0.35, -0.6, 0.9};
  spec.look_at = {0.05, 0.1, 0.0};
  spec.up = {0.0, 0.0, 1.0};
  return spec;
}

/// Runs from_spec and returns the message of the std::invalid_argument it must throw.
std::string validation_error(const CameraSpec& spec) {
  try {
    flatland::model::compile_camera(spec);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  ADD_FAILURE() << "from_spec accepted an invalid spec";
  return {};
}

void expect_error_names(const CameraSpec& spec, const std::string& field) {
  const std::string msg = validation_error(spec);
  EXPECT_EQ(msg.rfind(field + ": ", 0), 0u) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
}

/// Brown-Conrady model written out, independent of OpenCV: camera-frame point -> pixel. With
/// k4..k6 (d[5..7]) the rational model's denominator divides the radial term.
cv::Point2d brown_conrady(const cv::Vec3d& pc, const cv::Matx33d& K,
                          const flatland::camera::Distortion& d) {
  const double x = pc[0] / pc[2], y = pc[1] / pc[2];
  const double r2 = x * x + y * y;
  const double radial = (1 + d[0] * r2 + d[1] * r2 * r2 + d[4] * r2 * r2 * r2) /
                        (1 + d[5] * r2 + d[6] * r2 * r2 + d[7] * r2 * r2 * r2);
  const double xd = x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x);
  const double yd = y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y;
  return {K(0, 0) * xd + K(0, 2), K(1, 1) * yd + K(1, 2)};
}

// --- Camera pose and projection ------------------------------------------------------------------

TEST(RenderCamera, OverheadViewShowsTableXRightAndYUp) {
  const camera::CameraModel cam =
      flatland::model::compile_camera(CameraSpec{});  // (0,0,1) looking down, up +y
  const cv::Point2d below = cam.project(cv::Point3d(0, 0, 0));
  EXPECT_NEAR(below.x, 319.5, 1e-9);
  EXPECT_NEAR(below.y, 239.5, 1e-9);

  const cv::Point2d px = cam.project(cv::Point3d(0.1, 0, 0));
  EXPECT_NEAR(px.x, 319.5 + 70.0, 1e-9);  // fx * 0.1 m / 1 m: to the right
  EXPECT_NEAR(px.y, 239.5, 1e-9);
  const cv::Point2d py = cam.project(cv::Point3d(0, 0.1, 0));
  EXPECT_NEAR(py.x, 319.5, 1e-9);
  EXPECT_NEAR(py.y, 239.5 - 70.0, 1e-9);  // up in the image

  const cv::Vec3d c = cam.position_in_table();
  EXPECT_NEAR(cv::norm(c - cv::Vec3d(0, 0, 1)), 0.0, 1e-12);
  EXPECT_FALSE(cam.distorted());
}

TEST(RenderCamera, PoseIsARotationAndRvecReproducesIt) {
  for (const CameraSpec& spec : {CameraSpec{}, oblique_spec()}) {
    const camera::CameraModel cam = flatland::model::compile_camera(spec);
    EXPECT_LT(cv::norm(cam.R * cam.R.t() - cv::Matx33d::eye(), cv::NORM_INF), 1e-12);
    EXPECT_NEAR(cv::determinant(cam.R), 1.0, 1e-12);
    // The overhead camera is a half turn about x: the awkward case for Rodrigues.
    cv::Matx33d back;
    cv::Rodrigues(cam.rvec(), back);
    EXPECT_LT(cv::norm(back - cam.R, cv::NORM_INF), 1e-12);
    const cv::Vec3d c = cam.position_in_table();
    for (int i = 0; i < 3; ++i)
      EXPECT_NEAR(c[i], spec.position[static_cast<std::size_t>(i)], 1e-12);
  }
}

TEST(RenderCamera, LookAtPointProjectsToPrincipalPointAndUpIsUp) {
  const CameraSpec spec = oblique_spec({-0.2, 0.05, 1e-3, -5e-4, 0.01});
  const camera::CameraModel cam = flatland::model::compile_camera(spec);
  EXPECT_TRUE(cam.distorted());
  const cv::Point2d p = cam.project(cv::Point3d(spec.look_at[0], spec.look_at[1], 0));
  EXPECT_NEAR(p.x, spec.cx, 1e-9);
  EXPECT_NEAR(p.y, spec.cy, 1e-9);
  // A point straight above the look-at point appears higher in the image (up = table +z).
  const cv::Point2d q = cam.project(cv::Point3d(spec.look_at[0], spec.look_at[1], 0.05));
  EXPECT_LT(q.y, p.y - 10);
}

TEST(RenderCamera, ProjectMatchesOpenCVAndTheModelWrittenOut) {
  for (const bool rational : {false, true}) {
    SCOPED_TRACE(rational ? "rational" : "plumb_bob");
    camera::CameraModel cam =
        flatland::model::compile_camera(oblique_spec({-0.3, 0.1, 1e-3, -2e-3, 0.02}));
    if (rational) {
      cam.dist[5] = 0.05;  // k4..k6: the rational model's denominator
      cam.dist[6] = -0.02;
      cam.dist[7] = 0.01;
    }
    EXPECT_EQ(cam.rational(), rational);
    std::vector<cv::Point3d> pts;
    for (double x = -0.3; x <= 0.31; x += 0.1)
      for (double y = -0.2; y <= 0.41; y += 0.1)
        for (double z : {0.0, 0.03}) pts.emplace_back(x, y, z);
    const std::vector<cv::Point2d> got = cam.project(pts);
    ASSERT_EQ(got.size(), pts.size());

    std::vector<cv::Point2d> ref;
    cv::projectPoints(pts, cv::Mat(cam.rvec()), cv::Mat(cam.t), cv::Mat(cam.K), cv::Mat(cam.dist),
                      ref);
    for (std::size_t i = 0; i < pts.size(); ++i) {
      EXPECT_NEAR(got[i].x, ref[i].x, 1e-9);
      EXPECT_NEAR(got[i].y, ref[i].y, 1e-9);
      const cv::Vec3d pc = cam.R * cv::Vec3d(pts[i].x, pts[i].y, pts[i].z) + cam.t;
      ASSERT_GT(pc[2], 0);
      const cv::Point2d own = brown_conrady(pc, cam.K, cam.dist);
      EXPECT_NEAR(got[i].x, own.x, 1e-7);
      EXPECT_NEAR(got[i].y, own.y, 1e-7);
      const cv::Point2d single = cam.project(pts[i]);
      EXPECT_EQ(single, got[i]);
    }
    EXPECT_TRUE(cam.project(std::vector<cv::Point3d>{}).empty());
  }
}

// --- Validation ------------------------------------------------------------------------------

TEST(RenderCameraValidation, RejectsBadIntrinsics) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (double fx : {0.0, -700.0, nan, inf}) {
    CameraSpec s;
    s.fx = fx;
    expect_error_names(s, "camera.fx");
  }
  {
    CameraSpec s;
    s.fy = 0;
    expect_error_names(s, "camera.fy");
  }
  for (int w : {0, -640, 20000}) {
    CameraSpec s;
    s.width = w;
    expect_error_names(s, "camera.width");
  }
  {
    CameraSpec s;
    s.height = 0;
    expect_error_names(s, "camera.height");
  }
  {
    CameraSpec s;
    s.cx = nan;
    expect_error_names(s, "camera.cx");
  }
  {
    CameraSpec s;
    s.cy = inf;
    expect_error_names(s, "camera.cy");
  }
  {
    CameraSpec s;
    s.distortion[1] = nan;
    expect_error_names(s, "camera.distortion");
  }
  for (double fps : {0.0, -30.0, nan}) {
    CameraSpec s;
    s.fps = fps;
    expect_error_names(s, "camera.fps");
  }
  for (double exposure : {-1e-3, 0.05, nan}) {  // 0.05 s > 1/30 s
    CameraSpec s;
    s.exposure = exposure;
    expect_error_names(s, "camera.exposure");
  }
  CameraSpec ok;
  ok.exposure = 1.0 / 30.0;
  EXPECT_NO_THROW(flatland::model::compile_camera(ok));
}

TEST(RenderCameraValidation, RejectsBadPose) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (double z : {0.0, -0.5}) {
    CameraSpec s;
    s.position = {0.0, 0.0, z};
    s.look_at = {0.0, 0.0, z - 1.0};
    expect_error_names(s, "camera.position");
    EXPECT_NE(validation_error(s).find("above the table"), std::string::npos);
  }
  {
    CameraSpec s;
    s.position = {0.1, 0.2, nan};
    expect_error_names(s, "camera.position");
  }
  {
    CameraSpec s;
    s.look_at = {0.1, 0.2, 0.3};
    s.position = {0.1, 0.2, 0.3};
    expect_error_names(s, "camera.look_at");
  }
  {
    CameraSpec s;
    s.look_at = {nan, 0.0, 0.0};
    expect_error_names(s, "camera.look_at");
  }
  {
    CameraSpec s;  // looking level: the table is not in front of the camera
    s.look_at = {1.0, 0.0, 1.0};
    s.up = {0.0, 0.0, 1.0};
    expect_error_names(s, "camera.look_at");
  }
  {
    CameraSpec s;
    s.up = {0.0, 0.0, 1.0};  // parallel to the viewing direction of the overhead camera
    expect_error_names(s, "camera.up");
  }
  {
    CameraSpec s;
    s.up = {0.0, 0.0, 0.0};
    expect_error_names(s, "camera.up");
  }
}

// --- camera::Distortion maps
// -------------------------------------------------------------------------

/// Largest distance between output pixel centres and their map positions sent back through the
/// camera model (ideal pixel -> normalised ray -> cv::projectPoints with K_s and dist), over every
/// `step`-th pixel and the whole border.
double map_round_trip_error(const camera::CameraModel& cam, const DistortionMaps& maps, int step) {
  const int s = maps.supersample;
  const cv::Matx33d K_s(cam.K(0, 0) * s, 0, (cam.K(0, 2) + 0.5) * s - 0.5, 0, cam.K(1, 1) * s,
                        (cam.K(1, 2) + 0.5) * s - 0.5, 0, 0, 1);
  const cv::Matx33d& Ki = maps.ideal_K;
  std::vector<cv::Point3d> rays;
  std::vector<cv::Point2d> pixels;
  const int w = maps.map_x.cols, h = maps.map_x.rows;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      const bool border = u == 0 || v == 0 || u == w - 1 || v == h - 1;
      if (!border && (u % step != 0 || v % step != 0)) continue;
      const double mx = maps.map_x.at<float>(v, u), my = maps.map_y.at<float>(v, u);
      rays.emplace_back((mx - Ki(0, 2)) / Ki(0, 0), (my - Ki(1, 2)) / Ki(1, 1), 1.0);
      pixels.emplace_back(u, v);
    }
  std::vector<cv::Point2d> back;
  cv::projectPoints(rays, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(K_s), cv::Mat(cam.dist),
                    back);
  double worst = 0;
  for (std::size_t i = 0; i < back.size(); ++i)
    worst = std::max(worst, cv::norm(back[i] - pixels[i]));
  return worst;
}

TEST(RenderCameraDistortion, MapsRoundTripThroughTheCameraModel) {
  CameraSpec spec;  // 640 x 480, f = 700: corners at ~30 deg off axis
  spec.distortion = {-0.3, 0.1, 1e-3, 0.0, 0.0};
  const camera::CameraModel cam = flatland::model::compile_camera(spec);
  for (int s : {1, 3}) {
    SCOPED_TRACE("supersample " + std::to_string(s));
    const DistortionMaps maps = flatland::render::make_distortion_maps(cam, s);
    EXPECT_EQ(maps.supersample, s);
    ASSERT_EQ(maps.map_x.type(), CV_32FC1);
    ASSERT_EQ(maps.map_y.type(), CV_32FC1);
    EXPECT_EQ(maps.map_x.size(), cv::Size(640 * s, 480 * s));
    EXPECT_EQ(maps.map_y.size(), cv::Size(640 * s, 480 * s));
    EXPECT_DOUBLE_EQ(maps.ideal_K(0, 0), 700.0 * s);
    EXPECT_DOUBLE_EQ(maps.ideal_K(1, 1), 700.0 * s);
    // Barrel distortion: the pinhole footprint of the image is larger than the image.
    EXPECT_GT(maps.ideal_width, 640 * s);
    EXPECT_GT(maps.ideal_height, 480 * s);

    const double err = map_round_trip_error(cam, maps, s == 1 ? 1 : 7);
    EXPECT_LT(err, 1e-3);
    RecordProperty("round_trip_px_s" + std::to_string(s), std::to_string(err));

    // Every map position lies inside the ideal image with the 2-pixel margin.
    double minx, maxx, miny, maxy;
    cv::minMaxLoc(maps.map_x, &minx, &maxx);
    cv::minMaxLoc(maps.map_y, &miny, &maxy);
    EXPECT_GE(minx, 2.0 - 1e-3);
    EXPECT_GE(miny, 2.0 - 1e-3);
    EXPECT_LE(maxx, maps.ideal_width - 3.0 + 1e-3);
    EXPECT_LE(maxy, maps.ideal_height - 3.0 + 1e-3);
    // ... and the footprint is tight: no more than a pixel of extra margin.
    EXPECT_LT(minx, 3.0);
    EXPECT_LT(maxy, maps.ideal_height - 2.0);
  }
}

TEST(RenderCameraDistortion, PincushionMapsStayInsideTheImage) {
  CameraSpec spec;
  spec.distortion = {0.25, 0.0, 0.0, -1e-3, 0.0};
  const camera::CameraModel cam = flatland::model::compile_camera(spec);
  const DistortionMaps maps = flatland::render::make_distortion_maps(cam, 1);
  // The footprint shrinks towards the centre; the ideal image keeps at least the camera's size.
  EXPECT_GE(maps.ideal_width, 640);
  EXPECT_GE(maps.ideal_height, 480);
  EXPECT_LT(map_round_trip_error(cam, maps, 1), 1e-3);
}

TEST(RenderCameraDistortion, MapsAgreeWithProjectOfTablePoints) {
  // The whole chain the renderer relies on: a table point drawn by the ideal pinhole camera and
  // remapped lands where project() says.
  const camera::CameraModel cam =
      flatland::model::compile_camera(oblique_spec({-0.3, 0.1, 1e-3, -5e-4, 0.0}));
  const int s = 2;
  const DistortionMaps maps = flatland::render::make_distortion_maps(cam, s);
  std::vector<cv::Point3d> pts;
  for (double x = -0.2; x <= 0.31; x += 0.05)
    for (double y = -0.1; y <= 0.31; y += 0.05) pts.emplace_back(x, y, 0.0);
  const std::vector<cv::Point2d> distorted = cam.project(pts);
  std::vector<cv::Point2d> ideal;
  cv::projectPoints(pts, cv::Mat(cam.rvec()), cv::Mat(cam.t), cv::Mat(maps.ideal_K), cv::noArray(),
                    ideal);
  int checked = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const cv::Point2d p((distorted[i].x + 0.5) * s - 0.5, (distorted[i].y + 0.5) * s - 0.5);
    if (p.x < 0 || p.y < 0 || p.x > maps.map_x.cols - 1 || p.y > maps.map_x.rows - 1) continue;
    // Bilinear interpolation of the maps at p, computed in double.
    const int u0 = std::min(static_cast<int>(p.x), maps.map_x.cols - 2);
    const int v0 = std::min(static_cast<int>(p.y), maps.map_x.rows - 2);
    const double a = p.x - u0, b = p.y - v0;
    const auto lerp = [&](const cv::Mat& m) {
      return (1 - a) * (1 - b) * m.at<float>(v0, u0) + a * (1 - b) * m.at<float>(v0, u0 + 1) +
             (1 - a) * b * m.at<float>(v0 + 1, u0) + a * b * m.at<float>(v0 + 1, u0 + 1);
    };
    EXPECT_NEAR(lerp(maps.map_x), ideal[i].x, 5e-3) << "point " << i;
    EXPECT_NEAR(lerp(maps.map_y), ideal[i].y, 5e-3) << "point " << i;
    ++checked;
  }
  EXPECT_GT(checked, 50);
}

TEST(RenderCameraDistortion, IdentityMapsWithoutDistortion) {
  const camera::CameraModel cam = flatland::model::compile_camera(oblique_spec());
  for (int s : {1, 2}) {
    const DistortionMaps maps = flatland::render::make_distortion_maps(cam, s);
    EXPECT_EQ(maps.ideal_width, 800 * s);
    EXPECT_EQ(maps.ideal_height, 600 * s);
    EXPECT_DOUBLE_EQ(maps.ideal_K(0, 0), 820.0 * s);
    EXPECT_DOUBLE_EQ(maps.ideal_K(1, 1), 810.0 * s);
    EXPECT_DOUBLE_EQ(maps.ideal_K(0, 2), (405.3 + 0.5) * s - 0.5);
    EXPECT_DOUBLE_EQ(maps.ideal_K(1, 2), (296.8 + 0.5) * s - 0.5);
    ASSERT_EQ(maps.map_x.size(), cv::Size(800 * s, 600 * s));
    ASSERT_EQ(maps.map_y.size(), cv::Size(800 * s, 600 * s));
    bool identity = true;
    for (int v = 0; v < maps.map_x.rows && identity; ++v)
      for (int u = 0; u < maps.map_x.cols; ++u)
        if (maps.map_x.at<float>(v, u) != u || maps.map_y.at<float>(v, u) != v) {
          identity = false;
          break;
        }
    EXPECT_TRUE(identity);
  }
}

TEST(RenderCameraDistortion, RejectsDistortionThatFoldsOverAndBadSupersample) {
  CameraSpec spec;
  spec.distortion = {-2.0, 0.0, 0.0, 0.0, 0.0};  // r(1 - 2 r^2) peaks inside the image
  const camera::CameraModel cam = flatland::model::compile_camera(spec);
  try {
    flatland::render::make_distortion_maps(cam, 1);
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()).rfind("camera.distortion: ", 0), 0u) << e.what();
  }
  EXPECT_THROW(flatland::render::make_distortion_maps(camera::CameraModel{}, 0),
               std::invalid_argument);
}

// --- Effects ---------------------------------------------------------------------------------

double measured_sigma(const cv::Mat& noisy, double flat) {
  cv::Scalar mean, stddev;
  cv::meanStdDev(noisy, mean, stddev);
  EXPECT_NEAR(mean[0], flat, 0.1);
  return stddev[0];
}

TEST(RenderEffects, NoiseHasTheRequestedSigma) {
  struct Case {
    double read, gain, flat;
  };
  for (const Case c : {Case{2.0, 0.0, 100.0}, Case{0.0, 0.5, 100.0}, Case{1.5, 0.3, 180.0},
                       Case{3.0, 0.8, -10.0}}) {  // negative signal: read noise only
    cv::Mat img(480, 640, CV_32FC1, cv::Scalar(c.flat));
    EffectsRng rng(42);
    flatland::render::apply_noise(img, c.read, c.gain, rng);
    const double expected = std::sqrt(c.read * c.read + c.gain * std::max(c.flat, 0.0));
    EXPECT_NEAR(measured_sigma(img, c.flat), expected, 0.05 * expected)
        << "read " << c.read << " gain " << c.gain << " flat " << c.flat;
  }
}

// The noise is normal in shape, not just in sigma: the fractions within 1, 2 and 3 sigma and the
// kurtosis match the standard normal's (68.27 %, 95.45 %, 99.73 %, 3) within a few sampling
// standard errors of 307200 draws; the quantile table is symmetric and increasing.
TEST(RenderEffects, NoiseIsGaussian) {
  const float* q = flatland::render::gaussian_quantiles();
  for (int i = 0; i < 65536; ++i) {
    ASSERT_NEAR(q[i], -q[65535 - i], 1e-5) << i;
    if (i > 0) {
      ASSERT_GT(q[i], q[i - 1]) << i;
    }
  }
  cv::Mat img(480, 640, CV_32FC1, cv::Scalar(0.0));
  EffectsRng rng(3);
  flatland::render::apply_noise(img, 1.0, 0.0, rng);
  double within[3] = {0, 0, 0}, m2 = 0, m4 = 0;
  const double n = static_cast<double>(img.total());
  for (int v = 0; v < img.rows; ++v)
    for (int u = 0; u < img.cols; ++u) {
      const double z = img.at<float>(v, u);
      for (int k = 0; k < 3; ++k) within[k] += std::abs(z) < k + 1;
      m2 += z * z;
      m4 += z * z * z * z;
    }
  EXPECT_NEAR(within[0] / n, 0.682689, 0.004);
  EXPECT_NEAR(within[1] / n, 0.954500, 0.002);
  EXPECT_NEAR(within[2] / n, 0.997300, 0.0006);
  m2 /= n;
  m4 /= n;
  EXPECT_NEAR(m4 / (m2 * m2), 3.0, 0.05);  // SE of the kurtosis ~ sqrt(24/n) = 0.009
}

TEST(RenderEffects, NoiseIsSeeded) {
  const cv::Mat flat(120, 160, CV_32FC3, cv::Scalar(50, 100, 150));
  const auto noisy = [&](std::uint64_t seed) {
    cv::Mat img = flat.clone();
    EffectsRng rng(seed);
    flatland::render::apply_noise(img, 2.0, 0.4, rng);
    return img;
  };
  const cv::Mat a = noisy(7), b = noisy(7), c = noisy(8);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_INF), 1.0);
  EXPECT_GT(cv::norm(a, flat, cv::NORM_INF), 1.0);
}

// The noise's stream written out independently of effects.cpp, one value at a time as the
// renderer drew it before its runs were vectorised (2026-11-28): SplitMix64 (Steele, Lea, Flood
// 2014) seeded by one draw of the scene's generator, each word four 16-bit quantile indices from
// its lowest bits, running on across rows and channels. Pins the frames a seed gives.
void reference_noise(cv::Mat& image_f32, double read_dn, double gain_dn, std::uint64_t seed) {
  EffectsRng rng(seed);
  std::uint64_t state = rng.engine()();
  const float* quantile = flatland::render::gaussian_quantiles();
  const float read = static_cast<float>(read_dn), read_var = static_cast<float>(read_dn * read_dn);
  const float gain = static_cast<float>(gain_dn);
  std::uint64_t bits = 0;
  int left = 0;
  for (int v = 0; v < image_f32.rows; ++v) {
    float* row = image_f32.ptr<float>(v);
    for (int i = 0; i < image_f32.cols * image_f32.channels(); ++i) {
      if (left == 0) {
        std::uint64_t z = (state += 0x9e3779b97f4a7c15ULL);
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
        bits = z ^ (z >> 31);
        left = 4;
      }
      const float z = quantile[bits & 0xffff];
      bits >>= 16;
      --left;
      const float sigma = gain == 0 ? read : std::sqrt(read_var + gain * std::max(row[i], 0.0f));
      row[i] += sigma * z;
    }
  }
}

cv::Mat random_u8(int rows, int cols, int type, int seed) {
  cv::Mat img(rows, cols, type);
  cv::RNG(seed).fill(img, cv::RNG::UNIFORM, 0, 256);
  return img;
}

// apply_noise draws in runs of 2048 values and apply_noise_8u noises 8-bit images without a float
// frame (read noise alone from offsets rounded in advance): both give the reference's values
// exactly, on rows shorter and longer than a run, whose lengths are not multiples of the 4 values
// of a word, on a window of a larger image (rows not contiguous), with shot noise and with offsets
// that depend on the level; the 8-bit path is the float path rounded, bit for bit.
TEST(RenderEffects, NoiseIsTheReferenceStreamOnFloatAndEightBitImages) {
  struct Case {
    int rows, cols, type;
    double read, gain;
  };
  for (const Case c : {Case{48, 64, CV_8UC3, 2.0, 0.0}, Case{31, 53, CV_8UC3, 1.5, 0.3},
                       Case{9, 1001, CV_8UC3, 8.0, 0.0}, Case{40, 37, CV_8UC1, 0.0, 0.8},
                       Case{7, 701, CV_8UC4, 3.0, 0.2},
                       // 0.5 DN: 2 of the 65536 rounded offsets depend on the level (a sum within
                       // float rounding of a half); about 28 values of this frame draw them.
                       Case{480, 640, CV_8UC3, 0.5, 0.0}}) {
    SCOPED_TRACE("rows " + std::to_string(c.rows) + " cols " + std::to_string(c.cols) + " read " +
                 std::to_string(c.read) + " gain " + std::to_string(c.gain));
    const cv::Mat bytes = random_u8(c.rows, c.cols, c.type, c.rows * c.cols);
    cv::Mat expected;
    bytes.convertTo(expected, CV_32F);
    reference_noise(expected, c.read, c.gain, 11);
    cv::Mat floats;
    bytes.convertTo(floats, CV_32F);
    EffectsRng a(11);
    flatland::render::apply_noise(floats, c.read, c.gain, a);
    EXPECT_EQ(cv::norm(floats, expected, cv::NORM_INF), 0.0);
    // The 8-bit path, on a window of a larger image: its rows are not one contiguous block.
    cv::Mat canvas(c.rows + 2, c.cols + 5, c.type, cv::Scalar::all(0));
    cv::Mat window = canvas(cv::Rect(3, 1, c.cols, c.rows));
    bytes.copyTo(window);
    ASSERT_FALSE(window.isContinuous());
    EffectsRng b(11);
    flatland::render::apply_noise_8u(window, c.read, c.gain, b);
    EXPECT_EQ(cv::norm(window, flatland::render::quantize(expected), cv::NORM_INF), 0.0);
    EXPECT_GT(cv::norm(window, bytes, cv::NORM_INF), 0.0);
    // Both took one draw from the scene's generator, as the reference did.
    EffectsRng fresh(11);
    fresh.engine()();
    const std::uint64_t next = fresh.engine()();
    EXPECT_EQ(a.engine()(), next);
    EXPECT_EQ(b.engine()(), next);
  }
  cv::Mat floats(4, 4, CV_32FC1);
  EffectsRng rng(1);
  EXPECT_THROW(flatland::render::apply_noise_8u(floats, 2.0, 0.0, rng), std::invalid_argument);
}

/// Pearson's correlation of a and b (equal-sized single-channel float images).
double correlation(const cv::Mat& a, const cv::Mat& b) {
  cv::Scalar ma, sa, mb, sb;
  cv::meanStdDev(a, ma, sa);
  cv::meanStdDev(b, mb, sb);
  cv::Mat da = a - ma[0], db = b - mb[0];
  return da.dot(db) / (static_cast<double>(a.total()) * sa[0] * sb[0]);
}

// The noise against its closed form, on 640 x 480 x 3 frames of a flat signal: mean 0 (within 4
// standard errors, sigma / sqrt(n)); variance read^2 + gain * signal (within 4 standard errors of
// a sample variance, sigma^2 sqrt(2 / n)); no correlation between horizontal and vertical
// neighbours, neighbouring channels or the same pixel in successive frames beyond 4 / sqrt(n), the
// band of 4 standard errors of a correlation of independent values.
TEST(RenderEffects, NoiseIsUnbiasedWithTheClosedFormVarianceAndUncorrelated) {
  struct Case {
    double read, gain, flat;
  };
  for (const Case c : {Case{2.0, 0.0, 100.0}, Case{1.5, 0.3, 180.0}, Case{0.0, 0.5, 60.0}}) {
    SCOPED_TRACE("read " + std::to_string(c.read) + " gain " + std::to_string(c.gain));
    const cv::Mat flat(480, 640, CV_32FC3, cv::Scalar::all(c.flat));
    EffectsRng rng(2026);
    cv::Mat first = flat.clone(), second = flat.clone();
    flatland::render::apply_noise(first, c.read, c.gain, rng);
    flatland::render::apply_noise(second, c.read, c.gain, rng);
    const double variance = c.read * c.read + c.gain * c.flat;
    for (const cv::Mat* frame : {&first, &second}) {
      cv::Mat noise = *frame - flat;
      noise = noise.reshape(1);  // one column per value: pixels and channels interleaved
      const double n = static_cast<double>(noise.total());
      cv::Scalar mean, stddev;
      cv::meanStdDev(noise, mean, stddev);
      EXPECT_NEAR(mean[0], 0.0, 4 * std::sqrt(variance / n));
      EXPECT_NEAR(stddev[0] * stddev[0], variance, 4 * variance * std::sqrt(2 / n));
      const double band = 4 / std::sqrt(n);
      const int w = noise.cols;
      // Neighbouring channels of a pixel, neighbouring pixels in a row (3 values on), in a column.
      EXPECT_LT(std::abs(correlation(noise.colRange(0, w - 1), noise.colRange(1, w))), band);
      EXPECT_LT(std::abs(correlation(noise.colRange(0, w - 3), noise.colRange(3, w))), band);
      EXPECT_LT(std::abs(correlation(noise.rowRange(0, 479), noise.rowRange(1, 480))), band);
    }
    cv::Mat a = (first - flat), b = (second - flat);
    EXPECT_LT(std::abs(correlation(a.reshape(1), b.reshape(1))), 4 / std::sqrt(a.total() * 3.0));
  }
}

TEST(RenderEffects, EffectsThatAreOffDrawNothing) {
  EffectsRng used(99), fresh(99);
  cv::Mat img(48, 64, CV_32FC1, cv::Scalar(77.25));
  const cv::Mat before = img.clone();
  flatland::render::apply_noise(img, 0.0, 0.0, used);
  EXPECT_EQ(cv::norm(img, before, cv::NORM_INF), 0.0);
  EXPECT_EQ(flatland::render::jittered_time(1.25, 0.0, used), 1.25);
  EXPECT_FALSE(flatland::render::dropped(0.0, used));
  EXPECT_EQ(used.engine()(), fresh.engine()());  // the stream did not move
}

TEST(RenderEffects, JitterAndDropsFollowTheirDistributions) {
  EffectsRng rng(3);
  const int n = 20000;
  double sum = 0, sum2 = 0;
  for (int i = 0; i < n; ++i) {
    const double d = flatland::render::jittered_time(2.0, 1e-3, rng) - 2.0;
    sum += d;
    sum2 += d * d;
  }
  EXPECT_NEAR(sum / n, 0.0, 5e-5);
  EXPECT_NEAR(std::sqrt(sum2 / n), 1e-3, 5e-5);
  int drops = 0;
  for (int i = 0; i < n; ++i) drops += flatland::render::dropped(0.1, rng) ? 1 : 0;
  EXPECT_NEAR(drops / static_cast<double>(n), 0.1, 0.01);
  EXPECT_TRUE(flatland::render::dropped(1.0, rng));
  EXPECT_THROW(flatland::render::dropped(1.5, rng), std::invalid_argument);
  EXPECT_THROW(flatland::render::jittered_time(0.0, -1.0, rng), std::invalid_argument);
  cv::Mat img(4, 4, CV_32FC1, cv::Scalar(1));
  EXPECT_THROW(flatland::render::apply_noise(img, -1.0, 0.0, rng), std::invalid_argument);
}

TEST(RenderEffects, QuantizeRoundsAndSaturates) {
  const cv::Mat f =
      (cv::Mat_<float>(1, 8) << -5.0f, 0.4f, 0.6f, 1.5f, 127.49f, 254.6f, 255.4f, 300.0f);
  const cv::Mat q = flatland::render::quantize(f);
  ASSERT_EQ(q.type(), CV_8UC1);
  const std::vector<int> expected = {0, 0, 1, 2, 127, 255, 255, 255};
  for (int i = 0; i < 8; ++i) EXPECT_EQ(q.at<std::uint8_t>(0, i), expected[i]) << "index " << i;

  const cv::Mat rgb(2, 3, CV_32FC3, cv::Scalar(-1.0, 99.7, 1e6));
  const cv::Mat q3 = flatland::render::quantize(rgb);
  ASSERT_EQ(q3.type(), CV_8UC3);
  EXPECT_EQ(q3.at<cv::Vec3b>(1, 2), cv::Vec3b(0, 100, 255));
}

TEST(RenderEffects, DownsampleAveragesBlocks) {
  // 6 x 9 image of 3x3 blocks; inside each block a pixel checker of 0 and b (5 zeros, 4 b's when
  // the block starts with 0), so the block mean is 4b/9.
  cv::Mat img(6, 9, CV_32FC1);
  for (int v = 0; v < 6; ++v)
    for (int u = 0; u < 9; ++u) {
      const float b = static_cast<float>(9 * (1 + u / 3 + 3 * (v / 3)));
      img.at<float>(v, u) = ((u + v) % 2 == 1) ? b : 0.0f;
    }
  const cv::Mat small = flatland::render::downsample(img, 3);
  ASSERT_EQ(small.size(), cv::Size(3, 2));
  ASSERT_EQ(small.type(), CV_32FC1);
  for (int v = 0; v < 2; ++v)
    for (int u = 0; u < 3; ++u) {
      const double b = 9.0 * (1 + u + 3 * v);
      // Block (u, v) starts at (3u, 3v): its corner pixel is b when 3u + 3v is odd.
      const double ones = ((u + v) % 2 == 1) ? 5 : 4;
      EXPECT_NEAR(small.at<float>(v, u), ones * b / 9.0, 1e-4) << u << "," << v;
    }
  const cv::Mat same = flatland::render::downsample(img, 1);
  EXPECT_EQ(same.data, img.data);
  EXPECT_THROW(flatland::render::downsample(img, 4), std::invalid_argument);  // 9 % 4 != 0
  EXPECT_THROW(flatland::render::downsample(img, 0), std::invalid_argument);
}

TEST(RenderEffects, AverageFramesIsTheMean) {
  std::vector<cv::Mat> frames;
  for (float v : {1.0f, 2.0f, 6.0f}) frames.emplace_back(5, 4, CV_32FC3, cv::Scalar(v, 2 * v, 0));
  const cv::Mat avg = flatland::render::average_frames(frames);
  ASSERT_EQ(avg.type(), CV_32FC3);
  EXPECT_EQ(avg.at<cv::Vec3f>(4, 3), cv::Vec3f(3.0f, 6.0f, 0.0f));
  frames.emplace_back(5, 5, CV_32FC3, cv::Scalar::all(0));
  EXPECT_THROW(flatland::render::average_frames(frames), std::invalid_argument);
  EXPECT_THROW(flatland::render::average_frames({}), std::invalid_argument);
}

TEST(RenderEffects, VignettingKeepsTheCentreAndDarkensCorners) {
  const double strength = 0.4;
  cv::Mat img(481, 641, CV_32FC3, cv::Scalar::all(200.0));
  flatland::render::apply_vignetting(img, strength, cv::Point2d(320, 240));
  EXPECT_EQ(img.at<cv::Vec3f>(240, 320), cv::Vec3f(200, 200, 200));
  const float corner = static_cast<float>(200.0 * (1 - strength) * (1 - strength));
  for (const cv::Point& c :
       {cv::Point(0, 0), cv::Point(640, 0), cv::Point(0, 480), cv::Point(640, 480)})
    for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(img.at<cv::Vec3f>(c)[ch], corner, 1e-3);
  // Half way to the corner: (1 - s/4)^2.
  EXPECT_NEAR(img.at<cv::Vec3f>(120, 160)[0], 200.0 * (1 - strength / 4) * (1 - strength / 4),
              1e-3);

  // Off-centre principal point: only the farthest corner reaches (1 - s)^2, the others are
  // brighter.
  cv::Mat off(100, 200, CV_32FC1, cv::Scalar(1.0));
  flatland::render::apply_vignetting(off, strength, cv::Point2d(60.0, 40.0));
  EXPECT_FLOAT_EQ(off.at<float>(40, 60), 1.0f);
  EXPECT_NEAR(off.at<float>(99, 199), (1 - strength) * (1 - strength), 1e-6);
  EXPECT_GT(off.at<float>(0, 0), off.at<float>(99, 199));

  cv::Mat untouched(10, 10, CV_32FC1, cv::Scalar(5.0));
  flatland::render::apply_vignetting(untouched, 0.0, cv::Point2d(4.5, 4.5));
  EXPECT_EQ(cv::countNonZero(untouched != 5.0f), 0);
  EXPECT_THROW(flatland::render::apply_vignetting(untouched, 1.5, cv::Point2d(4.5, 4.5)),
               std::invalid_argument);
}

}  // namespace
