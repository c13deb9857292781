// Image effects of a real camera: exposure blur, anti-aliasing, vignetting, sensor noise,
// quantisation, timing jitter and dropped frames.
//
// The random effects draw from the caller's engine in a fixed order and draw nothing when off, so
// a scene renders the same frames for the same seed, and switching one effect off does not change
// the random numbers the others see.
#include "flatland/render/effects.hpp"
#include "flatland/sim/format.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::render {

namespace {

[[noreturn]] void fail(const std::string& what, const std::string& reason) {
  throw std::invalid_argument(what + ": " + reason);
}

void require_f32(const cv::Mat& image, const char* what) {
  if (image.empty() || image.depth() != CV_32F)
    fail(what, "expects a non-empty CV_32F image, got depth " + std::to_string(image.depth()) +
                   (image.empty() ? " (empty)" : ""));
}

}  // namespace

void FrameMean::add(const cv::Mat& f) {
  if (f.empty()) fail("average_frames", "empty sub-frame");
  if (count_ == 0) {
    sum_ = cv::Mat::zeros(f.size(), CV_MAKETYPE(CV_32F, f.channels()));
  } else if (f.size() != sum_.size() || f.channels() != sum_.channels()) {
    fail("average_frames", "sub-frames differ in size or channels");
  }
  // convertTo is a plain copy for CV_32F input; other depths (8-bit renders) are accepted too.
  f.convertTo(as_float_, CV_32F);
  sum_ += as_float_;
  ++count_;
}

cv::Mat FrameMean::finish() {
  if (count_ == 0) fail("average_frames", "no sub-frames");
  sum_ *= 1.0 / static_cast<double>(count_);
  count_ = 0;
  return std::move(sum_);
}

cv::Mat average_frames(const std::vector<cv::Mat>& subframes) {
  FrameMean mean;
  for (const cv::Mat& f : subframes) mean.add(f);
  return mean.finish();
}

cv::Mat downsample(const cv::Mat& image, int factor) {
  cv::Mat out;
  downsample(image, factor, out);
  return out;
}

void downsample(const cv::Mat& image, int factor, cv::Mat& out) {
  if (factor < 1) fail("downsample", "factor must be >= 1, got " + std::to_string(factor));
  if (factor == 1) {
    out = image;  // nothing to average: the image itself, not a copy
    return;
  }
  if (image.empty() || image.cols % factor != 0 || image.rows % factor != 0)
    fail("downsample", "image size " + std::to_string(image.cols) + " x " +
                           std::to_string(image.rows) + " is not a multiple of " +
                           std::to_string(factor));
  // INTER_AREA with an integer ratio is the exact mean over each factor x factor block.
  cv::resize(image, out, cv::Size(image.cols / factor, image.rows / factor), 0, 0, cv::INTER_AREA);
}

void apply_vignetting(cv::Mat& image_f32, double strength, cv::Point2d principal_point) {
  if (!(strength >= 0 && strength <= 1))
    fail("effects.vignetting", "must be in [0, 1], got " + sim::format_significant(strength, 9));
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

namespace {

/// SplitMix64 (Steele, Lea, Flood 2014): a fast, well-mixed 64-bit stream from a counter.
std::uint64_t splitmix64(std::uint64_t& state) {
  std::uint64_t z = (state += 0x9e3779b97f4a7c15ULL);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// Standard normal quantile (Acklam's rational approximation, refined by one Halley step on
/// erfc: ~1e-15 relative).
double normal_quantile(double p) {
  static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02,  -2.759285104469687e+02,
                             1.383577518672690e+02,  -3.066479806614716e+01, 2.506628277459239e+00};
  static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
                             6.680131188771972e+01, -1.328068155288572e+01};
  static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
                             -2.549732539343734e+00, 4.374664141464968e+00,  2.938163982698783e+00};
  static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00,
                             3.754408661907416e+00};
  double x;
  if (p < 0.02425) {
    const double q = std::sqrt(-2 * std::log(p));
    x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
        ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  } else if (p > 1 - 0.02425) {
    const double q = std::sqrt(-2 * std::log(1 - p));
    x = -(((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
        ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  } else {
    const double q = p - 0.5, r = q * q;
    x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
        (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1);
  }
  const double e = 0.5 * std::erfc(-x / std::sqrt(2.0)) - p;
  const double u = e * std::sqrt(2 * M_PI) * std::exp(x * x / 2);
  return x - u / (1 + x * u / 2);
}

}  // namespace

const float* gaussian_quantiles() {
  // The quantiles at the midpoints of 65536 equal-probability bins: a standard normal whose
  // probability is resolved to 2^-16. Tails beyond +-4.3 sigma fold into the outer bins, so the
  // variance is 1 - 3e-4 (sigma 0.99985) and the shape is otherwise exact.
  static const std::vector<float> table = [] {
    std::vector<float> t(65536);
    for (int i = 0; i < 65536; ++i) t[i] = static_cast<float>(normal_quantile((i + 0.5) / 65536.0));
    return t;
  }();
  return table.data();
}

void apply_noise(cv::Mat& image_f32, double read_sigma_dn, double shot_gain, EffectsRng& rng) {
  if (!(read_sigma_dn >= 0) || !std::isfinite(read_sigma_dn))
    fail("effects.noise_read_dn",
         "must be >= 0 and finite, got " + sim::format_significant(read_sigma_dn, 9));
  if (!(shot_gain >= 0) || !std::isfinite(shot_gain))
    fail("effects.noise_shot_gain",
         "must be >= 0 and finite, got " + sim::format_significant(shot_gain, 9));
  if (read_sigma_dn == 0 && shot_gain == 0) return;  // no draws: the stream stays as it was
  require_f32(image_f32, "apply_noise");
  // Sensor noise is a standard normal per pixel and channel, times sigma. A frame needs ~1e6 of
  // them; std::normal_distribution took 70 % of a closed-loop experiment and OpenCV's Ziggurat
  // 3.4 ms per 640 x 480 frame. Here each is one table lookup: 16 random bits index the normal's
  // quantiles at 65536 equal-probability midpoints (gaussian_quantiles). The stream is seeded by
  // one 64-bit draw from the scene's generator per frame, so frames stay reproducible and the
  // stream advances the same whatever the image holds.
  const float* quantile = gaussian_quantiles();
  std::uint64_t state = rng.engine()();
  const int n = image_f32.cols * image_f32.channels();
  const float read = static_cast<float>(read_sigma_dn);
  const float read_var = static_cast<float>(read_sigma_dn * read_sigma_dn);
  const float gain = static_cast<float>(shot_gain);
  std::uint64_t bits = 0;
  int left = 0;
  for (int v = 0; v < image_f32.rows; ++v) {
    float* row = image_f32.ptr<float>(v);
    for (int i = 0; i < n; ++i) {
      if (left == 0) {
        bits = splitmix64(state);
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

cv::Mat quantize(const cv::Mat& image_f32) {
  cv::Mat out;
  image_f32.convertTo(out, CV_8U);  // rounds to nearest and saturates to [0, 255]
  return out;
}

double jittered_time(double nominal, double sigma, EffectsRng& rng) {
  if (!(sigma >= 0) || !std::isfinite(sigma))
    fail("effects.jitter_s", "must be >= 0 and finite, got " + sim::format_significant(sigma, 9));
  if (sigma == 0) return nominal;
  std::normal_distribution<double> normal(0.0, sigma);
  return nominal + normal(rng.engine());
}

bool dropped(double probability, EffectsRng& rng) {
  if (!(probability >= 0 && probability <= 1))
    fail("effects.drop_probability",
         "must be in [0, 1], got " + sim::format_significant(probability, 9));
  if (probability == 0) return false;
  std::bernoulli_distribution drop(probability);
  return drop(rng.engine());
}

}  // namespace flatland::render
