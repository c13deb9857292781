// The world's parameters from recordings of the disk on the hand (docs/IDENTIFY.md): friction,
// restitution, the losses, the table's tilt, the hand's angle offset and the camera-to-joint time
// offset, fitted with Ceres on flatland's own simulator by multiple shooting (Bock), weighted by
// the tracker's sigma; each parameter with its sigma, or refused as "not determined" with the
// reason, as calibration refuses what its data cannot support.
#pragma once

#include "flatland/sim/motion.hpp"
#include "flatland/sim/spec.hpp"

#include <Eigen/Core>

#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace flatland::identify {

/// What one recording gives: the disk's measured hand contact parameter over time, with its
/// sigma per sample, and the joint's log of the hand angle that drove it. SI units.
struct Recording {
  /// For messages and reports: a file name or a label.
  std::string name;
  /// s, the camera's clock: sample times, strictly increasing.
  std::vector<double> t;
  /// Measured s_h at each t (the hand's global parameter: palm well -1, tip 0, back well +1).
  std::vector<double> s_h;
  /// The measurement's standard deviation at each t (the tracker's sigma in s_h), > 0.
  std::vector<double> sigma;
  /// The joint's log: times (s, the joint's clock) and hand angles (rad, 0 = palm up), strictly
  /// increasing in time, at least 4 entries, usually denser than the camera's samples. The hand
  /// motion is its interpolating cubic spline (JointLogMotion). It must cover the samples' times
  /// shifted by any time offset within the bounds (identify refuses it otherwise, naming
  /// joint_t).
  std::vector<double> joint_t;
  std::vector<double> joint_theta;
};

/// std::invalid_argument naming the recording and the field ("NAME: t[12]: not increasing") for
/// a recording identify cannot use: sizes that differ, fewer than 4 samples or joint entries,
/// non-finite values, times not strictly increasing, sigma <= 0.
void check_recording(const Recording& recording);

/// The hand driven by a joint's log: the not-a-knot cubic spline through (joint_t, joint_theta)
/// (theta, theta_dot and theta_ddot continuous), read at t + time_offset, plus angle_offset. The
/// pivot is fixed at the origin. Outside the log the spline's end pieces are extrapolated.
class JointLogMotion final : public sim::HandMotion {
 public:
  /// std::invalid_argument if the sizes differ, there are fewer than 4 entries, a value is not
  /// finite or the times do not increase strictly.
  JointLogMotion(std::vector<double> t, const std::vector<double>& theta, double time_offset = 0,
                 double angle_offset = 0);
  using sim::HandMotion::at;
  sim::HandKinematics at(double t, int segment) const override;

 private:
  std::vector<double> t_, a_, b_, c_, d_;  // theta = a + b u + c u^2 + d u^3, u = t - t_i
  double time_offset_, angle_offset_;
};

/// The parameters identify can fit, by name: "mu_static", "mu_kinetic", "restitution",
/// "rolling_resistance" (m), "drag" (N s/m), "drag_angular" (N m s/rad), "tilt" (rad),
/// "angle_offset" (rad, added to the joint's angle), "time_offset" (s: the joint's clock minus
/// the camera's, so the hand angle at camera time t is the log's at t + time_offset).
const std::vector<std::string>& parameter_names();

/// A closed interval of a parameter's values.
struct Bounds {
  double lower = 0, upper = 0;
};
/// The default bounds of a parameter (docs/IDENTIFY.md lists them); std::invalid_argument for an
/// unknown name.
Bounds default_bounds(const std::string& name);

/// How a fit is reported while it runs (one call per Ceres iteration).
struct Progress {
  int iteration = 0;
  double cost = 0;  ///< 0.5 * (weighted sum of squares)
  long simulations = 0;
  double wall_time = 0;  ///< s since the start
};

struct IdentifyOptions {
  /// Which parameters to fit (names of parameter_names()); the others keep the world's values.
  /// std::invalid_argument naming "unknowns" for an unknown or repeated name.
  std::vector<std::string> unknowns;
  /// s: the length of a shooting segment; each recording is cut into segments of at most this
  /// length (at sample times), each with its own initial state (s_h, sdot_h).
  double segment_duration = 1.0;
  /// Bounds that replace the defaults, by parameter name.
  std::map<std::string, Bounds> bounds;
  /// Starting values that replace the world's, by parameter name (inside the bounds).
  std::map<std::string, double> initial;
  /// Ceres iterations at most, per solve (the states alone, then everything with the continuity
  /// conditions relaxed and tightened, then as defined; again after a parameter is held). A fit
  /// whose last solve stops here has not converged: IdentifyResult::converged is false and a
  /// warning says so. 50 stopped short of convergence on a closed-loop experiment
  /// (it needed 60-70); docs/IDENTIFY.md.
  int max_iterations = 200;
  /// Threads evaluating segments at once; 0: as many as the machine has.
  int threads = 0;
  /// A parameter whose sigma exceeds this fraction of its bounds' width (or of |value| where
  /// that is larger) is reported as not determined.
  double max_relative_sigma = 0.5;
  /// The integrator's relative tolerance inside the fit (absolute: rtol / 100); tight, so that
  /// the central differences see a smooth function (docs/IDENTIFY.md says how it was chosen).
  double rtol = 1e-10;
  /// Called after each iteration; may be empty.
  std::function<void(const Progress&)> progress;
};

/// One parameter's result.
struct ParameterEstimate {
  std::string name;
  double initial = 0;  ///< where the fit started
  double value = 0;    ///< where it ended
  Bounds bounds;
  /// The standard deviation, absent when the data do not determine the parameter.
  std::optional<double> sigma;
  /// Why it is not determined (empty when sigma is present), e.g. "cannot be separated from
  /// drag (correlation -0.998)", "at its lower bound", "sigma 0.2 exceeds half its range".
  std::string not_determined;
  /// The sigma from the weights as given, before the Birge ratio's scaling (equal to sigma when
  /// chi^2 was consistent with its degrees of freedom; IdentifyResult::sigma_scale).
  std::optional<double> sigma_unscaled;
  /// Not fitted: the data did not determine it, so it was held at its starting value (`value`
  /// is that value) and the other unknowns fitted again with it there.
  bool held = false;
  /// The Gauss-Newton step that the linear model at the solution still takes for this parameter
  /// (its unit; 0 when held): where that model puts the minimum of chi^2, relative to `value`.
  /// About 0 at a minimum; IdentifyResult::step_in_sigma judges it.
  double step_to_minimum = 0;
};

/// One recording's fit, per sample: time (camera clock), measured and fitted s_h, and the
/// residual (fitted - measured) / sigma.
struct RecordingFit {
  std::string name;
  std::vector<double> t, measured, fitted, normalised_residual;
};

/// One shooting segment's fitted initial state (a rolling contact at t0).
struct SegmentState {
  std::size_t recording = 0;  ///< index into the recordings
  double t0 = 0, t1 = 0;      ///< s, the segment's span (camera clock)
  double s_h = 0, sdot_h = 0;
  std::optional<double> sigma_s_h, sigma_sdot_h;  ///< scaled as the parameters' sigma are
};

struct IdentifyResult {
  std::vector<ParameterEstimate> parameters;  ///< in IdentifyOptions::unknowns' order
  /// Correlations between the parameters (same order); rows and columns of parameters that are
  /// not determined are NaN.
  Eigen::MatrixXd correlation;
  double chi2 = 0;  ///< sum of squared normalised residuals of the measurements
  /// Samples minus fitted quantities (parameters and one initial state per recording; the
  /// segments' other initial states are tied by the continuity conditions).
  int degrees_of_freedom = 0;
  /// The 99 % quantile of the chi^2 distribution with degrees_of_freedom (infinite when there
  /// are none): chi^2 above it is not what noise of the given sigma makes.
  double chi2_limit = 0;
  /// The factor every reported sigma carries: sqrt(chi2 / dof) (the Birge ratio) when chi2
  /// exceeds chi2_limit, the sigma given being too small or the model missing something (a
  /// warning says so); 1 when chi2 is consistent. ParameterEstimate::sigma_unscaled has the
  /// sigma before it.
  double sigma_scale = 1;
  std::vector<RecordingFit> fits;  ///< one per recording
  std::vector<SegmentState> segments;
  int iterations = 0;
  long simulations = 0;        ///< simulator runs (segments), the differences' included
  double wall_time = 0;        ///< s
  double simulation_time = 0;  ///< s of wall time spent inside the simulator
  /// Whether the fit reached a minimum of chi^2: the last solve converged (Ceres' CONVERGENCE)
  /// and the linear model at the solution moves no determined parameter by more than 0.3 of its
  /// sigma (step_in_sigma). When not, a warning says that the values are where the solver
  /// stopped, not a minimum.
  bool converged = false;
  /// The largest |ParameterEstimate::step_to_minimum| / sigma over the determined parameters: how
  /// far, in sigma, the minimum lies from the values reported, as far as the linear model at the
  /// solution knows. A solver that stops short of the minimum (Ceres calls its tolerance
  /// convergence where a curved valley shrank its steps to nothing) shows here.
  double step_in_sigma = 0;
  /// chi^2 that the linear model at the solution expects its Gauss-Newton step to remove (0 at a
  /// minimum).
  double chi2_decrease_expected = 0;
  std::string termination_type;  ///< Ceres' termination type: CONVERGENCE, NO_CONVERGENCE, ...
  std::string termination;       ///< Ceres' message
  /// What the caller should know about the fit's validity, one line each: a fit that did not
  /// converge; chi^2 beyond chi2_limit (sigma scaled); a segment boundary where the fitted run is
  /// in flight or sliding (a segment starts rolling, so the continuity there is not the whole
  /// state: choose another segment_duration).
  std::vector<std::string> warnings;
  /// The world with the fitted values in place (the held ones at their starting values): contact
  /// law and tilt.
  sim::SimulationSpec world;
  /// The fitted (or, when not among the unknowns, the starting) hand angle offset (rad) and
  /// camera-to-joint time offset (s), which a SimulationSpec does not hold: for validate().
  double angle_offset = 0, time_offset = 0;
};

/// Fit opts.unknowns of `world` (its hand, object, gravity, contact and integrator; its motion
/// and initial state are replaced by each recording's joint log and fitted states) to the
/// recordings. std::invalid_argument (one line naming the field) for bad options or recordings;
/// std::runtime_error when the simulator fails at the starting values.
IdentifyResult identify(const sim::SimulationSpec& world, const std::vector<Recording>& recordings,
                        const IdentifyOptions& options);

/// How far a world predicts a recording it was not fitted to.
struct PredictionCheck {
  std::string name;
  /// The initial state the prediction starts from (fitted to the first `initial_window` s).
  double s_h0 = 0, sdot_h0 = 0;
  /// Per sample: time, measured, predicted, error (predicted - measured) and error / sigma.
  std::vector<double> t, measured, predicted, error, normalised_error;
  double rms_error = 0, max_abs_error = 0;
  /// s: the first time the error exceeds 3 sigma, measured from the start (absent: never): the
  /// RMS of error / sigma over 5 samples centred there (so that a lone noisy sample, 3 sigma
  /// off once in 370, does not count; pure noise reaches it with probability ~1e-8).
  std::optional<double> time_to_3_sigma;
  /// Why the prediction ended before the recording did (the disk dropped, ...); empty when the
  /// whole recording was predicted.
  std::string stopped;
};

struct ValidateOptions {
  /// s: the span at the recording's start to which the initial state is fitted.
  double initial_window = 0.5;
  double rtol = 1e-10;
  /// The hand's angle offset (rad) and the time offset (s) to apply (IdentifyResult's).
  double angle_offset = 0, time_offset = 0;
};

/// Simulate `held_out` from its first state with `world` (as identify's result gives it) and
/// report the error over time. std::invalid_argument for a bad recording or options.
PredictionCheck validate(const sim::SimulationSpec& world, const Recording& held_out,
                         const ValidateOptions& options = {});

}  // namespace flatland::identify
