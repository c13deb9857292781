// flatland.Env's native half: one synthetic experiment (drivers::run_synthetic's world, camera,
// joint and clock) driven a tick at a time through drivers::Loop's sense() and act(), the
// caller's action in place of a controller. reset() runs the waiting phase (t < 0: the hand at
// rest while the estimator locks on) and stops at the first tick at t >= 0; step() commands the
// action for ticks_per_step ticks. The episode ends when the loop stops safely (the disk left the
// hand, the camera or tracking was lost, ...), when the motion's time is up (the hand is then held
// at the plan's final angle, as the paper's controller holds it, and the experiment judged as
// run_synthetic judges it), or, truncated, at the time limit. The Gymnasium side (spaces, reward,
// argument checks) is Python's: flatland/__init__.py.
#include "convert.hpp"
#include "python_loop.hpp"

#include "flatland/drivers/experiment.hpp"
#include "flatland/drivers/synthetic.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/sim/format.hpp"

#include <pybind11/stl.h>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <utility>

namespace flatland::python {

using namespace pybind11::literals;

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

enum class Observation { kImage, kMeasurement, kState };

Observation parse_observation(const std::string& name) {
  if (name == "image") return Observation::kImage;
  if (name == "measurement") return Observation::kMeasurement;
  if (name == "state") return Observation::kState;
  throw std::invalid_argument("observation: must be image, measurement or state, got '" + name +
                              "'");
}

/// The observation vectors' entries, in order.
const std::vector<std::string>& observation_names(Observation kind) {
  static const std::vector<std::string> measurement = {
      "t",         "theta", "theta_dot", "s_meas",      "sigma_meas",
      "t_capture", "s_est", "sdot_est",  "sigma_s_est", "sigma_sdot_est"};
  static const std::vector<std::string> state = {"theta", "theta_dot", "s_h", "sdot_h"};
  static const std::vector<std::string> none;
  return kind == Observation::kMeasurement ? measurement
         : kind == Observation::kState     ? state
                                           : none;
}

/// One episode: the synthetic world and the loop over it, with no controller (the caller
/// commands). Not movable: the loop's frame callback points into it.
struct Episode {
  Episode(const drivers::LoopSetup& setup, std::shared_ptr<const model::Model> truth_model)
      : truth(std::move(truth_model)),
        world(truth, options.t_start),
        clock(&world, options.t_start),
        joint(world, truth->spec.faults),
        camera(truth, world, options.t_start) {
    options.world = &world;
    options.on_frame = [this](const drivers::CameraFrame& frame, const vision::TrackResult&,
                              const std::optional<control::Measurement>& z) {
      // A copy: the observation outlives the camera's buffers.
      if (!frame.image.empty()) {
        // Into a new buffer: the last one may be an observation the caller still holds.
        cv::Mat bgr;
        if (frame.image.channels() == 1)
          cv::cvtColor(frame.image, bgr, cv::COLOR_GRAY2BGR);
        else
          bgr = frame.image.clone();
        last_frame = bgr;
        ++frames_kept;
      }
      if (z) latest = z;
    };
    loop = std::make_unique<drivers::Loop>(setup, clock, camera, joint, options, nullptr,
                                           setup.make_estimator(setup.model->paper_plant));
  }
  Episode(const Episode&) = delete;
  Episode& operator=(const Episode&) = delete;

  std::shared_ptr<const model::Model> truth;
  drivers::LoopOptions options;  // before the world: its t_start is theirs
  drivers::SimWorld world;
  drivers::SimClock clock;
  drivers::SimJoint joint;
  drivers::SyntheticCamera camera;
  std::unique_ptr<drivers::Loop> loop;

  /// The tick the last observation is of (sensed, not yet acted on while the episode runs).
  control::ControlInput input;
  drivers::WorldSample truth_now;
  bool measured_now = false;  ///< a measurement was folded in at that tick
  long steps = 0;
  cv::Mat last_frame;  ///< the latest frame received, BGR
  long frames_kept = 0;
  std::optional<control::Measurement> latest;  ///< the latest measurement
  // What the observation's tick had received (the end of an episode runs the loop on).
  cv::Mat frame_seen;
  long frames_seen = 0;
  std::optional<control::Measurement> latest_seen;
  bool terminated = false, truncated = false;
  std::string ended_by;  ///< "disk", "safe-stop", "motion-end", "time-limit"
  std::optional<drivers::SyntheticResult> result;
};

class PyEnv {
 public:
  PyEnv(const py::object& scene_arg, const std::string& observation, long ticks_per_step,
        std::optional<double> duration, std::optional<double> time_limit,
        const py::object& estimator)
      : observation_(parse_observation(observation)), ticks_per_step_(ticks_per_step) {
    if (ticks_per_step < 1 || ticks_per_step > 1000000)
      throw std::invalid_argument("ticks_per_step: must be in [1, 1000000], got " +
                                  std::to_string(ticks_per_step));
    Scene scene = experiment_scene(scene_arg);
    const LoopChoice choice = choose_loop(scene, py::none(), estimator);
    nominal_ = model::compile(scene);
    drivers::require_friction(scene);
    setup_ = std::make_unique<drivers::LoopSetup>(nominal_, drivers::ControllerFactory{},
                                                  choice.estimator);
    const double plan_duration = setup_->plan.plan->duration();
    motion_end_ = duration.value_or(plan_duration);
    if (!(std::isfinite(motion_end_) && motion_end_ > 0))
      throw std::invalid_argument("duration: must be positive and finite (s), got " +
                                  sim::format_number(motion_end_));
    if (time_limit && !(std::isfinite(*time_limit) && *time_limit > 0))
      throw std::invalid_argument("time_limit: must be positive and finite (s), got " +
                                  sim::format_number(*time_limit));
    time_limit_ = time_limit;
    next_seed_ = nominal_->spec.effects.seed;
    truth_ = nominal_;
  }

  py::tuple reset(std::optional<std::uint64_t> seed) {
    const std::uint64_t s = seed.value_or(next_seed_);
    next_seed_ = s + 1;
    if (truth_->spec.effects.seed != s) {
      Scene scene = nominal_->spec;
      scene.effects.seed = s;
      truth_ = model::compile(scene);
    }
    episode_.reset();  // its renderer's GL context first
    {
      py::gil_scoped_release release;
      auto e = std::make_unique<Episode>(*setup_, truth_);
      wait_for_start(*e);
      episode_ = std::move(e);
    }
    return py::make_tuple(observe(), info());
  }

  /// (observation, terminated, truncated, info); the reward is Python's.
  py::tuple step(double action) {
    if (!episode_) throw std::runtime_error("Env.step: call reset() first");
    Episode& e = *episode_;
    if (e.terminated || e.truncated)
      throw std::runtime_error("Env.step: the episode has ended (" + e.ended_by +
                               "): call reset()");
    try {
      py::gil_scoped_release release;
      control::ControlOutput out;
      out.theta_ddot = action;
      out.mode = "action";
      out.theta_reference = kNaN;
      for (long i = 0; i < ticks_per_step_; ++i) {
        e.loop->act(out);
        if (!sense(e)) {  // the loop ended on its own (not expected before one of the ends)
          e.terminated = true;
          e.ended_by = "loop";
          e.result = drivers::judge_synthetic(e.loop->finish(), e.world, e.camera);
          break;
        }
        if (ended(e)) break;
      }
      ++e.steps;
    } catch (...) {
      episode_.reset();  // half a tick done: nothing to go on with
      throw;
    }
    return py::make_tuple(observe(), e.terminated, e.truncated, info());
  }

  /// The latest camera frame at the observation's tick as RGB (Gymnasium's rgb_array), or None
  /// before the first.
  py::object render() const {
    if (!episode_ || episode_->frame_seen.empty()) return py::none();
    cv::Mat rgb;
    cv::cvtColor(episode_->frame_seen, rgb, cv::COLOR_BGR2RGB);
    return image_to_numpy(rgb);
  }

  py::dict log() const {
    if (!episode_) throw std::runtime_error("Env.log: call reset() first");
    return log_columns(episode_->loop->result().log);
  }

  void close() { episode_.reset(); }

  py::dict description() const {
    py::dict d;
    const CameraSpec& camera = *nominal_->spec.camera;
    d["observation_names"] = observation_names(observation_);
    d["image_shape"] = py::make_tuple(camera.height, camera.width, 3);
    d["fps"] = camera.fps;
    d["dt"] = nominal_->control_dt;
    const JointSpec& joint = nominal_->spec.joint;
    d["max_acceleration"] = joint.torque_limit / joint.inertia;
    d["duration"] = motion_end_;
    d["time_limit"] = time_limit_ ? py::object(py::float_(*time_limit_)) : py::object(py::none());
    d["scene"] = nominal_->spec.origin;
    return d;
  }

  std::shared_ptr<control::Plan> plan() const {
    return std::const_pointer_cast<control::Plan>(setup_->plan.plan);
  }

 private:
  /// Begins the next tick; false once the loop has ended.
  bool sense(Episode& e) const {
    const control::ControlInput* input = e.loop->sense();
    if (!input) return false;
    e.input = *input;
    e.measured_now = input->measurement.has_value();
    e.truth_now = e.world.state_at(input->t);
    e.frame_seen = e.last_frame;
    e.frames_seen = e.frames_kept;
    e.latest_seen = e.latest;
    return true;
  }

  /// The hand at rest while the estimator locks on (the paper's controller's waiting stage),
  /// up to the first tick at t >= 0.
  void wait_for_start(Episode& e) const {
    const control::Plan& plan = *setup_->plan.plan;
    while (sense(e) && e.input.t < 0) {
      control::ControlOutput out;
      out.mode = "waiting";
      out.theta_reference = plan.hand(0.0).angle;
      e.loop->act(out);
    }
    if (e.loop->stopping() || e.input.t < 0)
      throw std::runtime_error("Env.reset: the loop stopped before t = 0 (" +
                               (e.loop->result().stop_reason ? e.loop->result().stop_reason->detail
                                                             : std::string("it ended")) +
                               ")");
  }

  /// After sense(): whether the episode ends at this tick; a terminated one is run to its end
  /// and judged.
  bool ended(Episode& e) const {
    if (e.loop->stopping()) {
      e.ended_by = e.world.failure() ? "disk" : "safe-stop";
      wind_down(e, false);
      return true;
    }
    if (e.input.t >= motion_end_) {
      e.ended_by = "motion-end";
      wind_down(e, true);
      return true;
    }
    if (time_limit_ && e.input.t >= *time_limit_) {
      e.ended_by = "time-limit";
      e.truncated = true;
      return true;
    }
    return false;
  }

  /// Runs the loop to its end from the tick sensed: the hand held at the plan's final angle with
  /// the scene's controller gains (the paper's controller's "done" stage), or the loop's own safe
  /// stop; then run_synthetic's verdict.
  void wind_down(Episode& e, bool hold) const {
    e.terminated = true;
    const control::Plan& plan = *setup_->plan.plan;
    const control::PaperConfig& gains = nominal_->controller.paper;
    const double final_angle = plan.hand(plan.duration()).angle;
    bool more = true;
    control::ControlInput tick = e.input;
    while (more) {
      control::ControlOutput out;
      if (hold) {
        out.theta_ddot =
            gains.kp * (final_angle - tick.joint.theta) - gains.kd * tick.joint.theta_dot;
        out.done = true;
        out.t_done = motion_end_;
        out.mode = control::to_string(control::Stage::kDone);
        out.theta_reference = plan.hand(std::max(tick.t, 0.0)).angle;
      }
      e.loop->act(out);
      const control::ControlInput* next = e.loop->sense();
      more = next != nullptr;
      if (more) tick = *next;
    }
    e.result = drivers::judge_synthetic(e.loop->finish(), e.world, e.camera);
  }

  py::object observe() {
    const Episode& e = *episode_;
    switch (observation_) {
      case Observation::kState: {
        const drivers::WorldSample& w = e.truth_now;
        return vector({w.theta, w.theta_dot, w.s_h, w.sdot_h});
      }
      case Observation::kMeasurement: {
        const control::ControlInput& in = e.input;
        const std::optional<control::Measurement>& z = e.latest_seen;
        const double s_start = nominal_->spec.sim.initial.s_h;
        const control::Estimate& est = in.estimate;
        return vector({in.t, in.joint.theta, in.joint.theta_dot, z ? z->s_h : s_start,
                       z ? z->sigma : kInf, z ? z->t_capture : -kInf, est.s_h, est.sdot_h,
                       in.estimating ? std::sqrt(est.covariance(0, 0)) : kInf,
                       in.estimating ? std::sqrt(est.covariance(1, 1)) : kInf});
      }
      case Observation::kImage:
        return image();
    }
    throw std::logic_error("Env: unknown observation");
  }

  static py::array_t<double> vector(std::initializer_list<double> values) {
    py::array_t<double> a(static_cast<py::ssize_t>(values.size()));
    std::copy(values.begin(), values.end(), a.mutable_data());
    return a;
  }

  /// The latest frame (BGR, uint8), zeros before the first; one read-only array per frame.
  py::object image() {
    const Episode& e = *episode_;
    if (image_cache_ && image_frame_ == e.frames_seen && image_episode_ == episode_.get())
      return image_cache_;
    py::array a;
    if (e.frame_seen.empty()) {
      const CameraSpec& camera = *nominal_->spec.camera;
      py::array_t<std::uint8_t> zeros({camera.height, camera.width, 3});
      std::fill(zeros.mutable_data(), zeros.mutable_data() + zeros.size(), 0);
      a = zeros;
    } else {
      a = image_to_numpy(e.frame_seen);
    }
    a.attr("setflags")("write"_a = false);
    image_cache_ = a;
    image_frame_ = e.frames_seen;
    image_episode_ = episode_.get();
    return image_cache_;
  }

  py::dict info() const {
    const Episode& e = *episode_;
    const drivers::WorldSample& w = e.truth_now;
    py::dict d;
    d["t"] = e.input.t;
    d["s_h"] = w.s_h;
    d["sdot_h"] = w.sdot_h;
    d["theta"] = w.theta;
    d["theta_dot"] = w.theta_dot;
    d["fn_ratio"] = w.fn_ratio;
    d["mu_required"] = w.mu_required;
    d["mode"] = sim::to_string(w.mode);
    d["estimating"] = e.input.estimating;
    d["measured"] = e.measured_now;
    d["stopping"] = e.loop->stopping();
    // Known once the loop has ended (the episode then has its result).
    const auto* stop =
        e.result && e.result->loop.stop_reason ? &*e.result->loop.stop_reason : nullptr;
    d["stop_reason"] = stop ? py::object(py::str(stop->detail)) : py::object(py::none());
    d["ended_by"] = e.ended_by.empty() ? py::object(py::none()) : py::object(py::str(e.ended_by));
    if (e.result) {
      const drivers::SyntheticResult& r = *e.result;
      d["success"] = r.success;
      d["outcome"] = drivers::to_string(r.outcome);
      d["failure"] = r.failure.empty() ? py::object(py::none()) : py::object(py::str(r.failure));
      d["s_end"] = r.s_end;
      d["duration_s"] = std::isfinite(r.loop.duration_s) ? py::object(py::float_(r.loop.duration_s))
                                                         : py::object(py::none());
      d["fn_min_ratio"] = r.fn_min_ratio;
      d["mu_max"] = r.mu_max;
    } else {
      d["success"] = false;
      d["outcome"] = py::none();
    }
    return d;
  }

  Observation observation_;
  long ticks_per_step_;
  double motion_end_ = 0;
  std::optional<double> time_limit_;
  std::shared_ptr<const model::Model> nominal_, truth_;
  std::unique_ptr<drivers::LoopSetup> setup_;
  std::uint64_t next_seed_ = 1;
  std::unique_ptr<Episode> episode_;
  py::object image_cache_;
  long image_frame_ = -1;
  const Episode* image_episode_ = nullptr;
};

}  // namespace

void bind_env(py::module_& m) {
  py::class_<PyEnv>(m, "Env")
      .def(py::init<const py::object&, const std::string&, long, std::optional<double>,
                    std::optional<double>, const py::object&>(),
           "scene"_a, "observation"_a, "ticks_per_step"_a, "duration"_a, "time_limit"_a,
           "estimator"_a)
      .def("reset", &PyEnv::reset, "seed"_a)
      .def("step", &PyEnv::step, "action"_a)
      .def("render", &PyEnv::render)
      .def("log", &PyEnv::log)
      .def("close", &PyEnv::close)
      .def_property_readonly("description", &PyEnv::description)
      .def_property_readonly("plan", &PyEnv::plan);
}

}  // namespace flatland::python
