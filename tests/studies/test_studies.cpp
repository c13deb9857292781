// The studies as library calls (flatland::studies): what a C++ (or Python) user gets back, checked
// against invariants of each study rather than against numbers it printed. The CLI's tests
// (tests/cli/test_cli_study_*.cpp) check the files and JSON that `flatland study` makes of them.
#include "flatland/model/model.hpp"
#include "flatland/studies/calibration_study.hpp"
#include "flatland/studies/closed_loop_study.hpp"
#include "flatland/studies/sim_study.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace studies = flatland::studies;
namespace sim = flatland::sim;
namespace drivers = flatland::drivers;

flatland::Scene bundled(const std::string& name) {
  return flatland::load_scene(std::string(FLATLAND_ASSET_DIR) + "/scenes/" + name);
}

long csv_lines(const std::string& csv) { return std::count(csv.begin(), csv.end(), '\n'); }

TEST(Studies, SimStudyErrorsFallWithTheTolerance) {
  const flatland::Scene scene = bundled("butterfly.yaml");
  studies::SimStudyOptions o;
  o.quick = true;
  o.min_cpu = 0;  // one call per timing: the errors are what is checked
  long calls = 0, last_total = 0;
  o.progress = [&](long done, long total) {
    ++calls;
    EXPECT_EQ(done, calls);
    last_total = total;
  };
  const studies::SimStudyResult r = studies::run_sim_study(scene.sim, o);
  ASSERT_EQ(r.rows.size(), studies::sim_study_settings(true).size());
  EXPECT_EQ(calls, static_cast<long>(r.rows.size()));
  EXPECT_EQ(last_total, calls);
  // The references are each formulation's tightest DOP853 run, and they agree with each other
  // far below the loosest settings' errors.
  for (const auto* ref : {&r.reference_reduced, &r.reference_general}) {
    EXPECT_EQ(ref->setting.method, sim::Method::kDormandPrince853);
    EXPECT_DOUBLE_EQ(ref->setting.rtol, 1e-13);
    EXPECT_TRUE(ref->failure.empty());
  }
  EXPECT_LT(std::abs(r.reference_reduced.k - r.reference_general.k), 1e-9);
  // Along each adaptive curve, the tightest setting is far more accurate than the loosest; every
  // error is measured against the other formulation's reference.
  for (auto method : {sim::Method::kDormandPrince54, sim::Method::kDormandPrince853})
    for (auto f : {sim::Formulation::kReduced, sim::Formulation::kGeneral}) {
      std::vector<const studies::SimStudyRow*> curve;
      for (const auto& row : r.rows)
        if (row.setting.method == method && row.setting.formulation == f) curve.push_back(&row);
      ASSERT_EQ(curve.size(), 4u);
      EXPECT_LT(curve.back()->err_k, 1e-3 * curve.front()->err_k)
          << studies::label(curve.back()->setting);
      const auto& other =
          f == sim::Formulation::kReduced ? r.reference_general : r.reference_reduced;
      EXPECT_DOUBLE_EQ(curve.front()->err_s_T, std::abs(curve.front()->s_T - other.s_T));
    }
  // The CSV: a header and one row per setting, 15 columns each.
  const std::string csv = studies::sim_study_csv(r);
  EXPECT_EQ(csv_lines(csv), static_cast<long>(r.rows.size()) + 1);
  std::istringstream lines(csv);
  for (std::string line; std::getline(lines, line);)
    EXPECT_EQ(std::count(line.begin(), line.end(), ','), 14) << line;
}

TEST(Studies, SimStudyRefusesAMotionThatIsNotTheButterfly) {
  flatland::Scene scene = bundled("butterfly.yaml");
  scene.sim.motion.kind = sim::MotionSpec::Kind::kFixed;
  EXPECT_THROW(studies::run_sim_study(scene.sim), std::invalid_argument);
}

// Its search for k plans from the palm to the back: a line or a circle has neither, refused
// before any setting is measured (no progress call), naming hand.shape.
TEST(Studies, SimStudyRefusesAHandWithoutPalmAndBackBeforeAnyWork) {
  for (const auto shape : {sim::HandSpec::Shape::kLine, sim::HandSpec::Shape::kCircle}) {
    flatland::Scene scene = bundled("butterfly.yaml");
    scene.sim.hand.shape = shape;
    scene.sim.hand.well_radius = 0.2;
    int progress_calls = 0;
    studies::SimStudyOptions o;
    o.quick = true;
    o.progress = [&](long, long) { ++progress_calls; };
    try {
      studies::run_sim_study(scene.sim, o);
      ADD_FAILURE() << "no refusal for " << sim::to_string(shape);
    } catch (const std::invalid_argument& e) {
      EXPECT_EQ(std::string(e.what()).rfind("hand.shape: ", 0), 0u) << e.what();
    }
    EXPECT_EQ(progress_calls, 0);
    EXPECT_THROW(studies::check_sim_study(scene.sim), std::invalid_argument);
  }
  EXPECT_NO_THROW(studies::check_sim_study(bundled("butterfly.yaml").sim));
}

TEST(Studies, CalibrationStudyRecoversTheCameraWithoutNoise) {
  studies::CalibrationStudyOptions o;
  o.quick = true;
  const studies::CalibrationStudyResult r = studies::run_calibration_study(o);
  ASSERT_EQ(r.cells.size(), 16u);
  EXPECT_EQ(r.grid.trials, 2);
  for (const auto& c : r.cells) {
    EXPECT_EQ(c.failures, 0) << c.views << " views, " << c.noise_px << " px";
    EXPECT_EQ(c.trials, 2);
    // Exact corners give the truth to the solver's precision; the reprojection RMS is of the
    // order of the noise (0.1 px noise: 0.1 px RMS, less the fit's degrees of freedom).
    if (c.noise_px == 0) {
      EXPECT_LT(c.rms_error[0], 1e-2) << c.views;  // fx, px
      EXPECT_LT(c.rms_px, 1e-3);
    } else {
      EXPECT_GT(c.rms_px, 0.5 * c.noise_px);
      EXPECT_LT(c.rms_px, 1.5 * c.noise_px);
    }
    for (std::size_t i = 0; i < 6; ++i) EXPECT_LE(c.rms_error[i], c.max_error[i] * (1 + 1e-12));
  }
  EXPECT_EQ(csv_lines(studies::calibration_study_csv(r)), 17);
}

// A world whose drawn radius cannot hold the disk's given inertia (J > m R^2) is recorded as
// invalid_world and left out of its cell's rate; the study goes on. J is put between the two
// worlds' m r^2, so that one of them cannot exist and the other can.
TEST(Studies, ClosedLoopRecordsAWorldThatCannotExistAndGoesOn) {
  flatland::Scene scene = bundled("airtable-feedback.yaml");
  scene.controller.plan = "solve";  // the plan for this disk's own k
  const double m = scene.sim.object.mass, R = scene.sim.object.radius;
  double r_small = 1e9, r_big = 0;
  for (int run = 0; run < 2; ++run) {
    const double r = drivers::perturb(scene, {}, studies::kClosedLoopSeed, run).sim.object.radius;
    r_small = std::min(r_small, r);
    r_big = std::max(r_big, r);
  }
  const double r_fits = std::min(r_big, R);  // the nominal must hold it too
  ASSERT_LT(r_small, r_fits) << "the seed's two draws cannot separate a world that cannot exist";
  scene.sim.object.inertia = m * 0.5 * (r_small * r_small + r_fits * r_fits);
  const auto nominal = flatland::model::compile(scene);
  studies::ClosedLoopGrid grid = studies::closed_loop_grid(*nominal, true);
  grid.cells.resize(1);  // one cell is enough: every cell meets the same draws
  studies::ClosedLoopStudyOptions o;
  o.threads = 2;
  const studies::ClosedLoopStudyResult r = studies::run_closed_loop_study(*nominal, grid, o);
  ASSERT_EQ(r.cells.size(), 1u);
  const auto& c = r.cells[0];
  ASSERT_EQ(c.runs.size(), 2u);
  for (const auto& run : c.runs) {
    const bool cannot_exist = m * run.drawn.radius * run.drawn.radius < *scene.sim.object.inertia;
    EXPECT_EQ(run.outcome == drivers::Outcome::kInvalidWorld, cannot_exist) << run.drawn.radius;
  }
  EXPECT_EQ(c.invalid_worlds, 1);
  int failed = 0;
  for (const auto& [cls, count] : c.failures) failed += count;
  EXPECT_EQ(c.successes + failed + c.numerical_failures + c.invalid_worlds, 2);
  const auto ci = drivers::wilson_interval(c.successes, 1 - c.numerical_failures);
  EXPECT_EQ(c.ci.lo, ci.lo);
  EXPECT_EQ(c.ci.hi, ci.hi);
}

TEST(Studies, ClosedLoopQuickGridHasACellThatMustFail) {
  const auto nominal = flatland::model::compile(bundled("airtable-feedback.yaml"));
  const studies::ClosedLoopGrid grid = studies::closed_loop_grid(*nominal, true);
  // 15 Hz and the scene's 30 Hz, the absurd 300 ms and the scene's 33 ms, and the baseline.
  EXPECT_EQ(grid.rates, (std::vector<double>{15, 30}));
  EXPECT_EQ(grid.latencies, (std::vector<double>{0.033, 0.3}));
  ASSERT_EQ(grid.cells.size(), 5u);
  EXPECT_EQ(grid.cells.back().controller, "open-loop");

  studies::ClosedLoopStudyOptions o;
  o.threads = 2;
  const studies::ClosedLoopStudyResult r = studies::run_closed_loop_study(*nominal, grid, o);
  ASSERT_EQ(r.cells.size(), grid.cells.size());
  for (const auto& c : r.cells) {
    ASSERT_EQ(c.runs.size(), 2u);
    int failed = 0;
    for (const auto& [cls, count] : c.failures) failed += count;
    EXPECT_EQ(c.successes + failed, 2);
    if (c.cell.latency > 0.25) {
      // No frame arrives before the safety monitor's 0.25 s: every run stops safely, for lack
      // of measurements.
      EXPECT_EQ(c.successes, 0);
      EXPECT_EQ(c.failures.count("safe_stop (tracking)") + c.failures.count("safe_stop (camera)"),
                c.failures.size());
    }
  }
  // The scene's own camera with feedback succeeds in both worlds.
  const auto nominal_cell = std::find_if(r.cells.begin(), r.cells.end(), [](const auto& c) {
    return c.cell.controller == "feedback" && c.cell.fps == 30 && c.cell.latency == 0.033;
  });
  ASSERT_NE(nominal_cell, r.cells.end());
  EXPECT_EQ(nominal_cell->successes, 2);
  EXPECT_EQ(csv_lines(studies::closed_loop_study_csv(r)), 6);
}

// The controller axis: every controller meets the very same worlds. "feedback" is the scene's
// own type (paper) in feedback mode, so it and "paper" must agree bit for bit in every world;
// the open loop, on the axis, replaces the baseline.
TEST(Studies, ClosedLoopControllerAxisMeetsIdenticalWorlds) {
  const auto nominal = flatland::model::compile(bundled("airtable-feedback.yaml"));
  ASSERT_EQ(nominal->spec.controller.type, "paper");
  const std::vector<std::string> axis = {"feedback", "paper", "open-loop"};
  studies::ClosedLoopGrid grid = studies::closed_loop_grid(*nominal, true, axis);
  EXPECT_EQ(grid.controllers, axis);
  EXPECT_FALSE(grid.open_loop_baseline);
  // Each controller over the whole 2 x 2 grid, in the axis' order; no baseline.
  ASSERT_EQ(grid.cells.size(), 12u);
  for (std::size_t i = 0; i < grid.cells.size(); ++i)
    EXPECT_EQ(grid.cells[i].controller, axis[i / 4]) << i;
  // Run the scene's own camera only (one cell per controller), to keep the test short.
  std::erase_if(grid.cells, [&](const auto& c) {
    return c.fps != grid.nominal_fps || c.latency != grid.nominal_latency;
  });
  ASSERT_EQ(grid.cells.size(), 3u);
  studies::ClosedLoopStudyOptions o;
  o.threads = 2;
  const studies::ClosedLoopStudyResult r = studies::run_closed_loop_study(*nominal, grid, o);
  ASSERT_EQ(r.cells.size(), 3u);
  const auto& feedback = r.cells[0];
  const auto& paper = r.cells[1];
  const auto& open = r.cells[2];
  EXPECT_EQ(paper.cell.controller, "paper");
  ASSERT_EQ(feedback.runs.size(), 2u);
  for (std::size_t w = 0; w < 2; ++w) {
    SCOPED_TRACE("world " + std::to_string(w));
    for (const auto* c : {&paper, &open}) {
      const flatland::drivers::DrawnPerturbation& a = feedback.runs[w].drawn;
      const flatland::drivers::DrawnPerturbation& b = c->runs[w].drawn;
      EXPECT_TRUE(a == b);
    }
    // The same controller under two names: the same experiment.
    EXPECT_EQ(feedback.runs[w].outcome, paper.runs[w].outcome);
    EXPECT_EQ(feedback.runs[w].fn_min, paper.runs[w].fn_min);
    EXPECT_EQ(feedback.runs[w].frames, paper.runs[w].frames);
    EXPECT_TRUE(feedback.runs[w].duration == paper.runs[w].duration ||
                (std::isnan(feedback.runs[w].duration) && std::isnan(paper.runs[w].duration)));
  }
  // The worlds themselves differ from one another.
  EXPECT_NE(feedback.runs[0].drawn.s_h0, feedback.runs[1].drawn.s_h0);
  // Bad axes are refused with the known names.
  try {
    studies::closed_loop_grid(*nominal, true, {"paper", "bogus"});
    ADD_FAILURE() << "an unknown controller";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("controllers: unknown type 'bogus' (known: open-loop, "
                                         "feedback, paper"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW(studies::closed_loop_grid(*nominal, true, {"paper", "paper"}),
               std::invalid_argument);
  EXPECT_THROW(studies::closed_loop_grid(*nominal, true, {}), std::invalid_argument);
}

TEST(Studies, ClosedLoopNeedsACamera) {
  const auto paper = flatland::model::compile(bundled("butterfly.yaml"));
  try {
    studies::closed_loop_grid(*paper, true);
    ADD_FAILURE() << "a grid without a camera";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(": camera: "), std::string::npos) << e.what();
  }
}

}  // namespace
