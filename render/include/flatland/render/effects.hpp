// Image effects of a real camera, each applied only when the scene asks for it.
#pragma once

#include "flatland/scene/scene.hpp"

#include <opencv2/core.hpp>

#include <random>

namespace flatland::render {

/// Seeded source of the random effects (noise, jitter, dropped frames). Draws nothing for
/// effects that are off.
class EffectsRng {
 public:
  explicit EffectsRng(std::uint64_t seed) : engine_(seed) {}
  std::mt19937_64& engine() { return engine_; }

 private:
  std::mt19937_64 engine_;
};

/// Exposure blur as a running mean: sub-frames (same size and channels; CV_32F, other depths are
/// converted) are added one at a time, so a caller need not hold them all.
class FrameMean {
 public:
  void add(const cv::Mat& subframe);
  /// The mean of what was added (CV_32F). The sum is scaled in place and handed over: call once.
  cv::Mat finish();

 private:
  cv::Mat sum_, as_float_;
  int count_ = 0;
};
/// Average of equally weighted sub-frames (CV_32F, same size and channels), for exposure blur.
cv::Mat average_frames(const std::vector<cv::Mat>& subframes);
/// Downsample an image rendered at `factor` x the resolution by area averaging (anti-aliasing).
cv::Mat downsample(const cv::Mat& image, int factor);
/// The same into `out`, reusing its memory when its size and type fit (factor 1: `out` becomes
/// the image itself).
void downsample(const cv::Mat& image, int factor, cv::Mat& out);
/// Vignetting: multiply by (1 - strength * (r / r_corner)^2)^2 about the principal point.
void apply_vignetting(cv::Mat& image_f32, double strength, cv::Point2d principal_point);
/// Sensor noise on a float image in DN: Gaussian with variance read^2 + gain * max(signal, 0).
void apply_noise(cv::Mat& image_f32, double read_sigma_dn, double shot_gain, EffectsRng& rng);
/// The same noise on an 8-bit image, rounded and saturated back to 8 bits: bit for bit
/// quantize(apply_noise(image as float)) with the same generator state, in one pass in the cache.
void apply_noise_8u(cv::Mat& image_u8, double read_sigma_dn, double shot_gain, EffectsRng& rng);
/// 65536 standard-normal quantiles at equal-probability midpoints: 16 uniform random bits index a
/// normal variate (what apply_noise draws; public for its tests).
const float* gaussian_quantiles();
/// Round and saturate to 8 bits.
cv::Mat quantize(const cv::Mat& image_f32);
/// Any frame as 8-bit BGR, as image files and videos take it: a float frame (effects.quantize
/// false) rounded and saturated, grey or BGRA converted.
cv::Mat to_bgr8(const cv::Mat& image);
/// Capture time of frame i with timing jitter (sigma s), and whether it is dropped.
double jittered_time(double nominal, double sigma, EffectsRng& rng);
bool dropped(double probability, EffectsRng& rng);

}  // namespace flatland::render
