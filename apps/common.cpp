#include "common.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <system_error>

#include <glob.h>
#include <sys/wait.h>
#include <unistd.h>

namespace flatland::app {

void add_common_options(CLI::App& cmd, CommonOptions& o, const std::string& out_help, bool plots) {
  cmd.add_option("--scene", o.scene,
                 "Scene file (YAML, SI units; schema in docs/SCENE.md). Default: the bundled "
                 "paper butterfly, " +
                     default_scene_path())
      ->type_name("FILE");
  cmd.add_flag("--json", o.json,
               "Print exactly one JSON object on stdout (lengths in m, times in s; inf/NaN as "
               "null); logs go to stderr. Default: off (human-readable summary)");
  cmd.add_option("--out", o.out, out_help)->type_name("PATH");
  if (plots)
    cmd.add_flag("--no-plot", o.no_plot,
                 "Write the CSV files but no gnuplot scripts or PNG plots (no gnuplot needed). "
                 "Default: off");
  const std::string group = "Integrator (defaults: the scene's simulator settings)";
  o.method_opt = cmd.add_option("--method", o.method,
                                "Integrator: dopri5 (adaptive Dormand-Prince 5(4)), dop853 "
                                "(adaptive Dormand-Prince 8(5,3), for tolerances below ~1e-8) or "
                                "rk4 (fixed step). Default: scene, else dopri5")
                     ->check(CLI::IsMember({"dopri5", "dop853", "rk4"}))
                     ->group(group);
  o.rtol_opt = cmd.add_option("--rtol", o.rtol,
                              "Relative tolerance of dopri5/dop853 (dimensionless, > 0). Default: scene, "
                              "else 1e-10")
                   ->group(group);
  o.atol_opt =
      cmd.add_option(
             "--atol", o.atol,
             "Absolute tolerance of dopri5/dop853 (in the state's units: m, rad, s_h and their rates "
             "per s; > 0). "
             "Default: scene, else 1e-12")
          ->group(group);
  o.step_opt =
      cmd.add_option("--step", o.step, "Fixed step of rk4, s (> 0). Default: scene, else 0.001 s")
          ->group(group);
  o.formulation_opt =
      cmd.add_option("--formulation", o.formulation,
                     "Equations: auto (reduced for a disk), general (the paper's A x = b) or "
                     "reduced (disk only). Default: scene, else auto")
          ->check(CLI::IsMember({"auto", "general", "reduced"}))
          ->group(group);
}

Scene load_scene_with_overrides(const CommonOptions& o) {
  Scene scene = load_scene(o.scene.empty() ? default_scene_path() : o.scene);
  sim::IntegratorSettings& in = scene.sim.run.integrator;
  if (o.method_opt && o.method_opt->count())
    in.method = o.method == "rk4"      ? sim::Method::kRungeKutta4
                : o.method == "dop853" ? sim::Method::kDormandPrince853
                                       : sim::Method::kDormandPrince54;
  if (o.rtol_opt && o.rtol_opt->count()) {
    require_positive("--rtol", o.rtol, "");
    in.rtol = o.rtol;
  }
  if (o.atol_opt && o.atol_opt->count()) {
    require_positive("--atol", o.atol, "");
    in.atol = o.atol;
  }
  if (o.step_opt && o.step_opt->count()) {
    require_positive("--step", o.step, "s");
    in.fixed_step = o.step;
  }
  if (o.formulation_opt && o.formulation_opt->count()) {
    scene.sim.run.formulation = o.formulation == "general"   ? sim::Formulation::kGeneral
                                : o.formulation == "reduced" ? sim::Formulation::kReduced
                                                             : sim::Formulation::kAuto;
  }
  return scene;
}

std::shared_ptr<const sim::RollingProblem> build_problem_checked(
    const sim::SimulationSpec& spec,
    const std::vector<std::pair<std::string, std::string>>& given) {
  try {
    return sim::build_problem(spec);
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    for (const auto& [field, option] : given)
      if (what.rfind(field + ":", 0) == 0) throw UsageError(what + " (set by " + option + ")");
    throw;
  }
}

void require_finite(const std::string& option, double v) {
  if (!std::isfinite(v))
    throw UsageError(option + ": must be a finite number, got " + format_number(v));
}

void require_positive(const std::string& option, double v, const std::string& unit) {
  if (!std::isfinite(v) || !(v > 0))
    throw UsageError(option + ": must be positive and finite" +
                     (unit.empty() ? "" : " (" + unit + ")") + ", got " + format_number(v));
}

void require_increasing(const std::string& from_option, double from, const std::string& to_option,
                        double to) {
  require_finite(from_option, from);
  require_finite(to_option, to);
  if (!(from < to))
    throw UsageError(to_option + ": must be larger than " + from_option + " (got " + from_option +
                     " " + format_number(from) + ", " + to_option + " " + format_number(to) + ")");
}

Json number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

void emit_json(const Json& j) {
  std::cout << j.dump(2) << '\n';
  std::cout.flush();
}

std::string format_number(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

const std::vector<std::string>& sample_columns() {
  static const std::vector<std::string> columns = {"t",
                                                   "theta",
                                                   "theta_dot",
                                                   "theta_ddot",
                                                   "s_h",
                                                   "sdot_h",
                                                   "sddot_h",
                                                   "s_o",
                                                   "sdot_o",
                                                   "x",
                                                   "y",
                                                   "object_angle",
                                                   "vx",
                                                   "vy",
                                                   "omega",
                                                   "f_n",
                                                   "f_t",
                                                   "fn_ratio",
                                                   "ft_ratio",
                                                   "mu_required",
                                                   "constraint_residual",
                                                   "redundant_residual"};
  return columns;
}

int sample_column(const std::string& name) {
  const auto& c = sample_columns();
  for (std::size_t i = 0; i < c.size(); ++i)
    if (c[i] == name) return static_cast<int>(i) + 1;
  throw std::logic_error("no sample column " + name);
}

std::string samples_csv(const std::vector<sim::Sample>& samples) {
  std::string out;
  const auto& cols = sample_columns();
  for (std::size_t i = 0; i < cols.size(); ++i) out += (i ? "," : "") + cols[i];
  out += '\n';
  for (const sim::Sample& s : samples) {
    const double v[] = {s.t,
                        s.theta,
                        s.theta_dot,
                        s.theta_ddot,
                        s.s_h,
                        s.sdot_h,
                        s.sddot_h,
                        s.s_o,
                        s.sdot_o,
                        s.object_position.x(),
                        s.object_position.y(),
                        s.object_angle,
                        s.object_velocity.x(),
                        s.object_velocity.y(),
                        s.object_angular_velocity,
                        s.force_normal,
                        s.force_tangential,
                        s.fn_ratio,
                        s.ft_ratio,
                        s.mu_required,
                        s.constraint_residual,
                        s.redundant_residual};
    static_assert(sizeof v / sizeof v[0] == 22);
    for (std::size_t i = 0; i < sizeof v / sizeof v[0]; ++i) {
      if (i) out += ',';
      out += format_number(v[i]);
    }
    out += '\n';
  }
  return out;
}

// ---- OutputSet --------------------------------------------------------------------------------

OutputSet::~OutputSet() {
  if (committed_) return;
  std::error_code ec;
  for (const auto& [tmp, final_path] : files_) fs::remove(tmp, ec);
  // Innermost first; remove() refuses non-empty directories, which is what we want.
  for (auto it = created_dirs_.rbegin(); it != created_dirs_.rend(); ++it) fs::remove(*it, ec);
}

void OutputSet::ensure_directory(const fs::path& dir) {
  if (dir.empty()) return;
  // Record the missing ancestors (outermost first) before creating them.
  std::vector<fs::path> missing;
  for (fs::path p = fs::absolute(dir).lexically_normal(); !p.empty() && !fs::exists(p);
       p = p.parent_path()) {
    missing.insert(missing.begin(), p);
    if (p == p.parent_path()) break;
  }
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir))
    throw std::runtime_error("cannot create output directory " + dir.string() + ": " +
                             (ec ? ec.message() : "not a directory"));
  created_dirs_.insert(created_dirs_.end(), missing.begin(), missing.end());
}

fs::path OutputSet::reserve(const fs::path& final_path) {
  fs::path tmp = final_path;
  tmp += ".tmp-" + std::to_string(::getpid());
  files_.emplace_back(tmp, final_path);
  return tmp;
}

fs::path OutputSet::reserve_keep_extension(const fs::path& final_path) {
  fs::path tmp = final_path;
  tmp.replace_filename(final_path.stem().string() + ".tmp-" + std::to_string(::getpid()) +
                       final_path.extension().string());
  files_.emplace_back(tmp, final_path);
  return tmp;
}

fs::path OutputSet::stage(const fs::path& final_path, const std::string& content) {
  const fs::path tmp = reserve(final_path);
  std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
  if (!f) throw std::runtime_error("cannot write " + tmp.string());
  f << content;
  f.close();
  if (!f) throw std::runtime_error("error writing " + tmp.string());
  return tmp;
}

void OutputSet::commit() {
  for (const auto& [tmp, final_path] : files_) {
    std::error_code ec;
    fs::rename(tmp, final_path, ec);
    if (ec)
      throw std::runtime_error("cannot rename " + tmp.string() + " to " + final_path.string() +
                               ": " + ec.message());
  }
  committed_ = true;
}

std::vector<std::string> OutputSet::paths() const {
  std::vector<std::string> p;
  for (const auto& f : files_) p.push_back(f.second.string());
  return p;
}

// ---- ProgressBar ------------------------------------------------------------------------------

ProgressBar::ProgressBar(std::string label)
    : label_(std::move(label)), enabled_(::isatty(STDERR_FILENO) == 1) {}

ProgressBar::~ProgressBar() {
  if (drawn_) std::cerr << '\n' << std::flush;
}

void ProgressBar::update(long done, long total) {
  if (!enabled_ || total <= 0) return;
  std::lock_guard lock(mutex_);
  const int percent =
      static_cast<int>(100.0 * static_cast<double>(done) / static_cast<double>(total));
  if (percent == last_percent_) return;  // redraw only when something visible changes
  last_percent_ = percent;
  constexpr int width = 40;
  const int filled = percent * width / 100;
  std::string bar(static_cast<std::size_t>(filled), '=');
  bar.resize(width, ' ');
  std::fprintf(stderr, "\r%s [%s] %3d%% (%ld/%ld)", label_.c_str(), bar.c_str(), percent, done,
               total);
  std::fflush(stderr);
  drawn_ = true;
}

// ---- gnuplot ----------------------------------------------------------------------------------

bool gnuplot_available() {
  const char* path = std::getenv("PATH");
  if (!path) return false;
  std::stringstream ss(path);
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    if (dir.empty()) dir = ".";
    const fs::path p = fs::path(dir) / "gnuplot";
    if (::access(p.c_str(), X_OK) == 0 && !fs::is_directory(p)) return true;
  }
  return false;
}

void require_gnuplot() {
  if (!gnuplot_available())
    throw std::runtime_error(
        "gnuplot not found on PATH; install it (Debian: apt-get install gnuplot-nox) or pass "
        "--no-plot to skip the plots");
}

std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string gnuplot_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("''") : std::string(1, c);
  return q + "'";
}

std::string gnuplot_terminal(int width, int height) {
  const std::string size = " size " + std::to_string(width) + "," + std::to_string(height);
  // pngcairo draws anti-aliased text and lines; plain png (libgd) is the fallback.
  return "if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {\n"
         "  set terminal pngcairo noenhanced" +
         size +
         " font 'Sans,10'\n"
         "} else {\n"
         "  set terminal png noenhanced" +
         size +
         "\n"
         "}\n";
}

void run_plot(OutputSet& outputs, const fs::path& dir, const PlotJob& job) {
  std::string script = "# Generated by flatland. Re-run in this directory with: gnuplot " +
                       job.script_name + "\n" +
                       "if (!exists('datafile')) datafile = " + gnuplot_quote(job.data_name) +
                       "\n" + "if (!exists('outfile')) outfile = " + gnuplot_quote(job.png_name) +
                       "\n" + "set datafile separator comma\n" + gnuplot_terminal(1000, 700) +
                       "set output outfile\n" + job.body + "unset output\n";
  const fs::path script_tmp = outputs.stage(dir / job.script_name, script);
  fs::path data_tmp = dir / job.data_name;
  data_tmp += ".tmp-" + std::to_string(::getpid());  // the staged CSV
  const fs::path png_tmp = outputs.reserve(dir / job.png_name);
  const std::string vars = "datafile=" + gnuplot_quote(data_tmp.filename().string()) +
                           "; outfile=" + gnuplot_quote(png_tmp.filename().string());
  // gnuplot's own output goes to stderr: stdout is reserved for the result (--json).
  const std::string cmd = "cd " + shell_quote(fs::absolute(dir).string()) + " && gnuplot -e " +
                          shell_quote(vars) + " " + shell_quote(script_tmp.filename().string()) +
                          " 1>&2";
  std::cout.flush();
  const int status = std::system(cmd.c_str());
  std::error_code ec;
  if (status == -1 || !WIFEXITED(status) || WEXITSTATUS(status) != 0 || !fs::exists(png_tmp, ec) ||
      fs::file_size(png_tmp, ec) == 0)
    throw std::runtime_error("gnuplot failed on " + (dir / job.script_name).string() +
                             (status != -1 && WIFEXITED(status)
                                  ? " (exit status " + std::to_string(WEXITSTATUS(status)) + ")"
                                  : " (did not run or was killed)"));
}

// ---- reports ----------------------------------------------------------------------------------

double s_at_half_period(const sim::SimulationSpec& spec, const sim::RunResult& r) {
  if (spec.motion.kind != sim::MotionSpec::Kind::kButterfly || r.trajectory.empty())
    return std::nan("");
  const double T = spec.initial.t0 + 0.5 * spec.motion.period;  // as sim::evaluate does
  const double eps = 1e-9 * std::max(1.0, std::abs(T));
  if (T < r.trajectory.t_begin() - eps || T > r.trajectory.t_end() + eps) return std::nan("");
  return r.trajectory.s_h(T);
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
  j["contact_lost"] = r.fn_min_ratio < 0;
  j["simulations"] = r.simulations;
  j["rhs_evals"] = r.rhs_evals;
  return j;
}

std::string solve_report_text(const sim::SolveReport& r) {
  std::ostringstream os;
  os << "  2T (period)        " << format_number(r.period) << " s\n"
     << "  k                  " << format_number(r.k) << "\n"
     << "  s_h(T)             " << format_number(r.s_T) << "\n"
     << "  s_h(2T), rate      " << format_number(r.s_end) << ", " << format_number(r.sdot_end)
     << " 1/s\n"
     << "  f_n at apex / mg   " << format_number(r.fn_apex_ratio) << "\n"
     << "  min f_n / mg       " << format_number(r.fn_min_ratio)
     << (r.fn_min_ratio < 0 ? "  (contact lost: the hand would throw the disk)" : "") << "\n"
     << "  required mu        " << format_number(r.mu_required) << "\n"
     << "  simulations        " << r.simulations << " (" << r.rhs_evals << " rhs evaluations)\n";
  return os.str();
}

void write_solution_outputs(OutputSet& outputs, const fs::path& dir, const sim::RunResult& run,
                            bool no_plot) {
  if (run.trajectory.empty()) throw std::runtime_error("the solution run recorded no trajectory");
  outputs.ensure_directory(dir);
  outputs.stage(dir / "trajectory.csv", samples_csv(run.trajectory.resample(1e-3)));
  if (no_plot) return;
  const std::string t = std::to_string(sample_column("t"));
  auto col = [](const char* name) { return std::to_string(sample_column(name)); };
  run_plot(outputs, dir,
           {"trajectory.gp", "trajectory.csv", "trajectory.png",
            "set multiplot layout 2,1 title 'Butterfly solution'\n"
            "set grid\n"
            "set xlabel 't (s)'\n"
            "set ylabel 'hand angle theta (rad)'\n"
            "plot datafile skip 1 using " +
                t + ":" + col("theta") +
                " with lines lw 2 title 'theta(t)'\n"
                "set ylabel 'hand contact parameter s_h'\n"
                "set yrange [-1.1:1.1]\n"
                "plot datafile skip 1 using " +
                t + ":" + col("s_h") +
                " with lines lw 2 title 's_h(t)'\n"
                "unset multiplot\n"});
  run_plot(outputs, dir,
           {"forces.gp", "trajectory.csv", "forces.png",
            "mu_clip = 2.0  # mu = |f_t|/f_n grows without bound as f_n -> 0\n"
            "set multiplot layout 2,1 title 'Contact forces'\n"
            "set grid\n"
            "set xlabel 't (s)'\n"
            "set ylabel 'force / (m g)'\n"
            "plot datafile skip 1 using " +
                t + ":" + col("fn_ratio") +
                " with lines lw 2 title 'normal f_n/mg', \\\n"
                "     datafile skip 1 using " +
                t + ":" + col("ft_ratio") +
                " with lines lw 2 title 'tangential f_t/mg', 0 with lines lc 'black' notitle\n"
                "set ylabel sprintf('required mu (clipped at %g)', mu_clip)\n"
                "set yrange [0:*]\n"
                "plot datafile skip 1 using " +
                t + ":(column(" + col("mu_required") + ") > mu_clip ? mu_clip : column(" +
                col("mu_required") +
                ")) with lines lw 2 title '|f_t|/f_n'\n"
                "unset multiplot\n"});
}

std::vector<std::string> expand_file_patterns(const std::vector<std::string>& patterns,
                                              const std::string& option) {
  std::vector<std::string> files;
  for (const std::string& p : patterns) {
    glob_t g{};
    const int rc = ::glob(p.c_str(), GLOB_TILDE | GLOB_BRACE, nullptr, &g);
    if (rc == 0)
      for (std::size_t i = 0; i < g.gl_pathc; ++i) files.emplace_back(g.gl_pathv[i]);
    ::globfree(&g);
    if (rc == GLOB_NOMATCH) throw UsageError(option + ": no file matches '" + p + "'");
    if (rc != 0) throw UsageError(option + ": cannot expand '" + p + "'");
  }
  std::sort(files.begin(), files.end());
  files.erase(std::unique(files.begin(), files.end()), files.end());
  return files;
}

}  // namespace flatland::app
