// flatland study: speed-accuracy studies (issue #6), one per knob, regenerating docs/ACCURACY.md.
// `sim` is the work-precision diagram of the simulator: for every integrator setting and both
// formulations, the error in s_h(T) and in the solved k* against the CPU time they cost.
// `calibration`: the intrinsics' parameter error and time against views and corner noise.
#include "study.hpp"

#include "flatland/calibration/intrinsics.hpp"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <iostream>
#include <memory>
#include <numbers>
#include <random>
#include <sstream>

namespace flatland::app {

namespace {

struct Setting {
  sim::Method method;
  sim::Formulation formulation;
  double rtol = 0, step = 0;  // rtol for the adaptive methods, step (s) for RK4
};

struct Row {
  Setting set;
  long steps = 0, rhs_evals = 0;
  double s_T = NAN, err_s_T = NAN, cpu_s_T = NAN;
  double k = NAN, err_k = NAN, cpu_k = NAN;
  int simulations = 0;
  std::string failure;  // the integrator's or the search's error, if any
};

sim::SimulationSpec with_setting(sim::SimulationSpec spec, const Setting& s) {
  auto& in = spec.run.integrator;
  in.method = s.method;
  if (s.method == sim::Method::kRungeKutta4) {
    in.fixed_step = s.step;
  } else {
    in.rtol = s.rtol;
    in.atol = s.rtol * 1e-2;  // docs/BENCHMARKS.md's convention: the state is O(1e-2..1)
  }
  spec.run.formulation = s.formulation;
  return spec;
}

// s_h(T) for the scene's motion (one unrecorded run to T) and k* solving s_h(T) = 0, each with
// the CPU time it costs at this setting.
Row measure(const sim::SimulationSpec& base, const Setting& s, double min_cpu) {
  Row r;
  r.set = s;
  const sim::SimulationSpec spec = with_setting(base, s);
  const double period = spec.motion.period;
  try {
    sim::RunOptions o = sim::run_options(spec);
    o.t_end = 0.5 * period;
    o.record = false;
    o.events.stop_on_contact_loss = false;  // as the searches: rolling enforced
    const auto problem = sim::build_problem(spec);
    sim::RunResult run;
    r.cpu_s_T = cpu_per_call([&] { run = sim::simulate(problem, spec.initial, o); }, min_cpu);
    r.s_T = run.final.s_h;
    r.steps = run.stats.steps;
    r.rhs_evals = run.stats.rhs_evals;
    sim::SearchSettings search;
    search.tolerance = 1e-14;  // below every integrator's error, so k* shows the integrator's
    sim::SolveReport rep;
    r.cpu_k = cpu_per_call([&] { rep = sim::solve_k(spec, period, search); }, min_cpu);
    r.k = rep.k;
    r.simulations = rep.simulations;
  } catch (const std::runtime_error& e) {
    r.failure = e.what();
  }
  return r;
}

std::string method_name(const Setting& s) { return sim::to_string(s.method); }

std::string label(const Setting& s) {
  std::ostringstream os;
  os << method_name(s) << " " << sim::to_string(s.formulation) << " ";
  if (s.method == sim::Method::kRungeKutta4)
    os << "h=" << format_number(s.step) << " s";
  else
    os << "rtol=" << format_number(s.rtol);
  return os.str();
}

std::string study_csv(const std::vector<Row>& rows) {
  std::string out =
      "method,formulation,rtol,atol,step,steps,rhs_evals,s_T,err_s_T,cpu_s_T,k,err_k,cpu_k,"
      "simulations\n";
  for (const Row& r : rows) {
    const bool rk4 = r.set.method == sim::Method::kRungeKutta4;
    out += method_name(r.set) + "," + sim::to_string(r.set.formulation) + "," +
           (rk4 ? "nan" : format_number(r.set.rtol)) + "," +
           (rk4 ? "nan" : format_number(r.set.rtol * 1e-2)) + "," +
           (rk4 ? format_number(r.set.step) : "nan") + "," + std::to_string(r.steps) + "," +
           std::to_string(r.rhs_evals) + "," + format_number(r.s_T) + "," +
           format_number(r.err_s_T) + "," + format_number(r.cpu_s_T) + "," + format_number(r.k) +
           "," + format_number(r.err_k) + "," + format_number(r.cpu_k) + "," +
           std::to_string(r.simulations) + "\n";
  }
  return out;
}

// One log-log work-precision plot: error column `ecol` against CPU column `tcol`, a curve per
// (method, formulation). Errors below 1e-16 are drawn at 1e-16 (the reference's own floor).
std::string plot_body(const std::string& title, const std::string& ylabel, int tcol, int ecol) {
  std::string body = "set title '" + title +
                     "'\n"
                     "set logscale xy\n"
                     "set format x '1e%L'\n"
                     "set format y '1e%L'\n"
                     "set grid\n"
                     "set xlabel 'CPU time (s)'\n"
                     "set ylabel '" +
                     ylabel +
                     "'\n"
                     "set key outside right\n"
                     "lift(e) = e < 1e-16 ? 1e-16 : e\n"
                     "sel(m, f, c) = (strcol(1) eq m && strcol(2) eq f) ? column(c) : NaN\n"
                     "plot ";
  const char* methods[] = {"rk4", "dopri5", "dop853"};
  const char* forms[] = {"reduced", "general"};
  const char* colors[] = {"#1b9e77", "#d95f02", "#7570b3"};
  bool first = true;
  for (int m = 0; m < 3; ++m)
    for (int f = 0; f < 2; ++f) {
      if (!first) body += ", \\\n     ";
      first = false;
      body += "datafile skip 1 using (sel('" + std::string(methods[m]) + "','" + forms[f] + "'," +
              std::to_string(tcol) + ")):(lift(sel('" + methods[m] + "','" + forms[f] + "'," +
              std::to_string(ecol) + "))) with linespoints lw 2 pt " +
              std::to_string(f == 0 ? 7 : 5) + " dt " + std::to_string(f == 0 ? 1 : 2) +
              " lc rgb '" + colors[m] + "' title '" + methods[m] + " " + forms[f] + "'";
    }
  return body + "\n";
}

}  // namespace

double cpu_now() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

void run_sim_study(const StudyOptions& o) {
  CommonOptions common;
  common.scene = o.scene;
  Scene scene = load_scene_with_overrides(common);
  sim::SimulationSpec& spec = scene.sim;
  if (spec.motion.kind != sim::MotionSpec::Kind::kButterfly)
    throw UsageError("study sim: the scene's motion must be the butterfly (motion.kind)");
  sim::build_problem(spec);
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();

  // --quick: a few points of each curve, the tightest (the reference) always among them.
  const std::vector<double> steps =
      o.quick ? std::vector<double>{1e-2, 1e-3}
              : std::vector<double>{1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4};
  const std::vector<int> exponents = o.quick
                                         ? std::vector<int>{3, 6, 9, 13}
                                         : std::vector<int>{3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13};
  std::vector<Setting> settings;
  for (auto f : {sim::Formulation::kReduced, sim::Formulation::kGeneral}) {
    for (double h : steps) settings.push_back({sim::Method::kRungeKutta4, f, 0, h});
    for (auto m : {sim::Method::kDormandPrince54, sim::Method::kDormandPrince853})
      for (int e : exponents) settings.push_back({m, f, std::pow(10.0, -e), 0});
  }
  std::cerr << "flatland: study sim: " << settings.size()
            << " settings, 2T = " << format_number(spec.motion.period)
            << " s, k = " << format_number(spec.motion.k) << "\n";
  const double start = cpu_now();
  std::vector<Row> rows;
  {
    ProgressBar bar("study sim");
    for (std::size_t i = 0; i < settings.size(); ++i) {
      rows.push_back(measure(spec, settings[i], o.min_cpu));
      bar.update(static_cast<long>(i + 1), static_cast<long>(settings.size()));
    }
  }
  // Reference: the tightest run of the other formulation (so a formulation's own systematic
  // error cannot cancel in its reference); the tightest is DOP853 at the smallest rtol.
  auto tightest = [&](sim::Formulation f) -> const Row& {
    const Row* best = nullptr;
    for (const Row& r : rows)
      if (r.set.formulation == f && r.set.method == sim::Method::kDormandPrince853 &&
          r.failure.empty() && (!best || r.set.rtol < best->set.rtol))
        best = &r;
    if (!best) throw std::runtime_error("study sim: no DOP853 reference run succeeded");
    return *best;
  };
  const Row& ref_red = tightest(sim::Formulation::kReduced);
  const Row& ref_gen = tightest(sim::Formulation::kGeneral);
  for (Row& r : rows) {
    const Row& ref = r.set.formulation == sim::Formulation::kReduced ? ref_gen : ref_red;
    r.err_s_T = std::abs(r.s_T - ref.s_T);
    r.err_k = std::abs(r.k - ref.k);
  }
  const double seconds = cpu_now() - start;

  OutputSet outputs(o.force);
  std::vector<std::string> written;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "sim.csv", study_csv(rows));
    if (plots) {
      run_plot(outputs, dir,
               {"sim_s_h.gp", "sim.csv", "sim_s_h.png",
                plot_body("Work-precision: s_h(T) of the scene butterfly (2T = " +
                              format_number(spec.motion.period) + " s)",
                          "|s_h(T) - reference|", 10, 9)});
      run_plot(outputs, dir,
               {"sim_k.gp", "sim.csv", "sim_k.png",
                plot_body("Work-precision: k* solving s_h(T) = 0 (2T = " +
                              format_number(spec.motion.period) + " s, one solve_k)",
                          "|k* - reference|", 13, 12)});
    }
    outputs.commit();
    written = outputs.paths();
  }

  if (o.json) {
    Json j;
    j["study"] = "sim";
    j["scene"] = scene.origin;
    j["period"] = spec.motion.period;
    j["k"] = spec.motion.k;
    Json ref;
    ref["reduced"] = {{"method", "dop853"},
                      {"rtol", ref_red.set.rtol},
                      {"s_T", number(ref_red.s_T)},
                      {"k", number(ref_red.k)}};
    ref["general"] = {{"method", "dop853"},
                      {"rtol", ref_gen.set.rtol},
                      {"s_T", number(ref_gen.s_T)},
                      {"k", number(ref_gen.k)}};
    ref["s_T_disagreement"] = number(std::abs(ref_red.s_T - ref_gen.s_T));
    ref["k_disagreement"] = number(std::abs(ref_red.k - ref_gen.k));
    j["reference"] = ref;
    Json arr = Json::array();
    for (const Row& r : rows) {
      Json q;
      q["method"] = method_name(r.set);
      q["formulation"] = sim::to_string(r.set.formulation);
      q["rtol"] = r.set.method == sim::Method::kRungeKutta4 ? Json(nullptr) : Json(r.set.rtol);
      q["step"] = r.set.method == sim::Method::kRungeKutta4 ? Json(r.set.step) : Json(nullptr);
      q["steps"] = r.steps;
      q["rhs_evals"] = r.rhs_evals;
      q["err_s_T"] = number(r.err_s_T);
      q["cpu_s_T"] = number(r.cpu_s_T);
      q["err_k"] = number(r.err_k);
      q["cpu_k"] = number(r.cpu_k);
      q["failure"] = r.failure.empty() ? Json(nullptr) : Json(r.failure);
      arr.push_back(q);
    }
    j["rows"] = arr;
    j["files"] = written;
    j["cpu_seconds"] = seconds;
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland study sim: " << rows.size() << " settings (" << scene.origin << ") in "
     << format_number(std::round(seconds * 100) / 100) << " s CPU\n"
     << "  reference s_h(T): reduced " << format_number(ref_red.s_T) << ", general "
     << format_number(ref_gen.s_T) << "; k*: reduced " << format_number(ref_red.k) << ", general "
     << format_number(ref_gen.k) << "\n";
  for (const Row& r : rows) {
    char line[200];
    std::snprintf(line, sizeof line,
                  "  %-34s err s_h(T) %8.1e in %8.2e s   err k* %8.1e in %8.2e s%s\n",
                  label(r.set).c_str(), r.err_s_T, r.cpu_s_T, r.err_k, r.cpu_k,
                  r.failure.empty() ? "" : ("  FAILED: " + r.failure).c_str());
    os << line;
  }
  for (const auto& p : written) os << "  wrote " << p << "\n";
  std::cout << os.str();
}

// ---- study calibration ------------------------------------------------------------------------

// The camera of tests/calibration/test_calibration_intrinsics.cpp: VGA, f = 800 px, an off-centre principal
// point and barrel distortion, so that every parameter has something to recover.
namespace {

struct CalibTruth {
  cv::Matx33d K{800, 0, 322.5, 0, 800, 237.5, 0, 0, 1};
  cv::Vec<double, 5> dist{-0.2, 0.08, 0.001, -0.0005, 0.0};
  cv::Size size{640, 480};
};

/// `n` views of a chessboard of 9 x 6 inner corners (25 mm squares) at random poses (0.35-0.8 m
/// away, tilted 15-45 deg), every corner at least 10 px inside the image, projected through the
/// truth with cv::projectPoints and perturbed by Gaussian noise of `sigma` px per coordinate.
std::vector<calibration::BoardView> synthetic_views(const CalibTruth& truth, int n, double sigma,
                                                    std::mt19937_64& rng) {
  std::vector<cv::Point3f> board;
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 9; ++c) board.emplace_back(0.025f * c, 0.025f * r, 0.f);
  std::uniform_real_distribution<double> U(0, 1);
  std::normal_distribution<double> N(0, 1);
  std::vector<calibration::BoardView> views;
  while (static_cast<int>(views.size()) < n) {
    const double tilt = (15 + 30 * U(rng)) * std::numbers::pi / 180,
                 phi = 2 * std::numbers::pi * U(rng);
    const cv::Vec3d rvec(tilt * std::cos(phi), tilt * std::sin(phi), U(rng) - 0.5);
    const double z = 0.35 + 0.45 * U(rng);
    const cv::Vec3d tvec((U(rng) - 0.5) * 0.6 * z - 0.1, (U(rng) - 0.5) * 0.45 * z - 0.06, z);
    std::vector<cv::Point2f> px;
    cv::projectPoints(board, rvec, tvec, truth.K, truth.dist, px);
    bool inside = true;
    for (const auto& p : px)
      inside = inside && p.x >= 10 && p.y >= 10 && p.x <= truth.size.width - 11 &&
               p.y <= truth.size.height - 11;
    if (!inside) continue;
    for (auto& p : px) {
      p.x += static_cast<float>(sigma * N(rng));
      p.y += static_cast<float>(sigma * N(rng));
    }
    calibration::BoardView v;
    v.name = "view" + std::to_string(views.size());
    v.image_size = truth.size;
    v.image_points = std::move(px);
    v.object_points = board;
    views.push_back(std::move(v));
  }
  return views;
}

}  // namespace

// The study's rows as an aligned table for the terminal: {JSON key, column header}.
std::string calibration_table(const Json& rows) {
  const std::pair<const char*, const char*> columns[] = {
      {"views", "views"},   {"noise_px", "noise_px"}, {"failures", "failures"},
      {"rms_err_fx", "fx"}, {"rms_err_fy", "fy"},     {"rms_err_cx", "cx"},
      {"rms_err_cy", "cy"}, {"rms_err_k1", "k1"},     {"rms_err_k2", "k2"},
      {"rms_px", "rms_px"}, {"time_s", "time_s"}};
  std::ostringstream os;
  char cell[32];
  for (const auto& [key, header] : columns) {
    std::snprintf(cell, sizeof cell, "%11s", header);
    os << cell;
  }
  os << "\n";
  for (const Json& r : rows) {
    for (const auto& [key, header] : columns) {
      const Json& v = r.at(key);
      if (v.is_number_integer())
        std::snprintf(cell, sizeof cell, "%11lld", v.get<long long>());
      else if (v.is_number())
        std::snprintf(cell, sizeof cell, "%11.3g", v.get<double>());
      else
        std::snprintf(cell, sizeof cell, "%11s", "-");
      os << cell;
    }
    os << "\n";
  }
  return os.str();
}

void run_calibration_study(const StudyOptions& o) {
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();
  const CalibTruth truth;
  const std::vector<int> view_counts = {5, 10, 20, 40};
  const std::vector<double> noises = {0, 0.1, 0.3, 1};
  const int trials = o.quick ? 2 : 8;
  const char* names[] = {"fx", "fy", "cx", "cy", "k1", "k2"};
  const double truth_p[] = {truth.K(0, 0), truth.K(1, 1), truth.K(0, 2),
                            truth.K(1, 2), truth.dist[0], truth.dist[1]};
  std::string csv = "views,noise_px,trials,failures";
  for (const char* nm : names) csv += std::string(",rms_err_") + nm + ",max_err_" + nm;
  csv += ",rms_px,time_s\n";
  Json rows = Json::array();
  std::cerr << "flatland: study calibration: " << view_counts.size() * noises.size() << " cells x "
            << trials << " trials (synthetic corners, cv::projectPoints + Gaussian noise)\n";
  ProgressBar bar("study calibration");
  long done = 0;
  const long total = static_cast<long>(view_counts.size() * noises.size());
  for (int nv : view_counts)
    for (double sigma : noises) {
      std::mt19937_64 rng(1000 * nv + static_cast<int>(sigma * 100));
      double sq[6] = {}, mx[6] = {}, rms = 0, time = 0;
      int ok = 0, failed = 0;
      for (int t = 0; t < trials; ++t) {
        const auto views = synthetic_views(truth, nv, sigma, rng);
        calibration::IntrinsicsOptions opt;
        opt.compute_covariance = false;  // timed: the estimate, not its uncertainty
        const auto t0 = std::chrono::steady_clock::now();
        try {
          const calibration::IntrinsicsResult r = calibration::calibrate_intrinsics(views, opt);
          time += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          const auto p = r.params();
          for (int i = 0; i < 6; ++i) {
            const double e = std::abs(p[static_cast<std::size_t>(i)] - truth_p[i]);
            sq[i] += e * e;
            mx[i] = std::max(mx[i], e);
          }
          rms += r.rms_px;
          ++ok;
        } catch (const std::exception&) {
          ++failed;
        }
      }
      std::string line = std::to_string(nv) + "," + format_number(sigma) + "," +
                         std::to_string(trials) + "," + std::to_string(failed);
      Json q;
      q["views"] = nv;
      q["noise_px"] = sigma;
      q["failures"] = failed;
      for (int i = 0; i < 6; ++i) {
        const double r = ok ? std::sqrt(sq[i] / ok) : std::nan("");
        // Appended piecewise: GCC 12 warns (-Wrestrict, a false positive) on "," + string here.
        line += ',';
        line += format_number(r);
        line += ',';
        line += format_number(ok ? mx[i] : std::nan(""));
        q[std::string("rms_err_") + names[i]] = number(r);
      }
      const double rms_px = ok ? rms / ok : std::nan(""), t_s = ok ? time / ok : std::nan("");
      line += "," + format_number(rms_px) + "," + format_number(t_s) + "\n";
      q["rms_px"] = number(rms_px);
      q["time_s"] = number(t_s);
      csv += line;
      rows.push_back(q);
      bar.update(++done, total);
    }

  OutputSet outputs(o.force);
  std::vector<std::string> written;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "calibration.csv", csv);
    if (plots) {
      // One panel per quantity: error against the number of views, one curve per noise level
      // (rows are views-major with 4 noise levels each: `every 4::i` picks noise level i, so
      // that gnuplot draws each curve as one line).
      auto panel = [](const std::string& title, const std::string& ylabel, int col) {
        std::string b = "set title '" + title + "'\nset ylabel '" + ylabel + "'\nplot ";
        const char* noise[] = {"0", "0.1", "0.3", "1"};
        for (int i = 0; i < 4; ++i)
          b += std::string(i ? ", \\\n     " : "") +
               "datafile skip 1 every 4::" + std::to_string(i) + " using 1:(lift(column(" +
               std::to_string(col) + "))) with linespoints lw 2 pt 7 title 'noise " + noise[i] +
               " px'";
        return b + "\n";
      };
      const std::string head =
          "set logscale xy\nset format y '1e%L'\nset grid\nset xtics (5, 10, 20, 40)\n"
          "set xlabel 'views'\nset key bottom left\nlift(e) = e < 1e-12 ? 1e-12 : e\n"
          "set multiplot layout 2,2 title 'Calibration: RMS parameter error against views'\n";
      run_plot(outputs, dir,
               {"calibration.gp", "calibration.csv", "calibration.png",
                head + panel("fx", "RMS error fx (px)", 5) + panel("cx", "RMS error cx (px)", 9) +
                    panel("k1", "RMS error k1", 13) +
                    "set title 'time'\nset ylabel 'calibration time (s)'\nplot "
                    "datafile skip 1 every 4::2 using 1:18 with "
                    "linespoints lw 2 pt 7 title 'noise 0.3 px'\n"
                    "unset multiplot\n"});
    }
    Json summary;
    summary["study"] = "calibration";
    summary["trials"] = trials;
    summary["rows"] = rows;
    outputs.stage(dir / "calibration.json", summary.dump(2) + "\n");
    outputs.commit();
    written = outputs.paths();
  }
  if (o.json) {
    Json j;
    j["study"] = "calibration";
    j["trials"] = trials;
    j["truth"] = {{"fx", truth_p[0]}, {"fy", truth_p[1]}, {"cx", truth_p[2]},
                  {"cy", truth_p[3]}, {"k1", truth_p[4]}, {"k2", truth_p[5]}};
    j["rows"] = rows;
    j["files"] = written;
    emit_json(j);
    return;
  }
  std::cout << "flatland study calibration: RMS error of each parameter over " << trials
            << " trials (synthetic corners; fx, fy, cx, cy in px)\n"
            << calibration_table(rows);
  for (const auto& p : written) std::cout << "  wrote " << p << "\n";
}

namespace {

void run_study(const StudyOptions& o) {
  if (o.name == "sim") return run_sim_study(o);
  if (o.name == "calibration") return run_calibration_study(o);
  if (o.name == "render") return run_render_study(o);
  if (o.name == "tracker") return run_tracker_study(o);
  if (o.name == "closed-loop") return run_closed_loop_study(o);
  throw UsageError("study: unknown study '" + o.name +
                   "' (available: sim, render, tracker, calibration, closed-loop)");
}

}  // namespace

Command add_study_command(CLI::App& app) {
  auto o = std::make_shared<StudyOptions>();
  CLI::App* cmd = add_command(app, "study");
  cmd->add_option("name", o->name,
                  "Which study: sim, render, tracker, calibration, closed-loop. 'render': the "
                  "renderer's centroid error against cv::projectPoints and its frames/s against "
                  "supersampling and resolution; 'tracker': centre error, latency and lost frames "
                  "of each tracking method against read noise and exposure blur. Both film the "
                  "scene's camera (default scene: assets/scenes/butterfly-camera.yaml)")
      ->required();
  cmd->add_option("--scene", o->scene,
                  "Scene file (YAML). Default: sim, the bundled paper butterfly " +
                      default_scene_path() +
                      " (its motion must be the butterfly); render and tracker, the bundled "
                      "butterfly-camera.yaml (the scene needs a camera); closed-loop, the bundled "
                      "airtable-feedback.yaml; calibration uses no scene")
      ->type_name("FILE");
  cmd->add_flag("--json", o->json,
                "Print exactly one JSON object on stdout (errors, CPU seconds, the references)");
  cmd->add_option("--out", o->out,
                  "Directory for the study's files, created if missing. sim: sim.csv (one row "
                  "per setting: method, formulation, rtol, atol, step in s, steps, rhs_evals, "
                  "s_T, err_s_T, cpu_s_T in s, k, err_k, cpu_k in s, simulations) and sim_s_h.png, "
                  "sim_k.png (log-log) with their gnuplot scripts; calibration: calibration.csv, "
                  "calibration.png, calibration.json; render: render.csv (one row per "
                  "supersampling and resolution), render_error.png, render_fps.png, render.json; "
                  "tracker: tracker.csv (one row per method, exposure and noise level), "
                  "tracker_error.png, tracker_latency.png, tracker.json; closed-loop: "
                  "closed_loop.csv, closed_loop.png, closed_loop.json. Default: no files")
      ->type_name("PATH");
  cmd->add_flag("--no-plot", o->no_plot, "Write the CSV but no plots (no gnuplot needed)");
  add_force_option(*cmd, o->force);
  cmd->add_flag("--quick", o->quick,
                "sim: RK4 at 2 steps and each Dormand-Prince at rtol 1e-3, 1e-6, 1e-9, 1e-13 "
                "(a quarter of the settings); calibration: 2 trials per cell instead of 8 (a few "
                "seconds); closed-loop: 2 "
                "worlds per cell on a 2 x 2 grid (15 Hz and the scene's rate; the scene's "
                "latency and 0.3 s) instead of 30 on 4 x 6; render: supersampling 1, 2, 4 at 2 "
                "resolutions, 4 disk positions (about a second); tracker: every third frame, "
                "exposures 0 and 1/fps, noise 0, 2, 8, 32 DN (a few seconds). Default: off");
  cmd->add_option("--min-cpu", o->min_cpu,
                  "CPU seconds each timing repeats for (> 0; longer is steadier). Default: 0.02")
      ->check(CLI::PositiveNumber);
  return {cmd, [o] { run_study(*o); }};
}

}  // namespace flatland::app
