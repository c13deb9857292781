// Uses flatland as a library from its installed prefix: loads the bundled scenes from the
// installed data, solves the paper's butterfly (sim), projects the disk's start through the
// scene's camera, compiled into a Model, runs the quick work-precision study (studies), and
// brings its own controller to the closed loop: a PD on the disk's contact parameter s_h, derived
// from flatland::control::Controller, in a synthetic experiment and a small Monte Carlo beside the
// paper's controller. Prints one JSON object; exit 1 on any error or failed check.
//   downstream [--no-loop]
#include <flatland/flatland.hpp>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <exception>
#include <memory>
#include <set>
#include <stdexcept>
#include <string>

namespace {

using namespace flatland;

// A lab's own law, in the few lines a user writes: the plan's hand motion as feedforward, the
// hand servoed to it, and a PD on the estimated s_h against the plan's s_h at the time (a disk
// behind its plan gets the hand's acceleration raised). Before t = 0 it waits; from the plan's end
// it holds the final angle and says the motion is done. It is a test of the interface, not a good
// law: on 30 perturbed worlds (seed 1) it succeeds 25 times whatever the sign of its s_h gains up
// to 4 times these, as often as open-loop playback (25), against the paper's controller's 30.
class PdOnContact final : public control::Controller {
 public:
  explicit PdOnContact(std::shared_ptr<std::atomic<long>> calls) : calls_(std::move(calls)) {}
  void start(const control::ControllerContext& context) override { plan_ = context.plan; }
  std::string name() const override { return "pd"; }
  control::ControlOutput step(const control::ControlInput& in) override {
    ++*calls_;
    control::ControlOutput out;
    const double T = plan_->duration(), t = std::clamp(in.t, 0.0, T);
    const sim::HandKinematics p = plan_->hand(t);
    const double theta = in.joint.theta, rate = in.joint.theta_dot;
    out.theta_reference = p.angle;
    out.mode = in.t < 0 ? "wait" : in.t >= T ? "hold" : "pd";
    if (in.t >= T) out.done = true, out.t_done = T;
    if (in.t < 0) return out;
    out.theta_ddot = kHandP * (p.angle - theta) + kHandD * (p.angular_velocity - rate);
    if (in.t >= T) return out;
    out.theta_ddot += p.angular_acceleration;
    if (in.estimating)
      out.theta_ddot += kSP * (plan_->s_h_at(t) - in.estimate.s_h) +
                        kSD * (plan_->sdot_h_at(t) - in.estimate.sdot_h);
    return out;
  }

 private:
  static constexpr double kHandP = 400, kHandD = 40;  // 1/s^2, 1/s: the hand on its plan
  static constexpr double kSP = 2, kSD = 0.5;         // rad/s^2 per unit of s_h, per 1/s
  std::shared_ptr<const control::Plan> plan_;
  std::shared_ptr<std::atomic<long>> calls_;
};

void require(bool ok, const std::string& what) {
  if (!ok) throw std::runtime_error("check failed: " + what);
}

// The controller in one synthetic experiment and a two-world Monte Carlo beside the paper's:
// the checks a user would make that their law ran as written, as JSON fields.
std::string run_own_controller(const std::string& data_dir) {
  const auto nominal = model::compile(load_scene(data_dir + "/scenes/airtable-feedback.yaml"));
  auto calls = std::make_shared<std::atomic<long>>(0);
  const drivers::LoopSetup setup(nominal, [calls] { return std::make_unique<PdOnContact>(calls); });
  const drivers::SyntheticResult run = drivers::run_synthetic(setup, nominal);
  const drivers::LoopResult& loop = run.loop;
  require(loop.controller == "pd", "the loop ran controller '" + loop.controller + "'");
  // Called at every tick until the loop stopped safely (from then on the loop decelerates alone).
  long before_stop = 0;
  std::set<std::string> modes;
  for (const drivers::TickLog& row : loop.log) {
    modes.insert(row.mode);
    before_stop += row.mode != "safe-stop";
  }
  require(loop.safe_stop ? *calls >= before_stop : *calls == static_cast<long>(loop.log.size()),
          "called " + std::to_string(*calls) + " times in " + std::to_string(loop.log.size()) +
              " ticks");
  require(modes.count("wait") && modes.count("pd"), "its modes are not in the log");
  require(!loop.finished || modes.count("hold"), "a finished motion without its hold");

  std::atomic<long> monte_carlo_calls{0};
  const drivers::MonteCarloController own("pd", [&monte_carlo_calls] {
    auto counter = std::make_shared<std::atomic<long>>(0);
    ++monte_carlo_calls;
    return std::make_unique<PdOnContact>(counter);
  });
  const drivers::MonteCarloResult mc =
      drivers::run_montecarlo(*nominal, {}, 2, 1, {"paper", own}, 0);
  require(mc.records.size() == 4 && monte_carlo_calls == 2, "Monte Carlo did not run 2 x 2");
  int own_successes = 0;
  for (int i = 0; i < 2; ++i) {
    const drivers::RunRecord &paper = mc.records[2 * i], &pd = mc.records[2 * i + 1];
    require(paper.controller == "paper" && pd.controller == "pd", "records' names");
    // The same world for both: every drawn value equal.
    const drivers::DrawnPerturbation &a = paper.drawn, &b = pd.drawn;
    require(a.s_h0 == b.s_h0 && a.tilt_deg == b.tilt_deg && a.radius == b.radius &&
                a.friction_scale == b.friction_scale && a.effects_seed == b.effects_seed &&
                a.mu_scale == b.mu_scale && a.loss_scale == b.loss_scale,
            "run " + std::to_string(i) + " drew different worlds for the two controllers");
    own_successes += pd.success;
  }
  char json[512];
  std::snprintf(json, sizeof json,
                "{\"controller\": \"%s\", \"outcome\": \"%s\", \"ticks\": %zu, \"calls\": %ld, "
                "\"modes\": %zu, \"montecarlo_successes\": %d, \"paper_successes\": %d}",
                loop.controller.c_str(), drivers::to_string(run.outcome).c_str(), loop.log.size(),
                calls->load(), modes.size(), own_successes,
                mc.records[0].success + mc.records[2].success);
  return json;
}

}  // namespace

// With --no-loop, the library's checks only (check.sh's second run, which checks where the data
// is found).
int main(int argc, char** argv) {
  const bool loop = !(argc > 1 && std::string(argv[1]) == "--no-loop");
  try {
    const flatland::Scene butterfly = flatland::load_scene(DATA_DIR "/scenes/butterfly.yaml");
    const flatland::sim::SolveReport solved =
        flatland::sim::solve_k(butterfly.sim, butterfly.sim.motion.period, {});
    const std::shared_ptr<const flatland::model::Model> filmed =
        flatland::model::compile(flatland::load_scene(DATA_DIR "/scenes/butterfly-camera.yaml"));
    const cv::Point2d origin = filmed->camera->project(cv::Point3d(0, 0, 0));
    flatland::studies::SimStudyOptions quick;
    quick.quick = true;
    quick.min_cpu = 0;
    const flatland::studies::SimStudyResult study =
        flatland::studies::run_sim_study(butterfly.sim, quick);
    const std::string own = loop ? run_own_controller(DATA_DIR) : "null";
    std::printf(
        "{\"k\": %.17g, \"origin_px\": [%.6f, %.6f], \"default_scene\": \"%s\", "
        "\"study_k\": %.17g, \"study_rows\": %zu, \"own_controller\": %s}\n",
        solved.k, origin.x, origin.y, flatland::default_scene_path().c_str(),
        study.reference_reduced.k, study.rows.size(), own.c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "downstream: %s\n", e.what());
    return 1;
  }
}
