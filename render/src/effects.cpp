// Image effects of a real camera: exposure blur, anti-aliasing, vignetting, sensor noise,
// quantisation, timing jitter and dropped frames.
//
// The random effects draw from the caller's engine in a fixed order and draw nothing when off, so
// a scene renders the same frames for the same seed, and switching one effect off does not change
// the random numbers the others see.
#include "flatland/render/effects.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::render {

namespace {

std::string num(double v) {
  std::ostringstream os;
  os.precision(9);
  os << v;
  return os.str();
}

[[noreturn]] void fail(const std::string& what, const std::string& reason) {
  throw std::invalid_argument(what + ": " + reason);
}

void require_f32(const cv::Mat& image, const char* what) {
  if (image.empty() || image.depth() != CV_32F)
    fail(what, "expects a non-empty CV_32F image, got depth " + std::to_string(image.depth()) +
                   (image.empty() ? " (empty)" : ""));
}

}  // namespace

cv::Mat average_frames(const std::vector<cv::Mat>& subframes) {
  if (subframes.empty()) fail("average_frames", "no sub-frames");
  const cv::Mat& first = subframes.front();
  if (first.empty()) fail("average_frames", "empty sub-frame");
  cv::Mat sum = cv::Mat::zeros(first.size(), CV_MAKETYPE(CV_32F, first.channels()));
  cv::Mat as_float;
  for (const cv::Mat& f : subframes) {
    if (f.size() != first.size() || f.channels() != first.channels())
      fail("average_frames", "sub-frames differ in size or channels");
    // convertTo is a plain copy for CV_32F input; other depths (8-bit renders) are accepted too.
    f.convertTo(as_float, CV_32F);
    sum += as_float;
  }
  sum *= 1.0 / static_cast<double>(subframes.size());
  return sum;
}

cv::Mat downsample(const cv::Mat& image, int factor) {
  if (factor < 1) fail("downsample", "factor must be >= 1, got " + std::to_string(factor));
  if (factor == 1) return image;
  if (image.empty() || image.cols % factor != 0 || image.rows % factor != 0)
    fail("downsample", "image size " + std::to_string(image.cols) + " x " +
                           std::to_string(image.rows) + " is not a multiple of " +
                           std::to_string(factor));
  // INTER_AREA with an integer ratio is the exact mean over each factor x factor block.
  cv::Mat out;
  cv::resize(image, out, cv::Size(image.cols / factor, image.rows / factor), 0, 0, cv::INTER_AREA);
  return out;
}

void apply_vignetting(cv::Mat& image_f32, double strength, cv::Point2d principal_point) {
  if (!(strength >= 0 && strength <= 1))
    fail("effects.vignetting", "must be in [0, 1], got " + num(strength));
  if (!std::isfinite(principal_point.x) || !std::isfinite(principal_point.y))
    fail("apply_vignetting", "principal point must be finite");
  if (strength == 0) return;
  require_f32(image_f32, "apply_vignetting");
  // r_corner: distance to the farthest corner pixel centre, so that the gain there is exactly
  // (1 - strength)^2 when the principal point is the image centre.
  const double xs[2] = {0.0, image_f32.cols - 1.0}, ys[2] = {0.0, image_f32.rows - 1.0};
  double rc2 = 0;
  for (double x : xs)
    for (double y : ys) {
      const double dx = x - principal_point.x, dy = y - principal_point.y;
      rc2 = std::max(rc2, dx * dx + dy * dy);
    }
  if (rc2 == 0) return;  // a 1x1 image centred on the principal point: nothing falls off
  const int channels = image_f32.channels();
  for (int v = 0; v < image_f32.rows; ++v) {
    float* row = image_f32.ptr<float>(v);
    const double dy = v - principal_point.y;
    for (int u = 0; u < image_f32.cols; ++u) {
      const double dx = u - principal_point.x;
      const double f = 1.0 - strength * (dx * dx + dy * dy) / rc2;
      const float gain = static_cast<float>(f * f);
      for (int c = 0; c < channels; ++c) row[u * channels + c] *= gain;
    }
  }
}

void apply_noise(cv::Mat& image_f32, double read_sigma_dn, double shot_gain, EffectsRng& rng) {
  if (!(read_sigma_dn >= 0) || !std::isfinite(read_sigma_dn))
    fail("effects.noise_read_dn", "must be >= 0 and finite, got " + num(read_sigma_dn));
  if (!(shot_gain >= 0) || !std::isfinite(shot_gain))
    fail("effects.noise_shot_gain", "must be >= 0 and finite, got " + num(shot_gain));
  if (read_sigma_dn == 0 && shot_gain == 0) return;  // no draws: the stream stays as it was
  require_f32(image_f32, "apply_noise");
  // One 64-bit draw from the scene's stream seeds OpenCV's generator, which fills a standard
  // normal per pixel and channel (Ziggurat: ~20x faster than std::normal_distribution, which
  // cost 70 % of a closed-loop experiment). The stream advances by one draw per frame whatever
  // the image holds, so frames stay reproducible from the seed.
  cv::RNG normal_source(static_cast<std::uint64_t>(rng.engine()()));
  cv::Mat noise(image_f32.size(), image_f32.type());
  normal_source.fill(noise, cv::RNG::NORMAL, 0.0, 1.0);
  if (shot_gain == 0) {
    cv::scaleAdd(noise, read_sigma_dn, image_f32, image_f32);
    return;
  }
  // sigma = sqrt(read^2 + gain * max(signal, 0)) per pixel and channel.
  cv::Mat sigma;
  cv::max(image_f32, 0.0, sigma);
  sigma.convertTo(sigma, CV_32F, shot_gain, read_sigma_dn * read_sigma_dn);
  cv::sqrt(sigma, sigma);
  image_f32 += sigma.mul(noise);
}

cv::Mat quantize(const cv::Mat& image_f32) {
  cv::Mat out;
  image_f32.convertTo(out, CV_8U);  // rounds to nearest and saturates to [0, 255]
  return out;
}

double jittered_time(double nominal, double sigma, EffectsRng& rng) {
  if (!(sigma >= 0) || !std::isfinite(sigma))
    fail("effects.jitter_s", "must be >= 0 and finite, got " + num(sigma));
  if (sigma == 0) return nominal;
  std::normal_distribution<double> normal(0.0, sigma);
  return nominal + normal(rng.engine());
}

bool dropped(double probability, EffectsRng& rng) {
  if (!(probability >= 0 && probability <= 1))
    fail("effects.drop_probability", "must be in [0, 1], got " + num(probability));
  if (probability == 0) return false;
  std::bernoulli_distribution drop(probability);
  return drop(rng.engine());
}

}  // namespace flatland::render
