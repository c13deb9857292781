// The multiple-shooting problem without Ceres: options' checks, segments, one segment's run.
#include "shooting.hpp"

#include "flatland/sim/format.hpp"

#include <Eigen/QR>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

namespace flatland::identify::detail {
namespace {

/// The joint's spline read at t + time_offset, plus angle_offset, sharing one spline between
/// every evaluation of the fit (building it costs O(log entries) memory and time per call).
class ShiftedMotion final : public sim::HandMotion {
 public:
  ShiftedMotion(std::shared_ptr<const JointLogMotion> base, double time_offset, double angle_offset)
      : base_(std::move(base)), time_offset_(time_offset), angle_offset_(angle_offset) {}
  using sim::HandMotion::at;
  sim::HandKinematics at(double t, int) const override {
    sim::HandKinematics k = base_->at(t + time_offset_);
    k.angle += angle_offset_;
    return k;
  }

 private:
  std::shared_ptr<const JointLogMotion> base_;
  double time_offset_, angle_offset_;
};

/// Below this a parameter hardly changes a run (SI units): the difference steps' floor.
double typical_size(const std::string& name) {
  if (name == "mu_static" || name == "mu_kinetic" || name == "restitution") return 1e-2;
  if (name == "rolling_resistance") return 1e-6;  // m
  if (name == "drag") return 1e-4;                // N s/m
  if (name == "drag_angular") return 1e-7;        // N m s/rad
  return 1e-4;                                    // tilt, angle_offset (rad), time_offset (s)
}

/// The world's own value of a parameter (offsets: 0); absent when the world has none.
std::optional<double> world_value(const sim::SimulationSpec& w, const std::string& name) {
  const sim::ContactLaw& c = w.contact;
  if (name == "mu_static") return c.mu;
  if (name == "mu_kinetic") return c.mu_kinetic ? c.mu_kinetic : c.mu;
  if (name == "restitution") return c.restitution;
  if (name == "rolling_resistance") return c.rolling_resistance;
  if (name == "drag") return c.drag;
  if (name == "drag_angular") return c.drag_angular;
  if (name == "tilt") return w.tilt;
  return 0.0;  // angle_offset, time_offset
}

void check_scalar_options(const IdentifyOptions& o) {
  if (!(o.segment_duration > 0) || !std::isfinite(o.segment_duration))
    throw std::invalid_argument("segment_duration: must be positive and finite, got " +
                                sim::format_number(o.segment_duration));
  if (o.max_iterations < 0 || o.max_iterations > 10000)
    throw std::invalid_argument("max_iterations: must be in [0, 10000], got " +
                                std::to_string(o.max_iterations));
  if (!(o.max_relative_sigma > 0) || !std::isfinite(o.max_relative_sigma))
    throw std::invalid_argument("max_relative_sigma: must be positive and finite");
  if (const std::string why = sim::integrator_setting_problem("rtol", o.rtol); !why.empty())
    throw std::invalid_argument(why);
  if (o.threads < 0 || o.threads > 256)
    throw std::invalid_argument("threads: must be in [0, 256], got " + std::to_string(o.threads));
}

std::vector<Unknown> make_unknowns(const sim::SimulationSpec& world, const IdentifyOptions& o) {
  std::set<std::string> seen;
  std::vector<Unknown> out;
  for (const std::string& name : o.unknowns) {
    Unknown u;
    u.name = name;
    u.bounds = default_bounds(name);  // throws naming "unknowns" for an unknown name
    if (!seen.insert(name).second)
      throw std::invalid_argument("unknowns: '" + name + "' is listed twice");
    u.typical = typical_size(name);
    out.push_back(u);
  }
  for (const auto& [name, b] : o.bounds) {
    const auto it = std::find_if(out.begin(), out.end(),
                                 [&name = name](const Unknown& u) { return u.name == name; });
    if (it == out.end()) throw std::invalid_argument("bounds." + name + ": not among the unknowns");
    const Bounds limits = default_bounds(name);
    if (!(b.lower < b.upper) || !std::isfinite(b.lower) || !std::isfinite(b.upper) ||
        b.lower < limits.lower || b.upper > limits.upper)
      throw std::invalid_argument("bounds." + name + ": need lower < upper within [" +
                                  sim::format_number(limits.lower) + ", " +
                                  sim::format_number(limits.upper) + "]");
    it->bounds = b;
  }
  for (Unknown& u : out) {
    std::optional<double> start = world_value(world, u.name);
    if (const auto it = o.initial.find(u.name); it != o.initial.end()) start = it->second;
    if (!start)
      throw std::invalid_argument("initial." + u.name +
                                  ": the world has no value (contact.mu absent): give one");
    if (!std::isfinite(*start) || *start < u.bounds.lower || *start > u.bounds.upper)
      throw std::invalid_argument("initial." + u.name + ": " + sim::format_number(*start) +
                                  " is outside its bounds [" + sim::format_number(u.bounds.lower) +
                                  ", " + sim::format_number(u.bounds.upper) + "]");
    u.initial = *start;
  }
  for (const auto& [name, value] : o.initial) {
    if (!seen.count(name))
      throw std::invalid_argument("initial." + name + ": not among the unknowns");
  }
  if (seen.count("mu_kinetic") && !seen.count("mu_static") && !world.contact.mu)
    throw std::invalid_argument(
        "unknowns: mu_kinetic needs a static coefficient (the world's contact.mu, or mu_static "
        "among the unknowns)");
  return out;
}

/// s and sdot at sample i from a least-squares quadratic through its neighbours (+-3 samples),
/// their s_h taken within half a period of sample i's.
std::pair<double, double> local_state(const Recording& r, std::size_t i, double period) {
  const std::size_t lo = i >= 3 ? i - 3 : 0, hi = std::min(r.t.size(), i + 4);
  Eigen::MatrixXd A(hi - lo, 3);
  Eigen::VectorXd b(hi - lo);
  for (std::size_t j = lo; j < hi; ++j) {
    const double u = r.t[j] - r.t[i];
    A.row(j - lo) << 1.0, u, u * u;
    b[j - lo] = r.s_h[i] + (std::isfinite(period) ? std::remainder(r.s_h[j] - r.s_h[i], period)
                                                  : r.s_h[j] - r.s_h[i]);
  }
  const Eigen::Vector3d c = A.colPivHouseholderQr().solve(b);
  return {c[0], c[1]};
}

/// The joint's log must cover the samples' times shifted by every time offset the fit may try:
/// its spline's end pieces are not extrapolated into the recording.
void check_joint_coverage(const Recording& rec, const std::vector<Unknown>& unknowns,
                          double time_offset) {
  double lo = time_offset, hi = time_offset;
  for (const Unknown& u : unknowns)
    if (u.name == "time_offset") lo = u.bounds.lower, hi = u.bounds.upper;
  const double need0 = rec.t.front() + lo, need1 = rec.t.back() + hi;
  if (rec.joint_t.front() > need0 || rec.joint_t.back() < need1)
    throw std::invalid_argument(rec.name + ": joint_t: the joint's log covers [" +
                                sim::format_number(rec.joint_t.front()) + ", " +
                                sim::format_number(rec.joint_t.back()) + "] s; the samples need [" +
                                sim::format_number(need0) + ", " + sim::format_number(need1) +
                                "] s (their times plus the time offset's range)");
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

ShootingProblem::ShootingProblem(const sim::SimulationSpec& world,
                                 const std::vector<Recording>& recordings,
                                 const IdentifyOptions& options, double angle_offset,
                                 double time_offset)
    : world_(world),
      recordings_(recordings),
      angle_offset_(angle_offset),
      time_offset_(time_offset) {
  check_scalar_options(options);
  if (recordings.empty()) throw std::invalid_argument("recordings: none given");
  unknowns_ = make_unknowns(world, options);
  world_.run.model = sim::ContactModel::kHybrid;
  base_ = sim::build_problem(world_);
  if (const auto* hand = dynamic_cast<const sim::HandCurve*>(base_->hand.get()))
    period_ = hand->period();
  run_ = sim::run_options(world_);
  run_.model = sim::ContactModel::kHybrid;
  run_.integrator.method = sim::Method::kDormandPrince54;
  run_.integrator.rtol = options.rtol;
  run_.integrator.atol = 1e-2 * options.rtol;
  run_.integrator.energy_tolerance.reset();
  run_.record = true;
  run_.keep_steps = 0;
  run_.stop_at_transition = false;
  run_.hand_inertia.reset();
  run_.events.s_h_bounds.reset();
  run_.probe_times.clear();
  for (std::size_t r = 0; r < recordings_.size(); ++r) {
    const Recording& rec = recordings_[r];
    check_recording(rec);
    check_joint_coverage(rec, unknowns_, time_offset_);
    joints_.push_back(std::make_shared<JointLogMotion>(rec.joint_t, rec.joint_theta));
    std::vector<double> dt(rec.t.size() - 1);
    for (std::size_t i = 0; i + 1 < rec.t.size(); ++i) dt[i] = rec.t[i + 1] - rec.t[i];
    // The continuity conditions stand for equalities: residuals scaled so that a gap of a
    // thousandth of the measurements' sigma costs as much as one sample one sigma off.
    continuity_s_.push_back(1e-3 * median(rec.sigma));
    continuity_sdot_.push_back(continuity_s_.back() / median(dt));
    // Segments of at most segment_duration, at least 3 samples each (a short tail joins the
    // segment before it).
    std::size_t first = 0;
    const std::size_t begin_index = segments_.size();
    while (first < rec.t.size()) {
      std::size_t end = first + 1;
      while (end < rec.t.size() && rec.t[end] - rec.t[first] < options.segment_duration) ++end;
      end = std::max(end, std::min(rec.t.size(), first + 3));
      if (rec.t.size() - end < 3) end = rec.t.size();
      Segment s;
      s.recording = r;
      s.first = first;
      s.end = end;
      s.t0 = rec.t[first];
      s.has_next = end < rec.t.size();
      s.t_end = s.has_next ? rec.t[end] : rec.t[end - 1];
      std::tie(s.guess_s, s.guess_sdot) = local_state(rec, first, period_);
      segments_.push_back(s);
      first = end;
    }
    if (segments_.size() - begin_index > 10000)
      throw std::invalid_argument(rec.name + ": more than 10000 segments: raise segment_duration");
  }
}

WorldValues ShootingProblem::values(const double* w) const {
  WorldValues v;
  v.law = world_.contact;
  v.tilt = world_.tilt;
  v.angle_offset = angle_offset_;
  v.time_offset = time_offset_;
  for (std::size_t j = 0; j < unknowns_.size(); ++j) {
    const std::string& n = unknowns_[j].name;
    const double x = w[j];
    if (n == "mu_static")
      v.law.mu = x;
    else if (n == "mu_kinetic")
      v.law.mu_kinetic = x;
    else if (n == "restitution")
      v.law.restitution = x;
    else if (n == "rolling_resistance")
      v.law.rolling_resistance = x;
    else if (n == "drag")
      v.law.drag = x;
    else if (n == "drag_angular")
      v.law.drag_angular = x;
    else if (n == "tilt")
      v.tilt = x;
    else if (n == "angle_offset")
      v.angle_offset = x;
    else if (n == "time_offset")
      v.time_offset = x;
  }
  // Both coefficients free: a kinetic one above the static one slides at the static one.
  if (v.law.mu && v.law.mu_kinetic && *v.law.mu_kinetic > *v.law.mu) v.law.mu_kinetic = v.law.mu;
  return v;
}

sim::RunResult ShootingProblem::run(std::size_t recording, double t0, double t_end, double s,
                                    double sdot, const WorldValues& v) const {
  auto pb = std::make_shared<sim::RollingProblem>(*base_);
  pb->contact = v.law;
  pb->gravity = world_.gravity * std::sin(v.tilt);
  pb->motion = std::make_shared<ShiftedMotion>(joints_[recording], v.time_offset, v.angle_offset);
  sim::RunOptions opt = run_;
  opt.t_end = t_end;
  sim::InitialContact init;
  init.t0 = t0;
  init.s_h = s;
  init.sdot_h = sdot;
  const auto start = std::chrono::steady_clock::now();
  ++simulations_;
  sim::RunResult result = sim::simulate(pb, init, opt);
  simulation_ns_ +=
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start)
          .count();
  return result;
}

bool ShootingProblem::simulate(std::size_t k, double s, double sdot, const double* w,
                               SegmentOutput& out, std::string* why) const {
  const Segment& seg = segments_[k];
  std::vector<double> s_h;
  if (!simulate_span(seg.recording, seg.t0, s, sdot, w, s_h, why, seg.t_end, &out.s_end,
                     &out.sdot_end, &out.end_mode))
    return false;
  out.s_h.assign(s_h.begin(), s_h.begin() + static_cast<long>(seg.end - seg.first));
  return true;
}

bool ShootingProblem::simulate_span(std::size_t recording, double t0, double s, double sdot,
                                    const double* w, std::vector<double>& s_h, std::string* why,
                                    std::optional<double> t_end, double* s_end, double* sdot_end,
                                    sim::ContactMode* end_mode) const {
  const Recording& rec = recordings_[recording];
  const double t_stop = t_end ? *t_end : rec.t.back();
  const auto describe = [&](const std::string& what) {
    if (why)
      *why = rec.name + ": the run from t = " + sim::format_number(t0) + " s (s_h " +
             sim::format_number(s) + ", sdot_h " + sim::format_number(sdot) + ") " + what;
  };
  sim::RunResult result;
  try {
    result = run(recording, t0, t_stop, s, sdot, values(w));
  } catch (const std::exception& e) {
    describe(std::string("failed: ") + e.what());
    return false;
  }
  s_h.clear();
  const auto from = std::lower_bound(rec.t.begin(), rec.t.end(), t0 - 1e-12);
  for (auto it = from; it != rec.t.end() && *it <= t_stop; ++it) {
    if (*it > result.trajectory.t_end()) break;
    s_h.push_back(result.trajectory.s_h(*it));
  }
  if (result.reason != sim::StopReason::kEndTime) {
    describe("stopped at t = " + sim::format_number(result.final.t) +
             " s: " + sim::to_string(result.reason));
    return false;
  }
  if (s_end) *s_end = result.final.s_h;
  if (sdot_end) *sdot_end = result.final.sdot_h;
  if (end_mode) *end_mode = result.final.mode;
  return true;
}

}  // namespace flatland::identify::detail
