// flatland track: follow the disk through a video or an image sequence and write its centre per
// frame (px, with uncertainty and track state) and, given the hand angle per frame, the contact
// parameter s_h through the camera file's calibration (docs/VISION.md).
#include "common.hpp"

#include "flatland/camera/camera_file.hpp"
#include "flatland/model/model.hpp"
#include "flatland/vision/image_file.hpp"
#include "flatland/vision/mapping.hpp"
#include "flatland/vision/tracker.hpp"
#include "flatland/vision/video_reader.hpp"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

#include <stdlib.h>

namespace flatland::app {

namespace {

struct TrackOptions {
  std::string scene, video, images, camera, out, method = "edge", encoder;
  bool force = false;
  bool json = false;
  double fps = 0;
  double min_quality = 0.5;
  double exposure = 0;  // s
  bool interlaced = false;
  CLI::Option* fps_opt = nullptr;
};

const char* kTrackColumns = "frame,t,u,v,sigma_px,quality,state,s_h";
/// A truncated video fails every read after the cut: one warning per frame up to this many.
constexpr long kMaxSkipWarnings = 10;

/// Frames by what became of them, with a warning per untrusted frame (up to kMaxSkipWarnings of
/// each kind).
struct FrameCounts {
  long frames = 0, found = 0, lost = 0, low_quality = 0;  // frames: those tracked
  long unreadable = 0, repeated = 0, damaged = 0;
  void count(vision::FrameIntegrity integrity, long index, const std::string& video) {
    long* n = integrity == vision::FrameIntegrity::kRepeated  ? &repeated
              : integrity == vision::FrameIntegrity::kDamaged ? &damaged
                                                              : &unreadable;
    ++*n;
    if (video.empty() && integrity == vision::FrameIntegrity::kUnreadable) return;  // warned
    const std::string what =
        integrity == vision::FrameIntegrity::kRepeated ? "repeats the frame before (same "
                                                         "pixels or timestamp); not measured"
        : integrity == vision::FrameIntegrity::kDamaged
            ? "damaged (the decoder reported an error in it or in a frame it depends on); not "
              "measured"
            : "cannot be decoded; skipped";
    const std::string source = video.empty() ? "--images" : "--video: " + video;
    if (*n <= kMaxSkipWarnings)
      std::cerr << "flatland: warning: " << source << ": frame " << index << " " << what << "\n";
    if (*n == kMaxSkipWarnings)
      std::cerr << "flatland: warning: " << source << ": further " << vision::to_string(integrity)
                << " frames not reported\n";
  }
};

/// Every frame must be the camera file's size: its K describes that image and no other.
void check_frame_size(const cv::Mat& image, const camera::CameraModel& camera,
                      const std::string& camera_path) {
  if (image.cols != camera.width || image.rows != camera.height)
    throw UsageError("frames are " + std::to_string(image.cols) + " x " +
                     std::to_string(image.rows) + " px but " + camera_path + " describes a " +
                     std::to_string(camera.width) + " x " + std::to_string(camera.height) +
                     " px camera");
}

/// Encoder log: rows "t,theta" (s, rad), strictly increasing t; a header line is skipped.
struct EncoderLog {
  std::vector<double> t, theta;
  /// Linear interpolation; nullopt outside the logged interval (no extrapolation).
  std::optional<double> at(double time) const {
    if (t.empty() || time < t.front() || time > t.back()) return std::nullopt;
    if (t.size() == 1) return theta.front();
    const auto it = std::upper_bound(t.begin(), t.end(), time);
    const std::size_t i = std::min<std::size_t>(
        t.size() - 2, static_cast<std::size_t>(std::max<std::ptrdiff_t>(0, it - t.begin() - 1)));
    const double w = (time - t[i]) / (t[i + 1] - t[i]);
    return theta[i] + w * (theta[i + 1] - theta[i]);
  }
};

// An encoder log of an hour at 1 kHz is ~3.6 M rows of ~30 bytes; a row is a few numbers.
constexpr std::size_t kMaxEncoderBytes = std::size_t{512} << 20;
constexpr std::size_t kMaxEncoderLine = 4096;

EncoderLog read_encoder(const std::string& path) {
  std::ifstream in(path);
  if (!in || std::filesystem::is_directory(path))
    throw UsageError("--encoder: cannot read " + path);
  EncoderLog log;
  std::string line;
  int line_no = 0;
  std::size_t bytes = 0;
  // Reads line by line with a bound on each line and on the whole file, so that a device or a
  // binary file is refused without being read into memory.
  while (true) {
    line.clear();
    int c = 0;
    while ((c = in.get()) != EOF && c != '\n') {
      if (line.size() >= kMaxEncoderLine)
        throw UsageError("--encoder: " + path + ":" + std::to_string(line_no + 1) +
                         ": a line longer than 4096 bytes (expected rows t,theta)");
      line += static_cast<char>(c);
    }
    if (c == EOF && line.empty()) break;
    bytes += line.size() + 1;
    if (bytes > kMaxEncoderBytes)
      throw UsageError("--encoder: " + path + " is larger than 512 MiB (expected rows t,theta)");
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream is(line);
    double t = 0, theta = 0;
    if (!(is >> t >> theta)) {
      if (line_no == 1) continue;  // header
      throw UsageError("--encoder: " + path + ":" + std::to_string(line_no) +
                       ": expected two numbers t,theta");
    }
    if (!std::isfinite(t) || !std::isfinite(theta))
      throw UsageError("--encoder: " + path + ":" + std::to_string(line_no) + ": not finite");
    if (!log.t.empty() && !(t > log.t.back()))
      throw UsageError("--encoder: " + path + ":" + std::to_string(line_no) +
                       ": times must increase strictly");
    log.t.push_back(t);
    log.theta.push_back(theta);
  }
  if (log.t.empty()) throw UsageError("--encoder: " + path + " has no rows t,theta");
  return log;
}

void run_track(const TrackOptions& o) {
  // ---- everything that can be bad input, before any frame is read
  if (o.video.empty() == o.images.empty())
    throw UsageError("exactly one of --video FILE or --images GLOB is required");
  if (o.out.empty()) throw UsageError("--out: required (FILE.csv)");
  const fs::path out = o.out;
  if (o.out.back() == '/' || fs::is_directory(out))
    throw UsageError("--out: must be a file name (FILE.csv), not a directory: " + o.out);
  check_output_file("--out", out, o.force);
  const vision::TrackMethod method = vision::parse_track_method(o.method);
  const camera::CameraFile camfile = camera::read_camera_file(o.camera);
  const camera::CameraModel& camera = camfile.camera;
  // Sections that calibrate --force wrote although their data did not support them.
  for (const std::string& mark : camfile.unsupported)
    std::cerr << "flatland: warning: " << o.camera << ": unsupported calibration, written with "
              << "--force: " << mark << "\n";
  if (o.fps_opt->count()) require_positive("--fps", o.fps, "frames per s");
  if (!(o.min_quality >= 0 && o.min_quality <= 1))
    throw UsageError("--min-quality: must be in [0, 1], got " + format_number(o.min_quality));
  if (!(o.exposure >= 0) || !std::isfinite(o.exposure))
    throw UsageError("--exposure: must be a finite time >= 0 s, got " + format_number(o.exposure));

  CommonOptions common;
  common.scene = o.scene;
  const Scene scene = load_scene_with_overrides(common);
  // The tracker's model is a solid disk's face: an object it cannot follow is refused up front,
  // not tracked into a biased centre.
  if (const auto problem = model::tracking_problem(scene.sim.object))
    throw UsageError(scene.origin + ": " + *problem);
  std::optional<EncoderLog> encoder;
  std::optional<vision::HandMapping> mapping;
  if (!o.encoder.empty()) {
    if (!camfile.has_table_pose)
      throw UsageError("--encoder: " + o.camera +
                       " has no table pose (needed to map pixels to the table for s_h)");
    encoder = read_encoder(o.encoder);
    mapping = model::hand_mapping(*model::compile(scene), camera,
                                  camfile.joint ? camfile.joint->axis_table : cv::Point2d(0, 0));
  }

  std::vector<std::string> files;
  std::optional<vision::VideoReader> video;
  vision::TrackerConfig cfg;
  cfg.method = method;
  if (camfile.has_table_pose) {
    // With the pose known the edge method fits the circle on the table plane: exact through an
    // oblique view and lens distortion (docs/VISION.md).
    cfg.camera = camera;
    cfg.plane_z = scene.render.disk_thickness;
  }
  long total = 0;
  double fps = camera.fps > 0 ? camera.fps : 30.0;
  if (!o.images.empty()) {
    files = expand_file_patterns({o.images}, "--images");
    total = static_cast<long>(files.size());
  } else {
    if (!fs::is_regular_file(o.video)) throw UsageError("--video: no such file: " + o.video);
    std::error_code ec;
    if (fs::file_size(o.video, ec) == 0 && !ec)
      throw UsageError("--video: " + o.video + ": zero-length file");
    try {
      video.emplace(o.video);
    } catch (const std::invalid_argument& e) {
      throw UsageError(std::string("--video: ") + e.what());
    }
    total = video->frame_count();
    const double vfps = video->fps();
    if (vfps > 0 && std::isfinite(vfps)) fps = vfps;
  }
  if (o.fps_opt->count()) fps = o.fps;
  if (o.exposure > 1.0 / fps)
    throw UsageError("--exposure: " + format_number(o.exposure) +
                     " s is longer than the interval between frames (1/" + format_number(fps) +
                     " fps = " + format_number(1.0 / fps) + " s)");
  // The image shows the disk's mean position over the exposure (and an interlaced frame's two
  // fields), the time stamp is mid-exposure: the tracker takes the difference off on a curved
  // path (docs/VISION.md, "The centre at the time stamp").
  cfg.image_time_variance_frames2 =
      vision::image_time_variance_frames2(o.exposure, 1.0 / fps, o.interlaced, 1.0 / fps);

  // ---- track
  vision::Tracker tracker(cfg);
  vision::RepeatCheck repeat;  // image sequences; a video's reader checks its own
  std::string csv = std::string(kTrackColumns) + "\n";
  FrameCounts n;
  double sigma2 = 0;
  double s_guess = NAN;  // previous s_h; NaN: none (first frame, after a loss)
  {
    ProgressBar bar("track");
    for (long i = 0;; ++i) {
      vision::VideoReader::Frame frame;
      if (!files.empty()) {
        if (i >= total) break;
        std::string why;
        const std::string& file = files[static_cast<std::size_t>(i)];
        frame.image = vision::read_image_file(file, cv::IMREAD_COLOR, why);
        if (frame.image.empty()) {
          std::cerr << "flatland: warning: skipping unreadable image " << file << " (" << why
                    << ")\n";
          frame.integrity = vision::FrameIntegrity::kUnreadable;
        } else if (repeat.repeated(frame.image)) {
          frame.integrity = vision::FrameIntegrity::kRepeated;
        }
      } else if (!video->read(frame)) {
        break;
      }
      const double t = static_cast<double>(i) / fps;
      const std::string head = std::to_string(i) + "," + format_number(t) + ",";
      bar.update(i + 1, std::max(total, i + 1));
      if (!frame.image.empty()) check_frame_size(frame.image, camera, o.camera);
      if (frame.integrity != vision::FrameIntegrity::kIntact) {
        // No measurement from a frame that brings no new, trustworthy picture.
        n.count(frame.integrity, i, o.video);
        if (frame.integrity == vision::FrameIntegrity::kUnreadable) s_guess = NAN;
        tracker.skip();
        csv += head + ",,,," + vision::to_string(frame.integrity) + ",\n";
        continue;
      }
      const vision::TrackResult r = tracker.track(frame.image);
      ++n.frames;
      if (!r.ok()) {
        ++n.lost;
        s_guess = NAN;
        csv += head + ",,,0,lost,\n";
        continue;
      }
      std::string row = head + format_number(r.center.x) + "," + format_number(r.center.y) + "," +
                        format_number(r.sigma_px) + "," + format_number(r.quality) + ",";
      if (r.quality < o.min_quality) {
        // Kept for inspection, but not a measurement: no s_h, and state says why.
        ++n.low_quality;
        csv += row + "low_quality,\n";
        continue;
      }
      ++n.found;
      sigma2 += r.sigma_px * r.sigma_px;
      row += std::string(vision::to_string(r.state)) + ",";
      std::optional<double> theta = encoder ? encoder->at(t) : std::nullopt;
      if (mapping && theta) {
        const double offset = camfile.joint ? camfile.joint->encoder_offset : 0.0;
        const auto c = vision::follow_contact(*mapping, r.center, *theta + offset, s_guess);
        if (c) {
          row += format_number(c->s_h);
          s_guess = c->s_h;
        }
      }
      csv += row + "\n";
    }
  }
  const long frames = n.frames, found = n.found, lost = n.lost, skipped = n.unreadable;
  if (frames == 0)
    throw UsageError(std::string(files.empty() ? "--video: " + o.video : "--images: " + o.images) +
                     ": no readable frame");

  OutputSet outputs(o.force);
  outputs.ensure_directory(out.parent_path());
  outputs.stage(out, csv);
  outputs.commit();

  const double rms_sigma = found > 0 ? std::sqrt(sigma2 / static_cast<double>(found)) : NAN;
  if (o.json) {
    Json j;
    j["frames"] = frames;
    j["found"] = found;
    j["lost"] = lost;
    j["skipped"] = skipped;
    j["unreadable"] = n.unreadable;
    j["repeated"] = n.repeated;
    j["damaged"] = n.damaged;
    j["low_quality"] = n.low_quality;
    j["min_quality"] = o.min_quality;
    j["exposure_s"] = o.exposure;
    j["interlaced"] = o.interlaced;
    j["rms_sigma_px"] = number(rms_sigma);
    j["method"] = vision::to_string(method);
    j["fit"] = cfg.camera && method == vision::TrackMethod::kEdge ? "table-plane" : "pixel";
    j["output"] = out.string();
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland track: " << (files.empty() ? o.video : o.images) << "\n"
     << "  method             " << vision::to_string(method)
     << (cfg.camera && method == vision::TrackMethod::kEdge ? " (circle fitted on the table plane)"
                                                            : "")
     << "\n"
     << "  frames             " << frames << " (" << found << " with the disk, " << lost
     << " lost, " << n.low_quality << " below quality " << format_number(o.min_quality) << ")"
     << " at " << format_number(fps) << " fps\n"
     << "  image time         "
     << (o.exposure > 0 || o.interlaced
             ? "exposure " + format_number(o.exposure) + " s" +
                   (o.interlaced ? ", interlaced" : "") +
                   ": centres taken to the frames' mid-exposure time"
             : std::string("instant (no --exposure)"))
     << "\n"
     << "  not measured       " << n.unreadable << " unreadable, " << n.repeated << " repeated, "
     << n.damaged << " damaged\n"
     << "  rms sigma          " << format_number(rms_sigma) << " px\n"
     << "  s_h                "
     << (mapping ? "from " + o.encoder : std::string("not computed (no --encoder)")) << "\n"
     << "  wrote              " << out.string() << "\n";
  std::cout << os.str();
}

}  // namespace

Command add_track_command(CLI::App& app) {
  auto o = std::make_shared<TrackOptions>();
  CLI::App* cmd = add_command(app, "track");
  cmd->add_option("--video", o->video, "Input video file (anything OpenCV's FFmpeg backend reads)")
      ->type_name("FILE");
  cmd->add_option("--images", o->images,
                  "Input images: a shell pattern, quoted (e.g. 'run/frame_*.png'), taken in name "
                  "order; unreadable files are skipped with a warning")
      ->type_name("GLOB");
  cmd->add_option("--camera", o->camera,
                  "Camera file (flatland calibrate's YAML: K, distortion, table pose, joint). "
                  "Required")
      ->type_name("FILE")
      ->required();
  add_force_option(*cmd, o->force);
  cmd->add_option("--out", o->out, "Output CSV (" + std::string(kTrackColumns) + "). Required")
      ->type_name("FILE.csv")
      ->required();
  cmd->add_flag(
      "--json", o->json,
      "Print exactly one JSON object on stdout ({frames, found, lost, skipped, unreadable, "
      "repeated, damaged, low_quality, min_quality, exposure_s, interlaced, fit, rms_sigma_px, "
      "method, output}); logs go to stderr. Default: off");
  o->fps_opt =
      cmd->add_option("--fps", o->fps,
                      "Frame rate for the time column, frames per s (> 0); t = frame "
                      "index / fps. Default: the video's, else the camera file's, else 30");
  cmd->add_option("--exposure", o->exposure,
                  "The camera's exposure time, s (in [0, 1/fps]). The image shows the disk's mean "
                  "position over it; the tracker takes each centre to the frame's time stamp "
                  "(mid-exposure) on a curved path. Default: 0 (an instant)")
      ->type_name("SECONDS");
  cmd->add_flag("--interlaced", o->interlaced,
                "Each frame is two interlaced fields half a frame apart (a 30 Hz analogue "
                "camera): the centre is taken to the frame's time stamp as for --exposure. "
                "Default: off");
  cmd->add_option("--min-quality", o->min_quality,
                  "Quality below which a found disk is not a measurement: its row keeps u, v, "
                  "sigma_px and quality but says low_quality and gets no s_h. In [0, 1]; "
                  "clean frames score about 0.95, frames a decoder patched 0.1-0.5. Default: 0.5");
  cmd->add_option("--method", o->method,
                  "Tracker: edge (sub-pixel face/O-ring edge + robust circle fit), moments "
                  "(coverage-weighted moments), hough (cv::HoughCircles baseline) or contour (the "
                  "OpenCV contour peer: Otsu, findContours, fitEllipse). Default: edge")
      ->check(CLI::IsMember({"edge", "moments", "hough", "contour"}));
  cmd->add_option("--encoder", o->encoder,
                  "Hand angle log, CSV rows t,theta (s, rad; optional header), interpolated at "
                  "each frame time; enables the s_h column (needs the camera file's table pose)")
      ->type_name("FILE");
  cmd->add_option("--scene", o->scene,
                  "Scene file for the hand shape, disk radius and disk thickness used by the s_h "
                  "mapping. Default: the bundled paper butterfly, " +
                      default_scene_path())
      ->type_name("FILE");
  return {cmd, [o] { run_track(*o); }};
}

}  // namespace flatland::app
