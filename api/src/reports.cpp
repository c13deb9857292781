#include "flatland/api/reports.hpp"

#include "flatland/sim/format.hpp"
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/object.hpp"
#include "flatland/sim/sensitivity.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace flatland::api {

Json number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

double s_at_half_period(const sim::SimulationSpec& spec, const sim::RunResult& r) {
  if (spec.motion.kind != sim::MotionSpec::Kind::kButterfly || r.trajectory.empty())
    return std::nan("");
  const double T = spec.initial.t0 + 0.5 * spec.motion.period;  // as sim::evaluate does
  for (const sim::Sample& s : r.probes)
    if (s.t == T) return s.s_h;  // kept while the run's older steps were folded away
  const double eps = 1e-9 * std::max(1.0, std::abs(T));
  if (T < r.trajectory.t_begin() - eps || T > r.trajectory.t_end() + eps) return std::nan("");
  return r.trajectory.s_h(T);
}

Json contact_events_json(const std::vector<sim::RecordedEvent>& all) {
  std::vector<const sim::RecordedEvent*> events;
  for (const auto& e : all)
    if (e.kind != sim::EventKind::kJunction && e.kind != sim::EventKind::kApex)
      events.push_back(&e);
  std::stable_sort(events.begin(), events.end(),
                   [](const auto* a, const auto* b) { return a->t < b->t; });
  Json arr = Json::array();
  for (const auto* e : events) {
    Json j;
    j["kind"] = sim::to_string(e->kind);
    j["t"] = number(e->t);
    j["s_h"] = number(e->s_h);
    if (e->impact) {
      j["impulse_normal"] = number(e->impact->impulse_normal);
      j["impulse_tangential"] = number(e->impact->impulse_tangential);
      j["vn_before"] = number(e->impact->vn_before);
      j["vn_after"] = number(e->impact->vn_after);
      j["vt_before"] = number(e->impact->vt_before);
      j["vt_after"] = number(e->impact->vt_after);
      j["sticking"] = e->impact->sticking;
      j["caught"] = e->caught;
      j["energy_change"] = number(e->energy_change);
      j["hand_rate_change"] = number(e->hand_rate_change);
    }
    arr.push_back(j);
  }
  return arr;
}

Json flights_json(const std::vector<sim::FlightReport>& flights) {
  Json arr = Json::array();
  for (const sim::FlightReport& f : flights) {
    const bool landed = f.t_landing.has_value();
    Json j;
    j["t_lift_off"] = number(f.t_lift_off);
    j["s_lift_off"] = number(f.s_lift_off);
    j["t_landing"] = landed ? number(*f.t_landing) : Json(nullptr);
    j["duration"] = landed ? number(*f.t_landing - f.t_lift_off) : Json(nullptr);
    j["s_landing"] = landed ? number(f.s_landing) : Json(nullptr);
    j["landing_x"] = landed ? number(f.landing_position.x()) : Json(nullptr);
    j["landing_y"] = landed ? number(f.landing_position.y()) : Json(nullptr);
    j["impulse_normal"] = landed ? number(f.impulse_normal) : Json(nullptr);
    j["impulse_tangential"] = landed ? number(f.impulse_tangential) : Json(nullptr);
    j["bounces"] = f.bounces;
    j["t_caught"] = f.t_caught ? number(*f.t_caught) : Json(nullptr);
    j["dropped"] = f.dropped;
    arr.push_back(j);
  }
  return arr;
}

Json contact_summary_json(const std::array<double, 4>& mode_time, int mode_changes, int impacts,
                          const std::vector<sim::RecordedEvent>& events,
                          const sim::Sample& initial) {
  Json j;
  Json modes;
  for (int m = 0; m < 4; ++m)
    modes[sim::to_string(static_cast<sim::ContactMode>(m))] = number(mode_time[m]);
  j["mode_time"] = modes;
  j["mode_changes"] = mode_changes;
  j["impacts"] = impacts;
  j["flights"] = flights_json(sim::flight_reports(events, initial));
  j["events"] = contact_events_json(events);
  return j;
}

Json energy_json(const sim::EnergyAudit& a) {
  Json j;
  j["initial"] = number(a.initial);
  j["final"] = number(a.final);
  j["work_hand"] = number(a.work_hand);
  j["work_losses"] = number(a.work_losses);
  j["impact_losses"] = number(a.impact_losses);
  j["balance"] = number(a.balance);
  j["worst"] = number(a.worst);
  j["t_worst"] = number(a.t_worst);
  j["bound"] = number(a.bound());
  j["tolerance"] = number(a.tolerance);
  j["scale"] = number(a.scale);
  j["checks"] = a.checks;
  j["holds"] = !a.broken;
  j["t_broken"] = number(a.t_broken);
  return j;
}

std::string energy_failure_text(const sim::EnergyAudit& a) {
  return "numerical failure: " + sim::breach_text(a) +
         "; the results from there on are wrong (docs/DYNAMICS.md, \"Energy audit\")";
}

Json solve_report_json(const sim::SolveReport& r) {
  Json j;
  j["period"] = number(r.period);
  j["k"] = number(r.k);
  j["s_T"] = number(r.s_T);
  j["s_end"] = number(r.s_end);
  j["sdot_end"] = number(r.sdot_end);
  j["fn_apex_ratio"] = number(r.fn_apex_ratio);
  j["fn_min_ratio"] = number(r.fn_min_ratio);
  j["mu_required"] = number(r.mu_required);
  j["friction_margin"] = number(r.friction_margin);
  j["contact_lost"] = r.fn_min_ratio < 0;
  j["simulations"] = r.simulations;
  j["rhs_evals"] = r.rhs_evals;
  j["energy"] = energy_json(r.run.audit);
  return j;
}

Json design_iterate_json(const design::Iterate& it) {
  Json j;
  j["evaluation"] = it.evaluation;
  for (std::size_t i = 0; i < it.parameters.size(); ++i)
    j[std::string(sim::kButterflyParameters[i])] = number(it.parameters[i]);
  j["mu_required"] = number(it.mu_required);
  j["s_T"] = number(it.s_T);
  j["fn_min_ratio"] = number(it.fn_min_ratio);
  j["robustness"] = number(it.robustness);
  j["feasible"] = it.feasible;
  return j;
}

Json design_json(const design::DesignResult& r, const sim::SimulationSpec& spec) {
  Json j;
  j["objective"] = design::to_string(r.objective);
  j["period"] = number(spec.motion.period);
  j["mu"] = r.objective == design::Objective::kRobustness ? number(r.mu) : Json(nullptr);
  j["start"] = design_iterate_json(r.start_point);
  j["best"] = design_iterate_json(r.best);
  // How much better the best design is than the start: mu needed less, or robustness more.
  const bool robustness = r.objective == design::Objective::kRobustness;
  j["improvement"] =
      number(!(r.best.feasible && r.start_point.feasible) ? std::numeric_limits<double>::quiet_NaN()
             : robustness ? r.best.robustness - r.start_point.robustness
                          : r.start_point.mu_required - r.best.mu_required);
  j["active"] = r.active;
  j["restored"] = r.restored;
  j["restore_stop"] = r.restore_stop.empty() ? Json(nullptr) : Json(r.restore_stop);
  j["stop"] = r.stop;
  j["evaluations"] = r.iterates.size();
  j["simulations"] = r.simulations;
  Json iterates = Json::array();
  for (const auto& it : r.iterates) iterates.push_back(design_iterate_json(it));
  j["iterates"] = iterates;
  return j;
}

Json time_optimal_json(const sim::TimeOptimalReport& r, const sim::SimulationSpec& spec) {
  Json j;
  j["period"] = number(r.period);
  j["k"] = number(r.k);
  j["fn_min_ratio"] = number(r.fn_min_ratio);
  j["mu"] = spec.contact.mu ? number(*spec.contact.mu) : Json(nullptr);
  j["friction_margin"] = number(r.friction_margin);
  j["limit"] = sim::to_string(r.limit);
  j["solves"] = r.solves;
  j["contact_lost"] = r.fn_min_ratio < 0;
  j["solution"] = solve_report_json(r.solution);
  return j;
}

Json locus_json(const std::vector<sim::SolveReport>& points, const sim::SimulationSpec& spec) {
  const bool friction = spec.contact.mu.has_value();
  Json arr = Json::array();
  for (const auto& p : points) {
    Json q;
    q["period"] = number(p.period);
    q["k"] = number(p.k);
    q["fn_min_ratio"] = number(p.fn_min_ratio);
    q["mu_required"] = number(p.mu_required);
    q["friction_margin"] = number(p.friction_margin);
    q["slips"] = friction && p.friction_margin < 0;
    q["contact_lost"] = p.fn_min_ratio < 0;
    q["failure"] = p.failure.empty() ? Json(nullptr) : Json(p.failure);
    arr.push_back(q);
  }
  Json j;
  j["points"] = arr;
  j["mu"] = friction ? number(*spec.contact.mu) : Json(nullptr);
  return j;
}

Json object_json(const sim::ObjectSpec& o) {
  Json j;
  j["mass"] = number(o.mass);
  if (o.round()) {
    // What the planar dynamics roll: a ball on rails rolls below its own radius with its own
    // inertia (sim::equivalent_disk, the conversion build_problem makes).
    const sim::RollingDisk disk = sim::equivalent_disk(o);
    const char* type = o.kind == sim::ObjectSpec::Kind::kRing   ? "ring"
                       : o.kind == sim::ObjectSpec::Kind::kBall ? "ball"
                                                                : "disk";
    j["type"] = type;
    j["radius"] = number(o.radius);
    j["rolling_radius"] = number(disk.radius);
    j["inertia"] = number(disk.inertia);
  } else {
    j["type"] = "ellipse";
    j["radius"] = nullptr;
    j["rolling_radius"] = nullptr;  // its radius of curvature changes along its outline
    j["inertia"] =
        number(o.inertia ? *o.inertia
                         : sim::make_uniform_ellipse(o.semi_axis_x, o.semi_axis_y, o.mass).inertia);
  }
  return j;
}

Json simulate_json(const sim::SimulationSpec& spec, const sim::RunResult& r) {
  const bool butterfly = spec.motion.kind == sim::MotionSpec::Kind::kButterfly;
  Json j;
  j["period"] = butterfly ? number(spec.motion.period) : Json(nullptr);
  j["k"] = butterfly ? number(spec.motion.k) : Json(nullptr);
  j["s_T"] = number(s_at_half_period(spec, r));
  j["s_end"] = number(r.final.s_h);
  j["sdot_end"] = number(r.final.sdot_h);
  j["fn_apex_ratio"] = number(r.fn_apex_ratio ? *r.fn_apex_ratio : std::nan(""));
  j["fn_min_ratio"] = number(r.fn_min_ratio);
  j["mu_required"] = number(r.mu_required);
  j["steps"] = r.stats.steps;
  j["rhs_evals"] = r.stats.rhs_evals;
  j["contact_lost"] = r.contact_lost || r.fn_min_ratio < 0;
  j["formulation"] = sim::to_string(r.formulation);
  j["method"] = sim::to_string(r.method);
  j["stop_reason"] = sim::to_string(r.reason);
  j["t_end"] = number(r.final.t);
  j["rejected"] = r.stats.rejected;
  j["restarts"] = r.stats.restarts;
  j["junction_crossings"] = r.stats.junction_crossings;
  j["max_constraint_residual"] = number(r.stats.max_constraint_residual);
  j["max_redundant_residual"] = number(r.stats.max_redundant_residual);
  j["model"] = sim::to_string(spec.run.model);
  j["mu"] = spec.contact.mu ? number(*spec.contact.mu) : Json(nullptr);
  j["end_mode"] = sim::to_string(r.final.mode);
  j["mode_changes"] = r.stats.mode_changes;
  j["impacts"] = r.stats.impacts;
  Json modes;
  for (int m = 0; m < 4; ++m)
    modes[sim::to_string(static_cast<sim::ContactMode>(m))] = number(r.stats.mode_time[m]);
  j["mode_time"] = modes;
  j["flights"] = flights_json(sim::flight_reports(r));
  j["events"] = contact_events_json(r.events);
  j["energy"] = energy_json(r.audit);
  j["object"] = object_json(spec.object);
  return j;
}

namespace {
Json vec3(const sim::Vec3& v) { return Json::array({number(v.x()), number(v.y()), number(v.z())}); }
Json param(const sim::SurfaceParam& v) { return Json::array({number(v.x()), number(v.y())}); }
}  // namespace

Json spatial_simulate_json(const sim::SpatialSpec& spec, const sim::SpatialRunResult& r) {
  const sim::SpatialSample& f = r.final;
  const sim::SpatialRunStats& st = r.stats;
  const double e0 = r.initial.energy;
  Json j;
  j["space"] = "3d";
  j["stop_reason"] = sim::to_string(r.stop);
  j["success"] = r.stop == sim::SpatialStop::kEndTime && !r.audit.broken;
  j["t_end"] = number(f.t);                 // where the run stopped, as in a planar report
  j["duration"] = number(spec.end_time());  // what was asked
  Json fin;
  fin["position"] = vec3(f.state.position);
  const Eigen::Quaterniond q = f.state.orientation.normalized();
  fin["orientation_wxyz"] =
      Json::array({number(q.w()), number(q.x()), number(q.y()), number(q.z())});
  fin["velocity"] = vec3(f.state.velocity);
  fin["angular_velocity"] = vec3(f.state.angular_velocity);
  fin["s_h"] = param(f.state.s_h);
  fin["s_o"] = param(f.state.s_o);
  fin["contact"] = vec3(f.contact);
  fin["force"] = vec3(f.force);
  fin["f_n"] = number(f.force_normal);
  fin["mu_required"] = number(f.mu_required);
  fin["energy"] = number(f.energy);
  j["final"] = fin;
  j["mu"] = spec.mu ? number(*spec.mu) : Json(nullptr);
  j["min_f_n"] = number(st.min_force_normal);
  j["max_mu_required"] = number(st.max_mu_required);
  j["energy_change"] = number(f.energy - e0);
  j["method"] = sim::to_string(spec.integrator.method);
  j["steps"] = st.steps;
  j["rejected"] = st.rejected;
  j["rhs_evals"] = st.rhs_evals;
  j["event_evals"] = st.event_evals;
  j["restarts"] = st.restarts;
  j["chart_changes"] = st.chart_changes;
  j["max_constraint_residual"] = number(st.max_constraint_residual);
  j["max_redundant_residual"] = number(st.max_redundant_residual);
  j["max_drift"] = number(st.max_drift);
  j["samples"] = r.samples.size();
  j["energy"] = energy_json(r.audit);
  return j;
}

}  // namespace flatland::api
