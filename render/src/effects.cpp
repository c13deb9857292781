// Image effects of a real camera: exposure blur, anti-aliasing, vignetting, sensor noise,
// quantisation, timing jitter and dropped frames.
//
// The random effects draw from the caller's engine in a fixed order and draw nothing when off, so
// a scene renders the same frames for the same seed, and switching one effect off does not change
// the random numbers the others see.
#include "flatland/render/effects.hpp"
#include "fail.hpp"
#include "flatland/sim/format.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::render {

namespace {

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

namespace {

void require_noise_levels(double read_sigma_dn, double shot_gain) {
  if (!(read_sigma_dn >= 0) || !std::isfinite(read_sigma_dn))
    fail("effects.noise_read_dn",
         "must be >= 0 and finite, got " + sim::format_significant(read_sigma_dn, 9));
  if (!(shot_gain >= 0) || !std::isfinite(shot_gain))
    fail("effects.noise_shot_gain",
         "must be >= 0 and finite, got " + sim::format_significant(shot_gain, 9));
}

constexpr std::uint64_t kSplitMixGamma = 0x9e3779b97f4a7c15ULL;

/// SplitMix64's output for the state after `state` (the state advanced by one gamma).
inline std::uint64_t splitmix64_next(std::uint64_t state) {
  std::uint64_t z = state + kSplitMixGamma;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

/// `words` 64-bit words of SplitMix64 from `state`, each four 16-bit indices, lowest bits first,
/// into index. SplitMix64 is a counter (the k-th output depends on state + k gamma only), so the
/// words are independent of each other: no carried dependency between iterations, and no branch.
void index_words(std::uint64_t state, std::uint16_t* index, int words) {
  for (int j = 0; j < words; ++j) {
    const std::uint64_t w = splitmix64_next(state + static_cast<std::uint64_t>(j) * kSplitMixGamma);
    if constexpr (std::endian::native == std::endian::little) {
      // The word as it lies in memory is its four indices, lowest bits first: one 8-byte store.
      // Written as four shifts, GCC vectorises the loop with SSE2's 32-bit multiplies standing in
      // for the 64-bit ones, 3 times slower (0.53 against 0.17 ms for a 640 x 480 x 3 frame).
      std::memcpy(index + 4 * j, &w, sizeof w);
    } else {
      for (int k = 0; k < 4; ++k) index[4 * j + k] = static_cast<std::uint16_t>(w >> (16 * k));
    }
  }
}

/// The noise of one frame as indices into 65536-entry tables, in the order the noise is added (row
/// by row, pixel by pixel, channel by channel): 16 random bits each, four to a SplitMix64 word, the
/// stream running on across rows. An index picks the normal's quantile at one of 65536
/// equal-probability midpoints (gaussian_quantiles), or that quantile times the read noise,
/// already rounded (rounded_offsets): the same index, so the same frame either way. Seeded by one
/// 64-bit draw from the scene's generator per frame, so frames stay reproducible and the scene's
/// stream advances the same whatever the image holds.
class IndexStream {
 public:
  explicit IndexStream(EffectsRng& rng) : state_(rng.engine()()) {}

  /// The next n indices.
  void fill(std::uint16_t* index, int n) {
    int i = 0;
    for (; i < n && left_ > 0; ++i, --left_) {
      index[i] = static_cast<std::uint16_t>(bits_);
      bits_ >>= 16;
    }
    const int words = (n - i) / 4;
    index_words(state_, index + i, words);
    state_ += static_cast<std::uint64_t>(words) * kSplitMixGamma;
    i += 4 * words;
    if (i == n) return;
    bits_ = splitmix64_next(state_);
    state_ += kSplitMixGamma;
    for (left_ = 4; i < n; ++i, --left_) {
      index[i] = static_cast<std::uint16_t>(bits_);
      bits_ >>= 16;
    }
  }

 private:
  std::uint64_t state_, bits_ = 0;
  int left_ = 0;
};

/// The next n standard normals of `stream` into z (index is scratch of n).
void fill_normals(IndexStream& stream, std::uint16_t* index, float* z, int n) {
  stream.fill(index, n);
  const float* quantile = gaussian_quantiles();
  for (int i = 0; i < n; ++i) z[i] = quantile[index[i]];
}

/// Values are noised in runs of at most this many (one row at a time, in pieces): the normals of a
/// run stay in the first-level cache between being drawn and being added.
constexpr int kRun = 2048;

/// Adds sigma * z to each of n values: sigma = read without shot noise (no square root), else
/// sqrt(read^2 + gain * max(value, 0)) of the value itself.
void add_noise(float* values, const float* z, int n, float read, float read_var, float gain) {
  if (gain == 0) {
    for (int i = 0; i < n; ++i) values[i] += read * z[i];
  } else {
    for (int i = 0; i < n; ++i)
      values[i] += std::sqrt(read_var + gain * std::max(values[i], 0.0f)) * z[i];
  }
}

}  // namespace

void apply_noise(cv::Mat& image_f32, double read_sigma_dn, double shot_gain, EffectsRng& rng) {
  require_noise_levels(read_sigma_dn, shot_gain);
  if (read_sigma_dn == 0 && shot_gain == 0) return;  // no draws: the stream stays as it was
  require_f32(image_f32, "apply_noise");
  // Sensor noise is a standard normal per pixel and channel, times sigma. A frame needs ~1e6 of
  // them; std::normal_distribution took 70 % of a closed-loop experiment and OpenCV's Ziggurat
  // 3.4 ms per 640 x 480 frame. Here each is one table lookup (IndexStream).
  IndexStream normals(rng);
  std::uint16_t index[kRun];
  float z[kRun];
  const int n = image_f32.cols * image_f32.channels();
  const float read = static_cast<float>(read_sigma_dn);
  const float read_var = static_cast<float>(read_sigma_dn * read_sigma_dn);
  const float gain = static_cast<float>(shot_gain);
  for (int v = 0; v < image_f32.rows; ++v) {
    float* row = image_f32.ptr<float>(v);
    for (int i = 0; i < n; i += kRun) {
      const int len = std::min(kRun, n - i);
      fill_normals(normals, index, z, len);
      add_noise(row + i, z, len, read, read_var, gain);
    }
  }
}

namespace {

/// Rounds to the nearest whole number, ties to even (as cvRound and quantize), and saturates to
/// [0, 255], branch-free so that the loop around it vectorises: adding 1.5 * 2^23 leaves the whole
/// number in the low mantissa bits, rounded by the processor's own round-to-nearest-even. Exact for
/// |x| < 2^22 (apply_noise_8u's caller keeps within kLargestValue).
inline std::uint8_t round_to_u8(float x) {
  const float shifted = x + 12582912.0f;  // 1.5 * 2^23
  std::int32_t rounded;
  std::memcpy(&rounded, &shifted, sizeof rounded);
  rounded -= 0x4b400000;
  rounded = rounded < 0 ? 0 : rounded;
  return static_cast<std::uint8_t>(rounded > 255 ? 255 : rounded);
}

/// Below this, value plus noise is within round_to_u8's range (2^22) even at 10 sigma.
constexpr double kLargestValue = 4.0e6;

/// Read noise up to this sigma has its rounded offsets within an int8 (4.3 sigma < 127).
constexpr float kLargestTabledRead = 28.0f;

/// Read noise alone on whole-number levels, rounded: for each of the 65536 quantile indices the
/// whole number d with round_to_u8(level + read * quantile) == clamp(level + d, 0, 255) at every
/// level 0..255, found by trying them all. Where there is none (the sum lands within float
/// rounding of a half and the tie goes to the even level: 2 indices at 0.5 DN, none at 1, 1.5, 2,
/// 3, 8 or 28 DN) the offset is 0 and the index is listed in `level_dependent`.
struct RoundedOffsets {
  std::vector<std::int8_t> offset = std::vector<std::int8_t>(65536);
  std::vector<std::uint16_t> level_dependent;
};

/// Built once per sigma (17 million sums, a few ms) and kept: a run's frames share it, as do a
/// Monte Carlo's worlds with the same sensor.
std::shared_ptr<const RoundedOffsets> rounded_offsets(float read) {
  static std::mutex mutex;
  static std::map<float, std::shared_ptr<const RoundedOffsets>> built;
  const std::lock_guard<std::mutex> lock(mutex);
  if (const auto it = built.find(read); it != built.end()) return it->second;
  const float* quantile = gaussian_quantiles();
  auto table = std::make_shared<RoundedOffsets>();
  for (int k = 0; k < 65536; ++k) {
    const float noise = read * quantile[k];
    const int d = static_cast<int>(std::nearbyint(noise));
    int differ = 0;
    for (int level = 0; level < 256; ++level)
      differ += round_to_u8(static_cast<float>(level) + noise) != std::clamp(level + d, 0, 255);
    if (differ == 0)
      table->offset[k] = static_cast<std::int8_t>(d);
    else
      table->level_dependent.push_back(static_cast<std::uint16_t>(k));
  }
  if (built.size() >= 8) built.erase(built.begin());  // sensors in one process: a handful
  return built.emplace(read, std::move(table)).first->second;
}

/// apply_noise_8u with read noise alone: each value's offset is looked up already rounded
/// (rounded_offsets, a 64 KB table where the float quantiles take 256 KB) from the same index
/// stream and added with saturation in a loop that vectorises; an offset that depends on the level
/// is computed as apply_noise computes it.
void add_rounded_read_noise(cv::Mat& image_u8, float read, EffectsRng& rng) {
  const auto table = rounded_offsets(read);
  const std::int8_t* offsets = table->offset.data();
  const float* quantile = gaussian_quantiles();
  IndexStream stream(rng);
  std::uint16_t index[kRun];
  std::int8_t d[kRun];
  const int n = image_u8.cols * image_u8.channels();
  for (int v = 0; v < image_u8.rows; ++v) {
    std::uint8_t* row = image_u8.ptr<std::uint8_t>(v);
    for (int i = 0; i < n; i += kRun) {
      const int len = std::min(kRun, n - i);
      stream.fill(index, len);
      for (int k = 0; k < len; ++k) d[k] = offsets[index[k]];
      std::uint8_t* values = row + i;
      for (int k = 0; k < len; ++k) {
        const int sum = values[k] + d[k];
        values[k] = static_cast<std::uint8_t>(sum < 0 ? 0 : (sum > 255 ? 255 : sum));
      }
      for (const std::uint16_t dependent : table->level_dependent) {
        int hits = 0;
        for (int k = 0; k < len; ++k) hits += index[k] == dependent;
        if (hits == 0) continue;
        for (int k = 0; k < len; ++k)  // offset 0 above: the value is still the render's
          if (index[k] == dependent)
            values[k] = round_to_u8(static_cast<float>(values[k]) + read * quantile[dependent]);
      }
    }
  }
}

}  // namespace

void apply_noise_8u(cv::Mat& image_u8, double read_sigma_dn, double shot_gain, EffectsRng& rng) {
  require_noise_levels(read_sigma_dn, shot_gain);
  if (read_sigma_dn == 0 && shot_gain == 0) return;
  if (image_u8.empty() || image_u8.depth() != CV_8U)
    fail("apply_noise_8u", "expects a non-empty CV_8U image, got depth " +
                               std::to_string(image_u8.depth()) +
                               (image_u8.empty() ? " (empty)" : ""));
  // The same frame as quantize() of apply_noise() on the image as floats, bit for bit: the same
  // normals in the same order and the same float arithmetic on each value, converted, noised and
  // rounded in one pass while its run is in the cache, instead of three passes over a float frame
  // 4 times the size.
  if (255 + 10 * std::sqrt(read_sigma_dn * read_sigma_dn + shot_gain * 255) > kLargestValue) {
    cv::Mat floats;  // noise far beyond the 8-bit range: the general path
    image_u8.convertTo(floats, CV_32F);
    apply_noise(floats, read_sigma_dn, shot_gain, rng);
    floats.convertTo(image_u8, CV_8U);
    return;
  }
  const int n = image_u8.cols * image_u8.channels();
  const float read = static_cast<float>(read_sigma_dn);
  const float read_var = static_cast<float>(read_sigma_dn * read_sigma_dn);
  const float gain = static_cast<float>(shot_gain);
  if (gain == 0 && read <= kLargestTabledRead) {
    add_rounded_read_noise(image_u8, read, rng);
    return;
  }
  IndexStream normals(rng);
  std::uint16_t index[kRun];
  float z[kRun];
  // Shot noise's sigma of each of the 256 levels, computed once as add_noise computes it.
  float sigma_of_level[256];
  for (int level = 0; level < 256; ++level)
    sigma_of_level[level] = std::sqrt(read_var + gain * std::max(static_cast<float>(level), 0.0f));
  for (int v = 0; v < image_u8.rows; ++v) {
    std::uint8_t* row = image_u8.ptr<std::uint8_t>(v);
    for (int i = 0; i < n; i += kRun) {
      const int len = std::min(kRun, n - i);
      fill_normals(normals, index, z, len);
      std::uint8_t* values = row + i;
      if (gain == 0) {  // read noise beyond rounded_offsets' range
        for (int k = 0; k < len; ++k)
          values[k] = round_to_u8(static_cast<float>(values[k]) + read * z[k]);
      } else {
        for (int k = 0; k < len; ++k)
          values[k] = round_to_u8(static_cast<float>(values[k]) + sigma_of_level[values[k]] * z[k]);
      }
    }
  }
}

cv::Mat quantize(const cv::Mat& image_f32) {
  cv::Mat out;
  image_f32.convertTo(out, CV_8U);  // rounds to nearest and saturates to [0, 255]
  return out;
}

cv::Mat to_bgr8(const cv::Mat& image) {
  cv::Mat out = image;
  if (out.depth() != CV_8U) out.convertTo(out, CV_8U);
  if (out.channels() == 1) cv::cvtColor(out, out, cv::COLOR_GRAY2BGR);
  if (out.channels() == 4) cv::cvtColor(out, out, cv::COLOR_BGRA2BGR);
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
