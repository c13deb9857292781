// End-to-end tests of `flatland experiment` and `flatland montecarlo`: run the built binary in a
// fresh temporary directory and check exit codes, the JSON, the files, bad input, and that a
// recording replayed through the CLI commands exactly what the recorded run commanded. Numbers are
// checked against what is known independently (the butterfly turns the hand from 0 to pi and
// carries the disk from the palm well, s_h = -1, to the back well, +1; the log ticks at 1 kHz
// from t = -0.25 s), never against numbers the program printed.
#include "cli_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using flatland_test::cells_of;
using flatland_test::have_tool;
using flatland_test::lines_of;
using flatland_test::quote;
using flatland_test::read_text;
using flatland_test::Result;
using flatland_test::write_text;
using nlohmann::json;

/// A CSV file as a header and rows of cells.
struct Csv {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;
  /// Index of the column whose name is `name` or starts with "name[" (the unit); -1 if none.
  int column(const std::string& name) const {
    for (std::size_t i = 0; i < header.size(); ++i)
      if (header[i] == name || header[i].rfind(name + "[", 0) == 0) return static_cast<int>(i);
    return -1;
  }
  /// The text of one column, one line per row.
  std::string column_text(const std::string& name) const {
    const int c = column(name);
    std::string s;
    for (const auto& r : rows) s += (c >= 0 && c < static_cast<int>(r.size()) ? r[c] : "?") + "\n";
    return s;
  }
};

Csv read_csv(const fs::path& p) {
  Csv csv;
  const auto lines = lines_of(read_text(p));
  if (lines.empty()) return csv;
  csv.header = cells_of(lines[0]);
  for (std::size_t i = 1; i < lines.size(); ++i) csv.rows.push_back(cells_of(lines[i]));
  return csv;
}

class CliExperimentTest : public flatland_test::CliTestBase {
 protected:
  static json parse_json(const Result& r) {
    json j;
    EXPECT_NO_THROW(j = json::parse(r.out)) << "stdout is not one JSON value:\n" << r.out;
    EXPECT_TRUE(j.is_object());
    return j;
  }

  /// Bad input: exit 2, one line "flatland: error: ..." naming `what`, nothing on stdout, none of
  /// `outs` created.
  void expect_bad_input(const std::string& args, const std::string& what,
                        const std::vector<std::string>& outs = {"out"}) const {
    SCOPED_TRACE(args);
    const Result r = run(args);
    EXPECT_EQ(r.code, 2) << "stderr: " << r.err;
    const auto err = lines_of(r.err);
    ASSERT_EQ(err.size(), 1u) << "stderr: " << r.err;
    EXPECT_EQ(err[0].rfind("flatland: error: ", 0), 0u) << err[0];
    EXPECT_NE(err[0].find(what), std::string::npos)
        << "message does not name " << what << ": " << err[0];
    EXPECT_TRUE(r.out.empty()) << r.out;
    for (const auto& o : outs) EXPECT_FALSE(fs::exists(dir_ / o)) << "created " << o;
  }

  static int temporaries_in(const fs::path& d) {
    int n = 0;
    for (const auto& e : fs::recursive_directory_iterator(d)) {
      const std::string name = e.path().filename().string();
      if (name.find(".tmp-") != std::string::npos || name.find(".partial-") != std::string::npos)
        ++n;
    }
    return n;
  }
};

// --------------------------------------------------------------------------------------------

TEST_F(CliExperimentTest, HelpListsTheOptions) {
  Result r = run("experiment --help");
  EXPECT_EQ(r.code, 0) << r.err;
  for (const char* s : {"--scene", "--controller", "feedback", "open-loop", "--camera", "synthetic",
                        "video:", "v4l2:", "--joint", "log:", "--out", "--record", "--video",
                        "--json", "--no-plot", "airtable-feedback.yaml", "REQUIRED"})
    EXPECT_NE(r.out.find(s), std::string::npos) << "help does not mention " << s << ":\n" << r.out;
  r = run("montecarlo --help");
  EXPECT_EQ(r.code, 0) << r.err;
  for (const char* s : {"--n", "--seed", "--controller", "--threads", "--s-h", "--tilt-deg",
                        "--radius-rel", "--noise-dn", "--latency", "--latency-jitter", "--drop",
                        "--friction-rel", "--contact-rel", "--out", "--json"})
    EXPECT_NE(r.out.find(s), std::string::npos) << "help does not mention " << s << ":\n" << r.out;
  r = run("--help");
  EXPECT_NE(r.out.find("experiment"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("montecarlo"), std::string::npos) << r.out;
}

TEST_F(CliExperimentTest, BadInputExits2AndWritesNothing) {
  expect_bad_input("experiment --controller closed --out out", "--controller");
  expect_bad_input("experiment --out out --camera webcam", "--camera");
  expect_bad_input("experiment --out out --joint encoder", "--joint");
  // A synthetic camera films the simulated joint: a joint log cannot drive it.
  expect_bad_input("experiment --out out --joint log:rec", "--joint");
  // A recorded camera needs its recorded joint.
  expect_bad_input("experiment --out out --camera video:rec", "--joint");
  expect_bad_input("experiment --out out --camera video:missing --joint log:missing", "missing");
  expect_bad_input("experiment --out out --scene missing.yaml", "cannot read scene file");
  expect_bad_input("experiment --json", "--out");
  // --record inside --out would be swept into the outputs.
  expect_bad_input("experiment --out out --record out/rec", "--record", {"out"});
  if (!fs::exists("/dev/video63")) {
    // No live joint driver exists: a live camera alone is refused before the device is touched.
    expect_bad_input("experiment --out out --camera v4l2:63", "no live joint driver");
    // With a joint log, the missing device is what is wrong.
    fs::create_directories(dir_ / "j");
    write_text(dir_ / "j" / "joint.csv", "tick,t,theta,theta_dot,theta_ddot_cmd\n0,-0.25,0,0,0\n");
    expect_bad_input("experiment --out out --camera v4l2:63 --joint log:j", "v4l2:63");
  }
  // An existing, non-empty --out is refused and left alone.
  fs::create_directories(dir_ / "full");
  write_text(dir_ / "full" / "keep.txt", "x");
  const Result r = run("experiment --out full");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;
  EXPECT_EQ(read_text(dir_ / "full" / "keep.txt"), "x");
  EXPECT_FALSE(fs::exists(dir_ / "full" / "log.csv"));

  expect_bad_input("montecarlo --n 0", "--n");
  expect_bad_input("montecarlo --controller closed", "--controller");
  expect_bad_input("montecarlo --drop 1", "--drop");
  expect_bad_input("montecarlo --tilt-deg -1", "--tilt-deg");
  expect_bad_input("montecarlo --latency 0.01 --latency-jitter 0.02", "--latency-jitter");
  expect_bad_input("montecarlo --out full", "--out", {});
  expect_bad_input("montecarlo --contact-rel 1", "--contact-rel");
  // Unknown controllers are named with the known ones; a name given twice (comma list or
  // repeated option) is refused.
  expect_bad_input("montecarlo --controller open-loop,closed --out out",
                   "--controller: unknown type 'closed' (known: open-loop, feedback, paper");
  expect_bad_input("montecarlo --controller paper --controller paper --out out",
                   "--controller: paper given twice");
  expect_bad_input("montecarlo --controller paper,open-loop,paper --out out", "given twice");

  // Friction is always counted: a synthetic world needs the scene's contact.mu.
  std::string scene = read_text(fs::path(FLATLAND_ASSET_DIR) / "scenes" / "airtable-feedback.yaml");
  for (const char* key : {"  mu: ", "  mu_kinetic: "}) {
    const auto at = scene.find(key);
    ASSERT_NE(at, std::string::npos) << key;
    scene.erase(at, scene.find('\n', at) + 1 - at);
  }
  write_text(dir_ / "frictionless.yaml", scene);
  expect_bad_input("experiment --scene frictionless.yaml --out out", "contact.mu");
  expect_bad_input("montecarlo --n 2 --scene frictionless.yaml --out out", "contact.mu");
}

TEST_F(CliExperimentTest, SyntheticFeedbackRunWritesTheLogResultPlotsAndVideo) {
  const bool plots = have_tool("gnuplot");
  const std::string args =
      std::string("experiment --out run --video --json") + (plots ? "" : " --no-plot");
  const Result r = run(args);
  if (r.code == 1 && r.err.find("MP4 writer") != std::string::npos)
    GTEST_SKIP() << "no MP4 encoder here: " << r.err;
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  for (const char* k :
       {"success", "duration_s", "s_end", "fn_min_ratio", "mu_max", "frames", "frames_lost",
        "safe_stop", "stop_reason", "failure", "k", "period", "controller", "camera", "nees_mean",
        "measurements", "estimator_steps", "hand_acceleration"})
    EXPECT_TRUE(j.contains(k)) << "missing key " << k << "\n" << r.out;
  // The paper's feedback experiment succeeds on its own scene.
  EXPECT_EQ(j.value("success", false), true) << r.out;
  EXPECT_TRUE(j["failure"].is_null()) << r.out;
  EXPECT_EQ(j.value("safe_stop", true), false) << r.out;
  EXPECT_EQ(j.value("controller", ""), "feedback");
  EXPECT_EQ(j.value("camera", ""), "synthetic");
  ASSERT_TRUE(j["s_end"].is_number()) << r.out;
  EXPECT_NEAR(j["s_end"].get<double>(), 1.0, 0.1) << "the disk ends in the back well";
  EXPECT_DOUBLE_EQ(j.value("period", 0.0), 4.0);  // the scene's 2T
  // Roughly the paper's 4.23 s execution of a 4.0 s plan (not a number this test pins).
  ASSERT_TRUE(j["duration_s"].is_number()) << r.out;
  EXPECT_GT(j["duration_s"].get<double>(), 3.5);
  EXPECT_LT(j["duration_s"].get<double>(), 5.5);

  const fs::path d = dir_ / "run";
  std::vector<std::string> files = {"log.csv", "result.json", "video.mp4"};
  if (plots) files.insert(files.end(), {"theta.png", "s_h.png", "theta.gp", "s_h.gp"});
  for (const auto& f : files) {
    EXPECT_TRUE(fs::exists(d / f)) << f;
    if (fs::exists(d / f)) {
      EXPECT_GT(fs::file_size(d / f), 0u) << f;
    }
  }
  EXPECT_EQ(temporaries_in(dir_), 0);
  json saved;
  ASSERT_NO_THROW(saved = json::parse(read_text(d / "result.json")));
  EXPECT_EQ(saved, j) << "result.json is not the --json object";

  // The 1 kHz log: every TickLog field, units in the header, ticks 1 ms apart from -0.25 s.
  const Csv log = read_csv(d / "log.csv");
  for (const char* c : {"t[s]",
                        "theta[rad]",
                        "theta_dot[rad/s]",
                        "command[rad/s^2]",
                        "command_recorded[rad/s^2]",
                        "theta_ddot[rad/s^2]",
                        "theta_ddot_source",
                        "stage",
                        "s_est",
                        "sdot_est[1/s]",
                        "var_s",
                        "var_sdot[1/s^2]",
                        "estimating",
                        "measured",
                        "s_meas",
                        "t_capture",
                        "nis",
                        "theta_plan[rad]",
                        "s_true",
                        "sdot_true[1/s]",
                        "theta_true[rad]",
                        "fn_ratio",
                        "mu_required",
                        "nees"})
    EXPECT_GE(log.column(c), 0) << "log.csv has no column " << c;
  ASSERT_GT(log.rows.size(), 4000u);
  const int t = log.column("t"), th = log.column("theta"), st = log.column("s_true"),
            me = log.column("measured"), stage = log.column("stage");
  ASSERT_GE(t, 0);
  const int tc = log.column("t_capture");
  long measured = 0;
  bool servo = false;
  for (std::size_t i = 0; i < log.rows.size(); ++i) {
    ASSERT_EQ(log.rows[i].size(), log.header.size()) << "row " << i;
    EXPECT_NEAR(std::stod(log.rows[i][t]), -0.25 + 0.001 * static_cast<double>(i), 1e-9);
    measured += log.rows[i][me] == "1";
    // A measurement arrives the scene's camera.latency (0.033 s) after its capture, and is
    // folded in at the first 1 ms tick after that.
    if (log.rows[i][me] == "1") {
      const double age = std::stod(log.rows[i][t]) - std::stod(log.rows[i][tc]);
      EXPECT_GE(age, 0.033 - 1e-9) << "row " << i;
      EXPECT_LE(age, 0.034 + 1e-9) << "row " << i;
    } else {
      EXPECT_EQ(log.rows[i][tc], "nan") << "row " << i;
    }
    servo = servo || log.rows[i][stage] == "servo";
  }
  EXPECT_TRUE(servo) << "the feedback controller never servoed";
  EXPECT_EQ(measured, j.value("measurements", -1L));
  // The hand turns half a revolution, 0 -> pi; the disk goes from the palm to the back well.
  EXPECT_NEAR(std::stod(log.rows.front()[th]), 0.0, 1e-3);
  EXPECT_NEAR(std::stod(log.rows.back()[th]), std::numbers::pi, 0.02);
  EXPECT_NEAR(std::stod(log.rows.front()[st]), -1.0, 1e-6);
  EXPECT_NEAR(std::stod(log.rows.back()[st]), 1.0, 0.1);

  // The video holds every frame the loop received.
  if (have_tool("ffprobe")) {
    const std::string cmd =
        "cd " + quote(dir_.string()) +
        " && ffprobe -v error -count_frames -select_streams v:0 -show_entries "
        "stream=width,height,nb_read_frames -of json run/video.mp4 > probe.json";
    ASSERT_EQ(std::system(cmd.c_str()), 0);
    json probe;
    ASSERT_NO_THROW(probe = json::parse(read_text(dir_ / "probe.json")));
    ASSERT_EQ(probe["streams"].size(), 1u);
    EXPECT_EQ(probe["streams"][0].value("width", -1), 640);
    EXPECT_EQ(probe["streams"][0].value("height", -1), 480);
    EXPECT_EQ(probe["streams"][0].value("nb_read_frames", ""),
              std::to_string(j.value("frames", -1L)));
  }

  // The same command again: the output exists, nothing is overwritten.
  const std::string before = read_text(d / "log.csv");
  const Result again = run(args);
  EXPECT_EQ(again.code, 2) << again.err;
  EXPECT_NE(again.err.find("--out"), std::string::npos) << again.err;
  EXPECT_EQ(read_text(d / "log.csv"), before);
}

TEST_F(CliExperimentTest, RecordThenReplayCommandsExactlyTheSame) {
  // Open loop: a shorter decision path, but every frame still goes through the tracker and
  // estimator, and the command column still has to match bit for bit.
  const Result rec = run("experiment --controller open-loop --no-plot --out a --record rec --json");
  ASSERT_EQ(rec.code, 0) << rec.err;
  const json jr = parse_json(rec);
  EXPECT_EQ(jr.value("controller", ""), "open-loop");
  EXPECT_TRUE(jr["success"].is_boolean()) << rec.out;
  ASSERT_TRUE(fs::exists(dir_ / "rec" / "recording.json"));
  ASSERT_TRUE(fs::exists(dir_ / "rec" / "joint.csv"));
  ASSERT_TRUE(fs::exists(dir_ / "rec" / "frames.csv"));
  json meta;
  ASSERT_NO_THROW(meta = json::parse(read_text(dir_ / "rec" / "recording.json")));
  EXPECT_EQ(meta.value("camera", ""), "synthetic");

  const Result rep =
      run("experiment --controller open-loop --no-plot --camera video:rec --joint log:rec --out b "
          "--json");
  ASSERT_EQ(rep.code, 0) << rep.err;
  const json jp = parse_json(rep);
  // No truth in a replay.
  for (const char* k : {"success", "s_end", "fn_min_ratio", "mu_max"})
    EXPECT_TRUE(jp[k].is_null()) << k << " in " << rep.out;
  EXPECT_EQ(jp.value("camera", ""), "video:rec");
  EXPECT_EQ(jp["frames"], jr["frames"]);
  EXPECT_EQ(jp["measurements"], jr["measurements"]);

  const Csv a = read_csv(dir_ / "a" / "log.csv");
  const Csv b = read_csv(dir_ / "b" / "log.csv");
  ASSERT_FALSE(a.rows.empty());
  EXPECT_EQ(b.rows.size(), a.rows.size());
  EXPECT_EQ(b.column_text("t"), a.column_text("t"));
  EXPECT_EQ(b.column_text("command"), a.column_text("command"))
      << "the replay commanded differently";
  EXPECT_EQ(b.column_text("s_est"), a.column_text("s_est"));
  EXPECT_EQ(temporaries_in(dir_), 0);
}

TEST_F(CliExperimentTest, RecordThenReplayFeedback) {
  const Result rec = run("experiment --no-plot --out a --record rec --json");
  ASSERT_EQ(rec.code, 0) << rec.err;
  const Result rep = run("experiment --no-plot --camera video:rec --joint log:rec --out b --json");
  ASSERT_EQ(rep.code, 0) << rep.err;
  const json jr = parse_json(rec), jp = parse_json(rep);
  EXPECT_EQ(jp["frames"], jr["frames"]);
  EXPECT_EQ(jp["safe_stop"], jr["safe_stop"]);
  const Csv a = read_csv(dir_ / "a" / "log.csv");
  const Csv b = read_csv(dir_ / "b" / "log.csv");
  ASSERT_FALSE(a.rows.empty());
  EXPECT_EQ(b.column_text("command"), a.column_text("command"))
      << "the replay commanded differently";
  EXPECT_EQ(b.column_text("stage"), a.column_text("stage"));
  // The replay logs the recorded command beside its own; a run that records has none to show.
  EXPECT_EQ(b.column_text("command_recorded"), a.column_text("command"));
  const int recorded = a.column("command_recorded");
  ASSERT_GE(recorded, 0);
  for (const auto& row : a.rows) ASSERT_EQ(row[recorded], "nan");
  // The estimator propagated with the readings' acceleration at every tick it ran: the result
  // counts the ticks by source, and log.csv names the source of each.
  for (const json* j : {&jr, &jp}) {
    ASSERT_TRUE(j->contains("hand_acceleration")) << rep.out;
    EXPECT_EQ((*j)["hand_acceleration"].value("command", -1), 0);
    EXPECT_GT((*j)["hand_acceleration"].value("readings", 0), 4000);
  }
  const int source = b.column("theta_ddot_source");
  ASSERT_GE(source, 0);
  EXPECT_EQ(b.rows.front()[source], "command");  // the first tick has no reading before it
  for (std::size_t i = 1; i < b.rows.size(); ++i) ASSERT_EQ(b.rows[i][source], "readings") << i;
}

TEST_F(CliExperimentTest, MonteCarloWritesRunsAndCounts) {
  const Result r = run("montecarlo --n 2 --seed 5 --threads 2 --out mc --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  for (const char* k : {"runs", "success_open_loop", "success_feedback", "ci95", "perturbations",
                        "runs_per_second"})
    EXPECT_TRUE(j.contains(k)) << "missing key " << k << "\n" << r.out;
  EXPECT_EQ(j.value("runs", -1), 2);
  ASSERT_TRUE(j["ci95"].contains("open_loop") && j["ci95"]["open_loop"].size() == 2u) << r.out;
  ASSERT_TRUE(j["ci95"].contains("feedback") && j["ci95"]["feedback"].size() == 2u) << r.out;
  EXPECT_DOUBLE_EQ(j["perturbations"].value("tilt_deg", 0.0), 0.25);
  EXPECT_DOUBLE_EQ(j["perturbations"].value("drop", 0.0), 0.02);
  // runs.csv: one row per run and controller, the successes adding up to the counts.
  const Csv csv = read_csv(dir_ / "mc" / "runs.csv");
  ASSERT_EQ(csv.rows.size(), 4u);
  const int run_col = csv.column("run"), c = csv.column("controller"), s = csv.column("success");
  ASSERT_GE(run_col, 0);
  int ok_open = 0, ok_feedback = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(csv.rows[i][run_col], std::to_string(i / 2));
    EXPECT_EQ(csv.rows[i][c], i % 2 ? "feedback" : "open-loop");
    if (csv.rows[i][s] == "1") (i % 2 ? ok_feedback : ok_open)++;
  }
  EXPECT_EQ(j.value("success_open_loop", -1), ok_open);
  EXPECT_EQ(j.value("success_feedback", -1), ok_feedback);
  // The interval brackets the observed rate.
  const double lo = j["ci95"]["feedback"][0], hi = j["ci95"]["feedback"][1];
  EXPECT_LE(lo, ok_feedback / 2.0);
  EXPECT_GE(hi, ok_feedback / 2.0);
  json saved;
  ASSERT_NO_THROW(saved = json::parse(read_text(dir_ / "mc" / "result.json")));
  EXPECT_EQ(saved["success_feedback"], j["success_feedback"]);
}

// Controllers named in a comma list and by a repeated option, compared on the same worlds: the
// JSON's per-controller summaries and its paired comparison agree with a count over runs.csv, and
// result.json holds the same.
TEST_F(CliExperimentTest, MonteCarloComparesNamedControllersOnTheSameWorlds) {
  const int n = 3;
  const Result r = run("montecarlo --n " + std::to_string(n) +
                       " --seed 7 --controller open-loop,feedback --controller paper --out mc "
                       "--json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  const std::vector<std::string> names = {"open-loop", "feedback", "paper"};
  EXPECT_EQ(j["controllers"].get<std::vector<std::string>>(), names);
  const Csv csv = read_csv(dir_ / "mc" / "runs.csv");
  ASSERT_EQ(csv.rows.size(), 3u * n);
  const int c_run = csv.column("run"), c_ctl = csv.column("controller"),
            c_ok = csv.column("success"), c_s0 = csv.column("s_h0"), c_out = csv.column("outcome"),
            c_mu = csv.column("mu"), c_fn = csv.column("fn_min_ratio");
  ASSERT_GE(c_mu, 0) << "runs.csv has no mu column";
  ASSERT_GE(csv.column("stop_cause"), 0) << "runs.csv has no stop_cause column";
  // success[controller][world], and every controller meets the same drawn world.
  std::map<std::string, std::vector<bool>> ok;
  for (const auto& row : csv.rows) {
    const int w = std::stoi(row[c_run]);
    ok[row[c_ctl]].resize(n);
    ok[row[c_ctl]][w] = row[c_ok] == "1";
    EXPECT_EQ(row[c_s0], csv.rows[3 * w][c_s0]) << "world " << w;
    EXPECT_NE(row[c_out], "numerical_failure");
    EXPECT_GT(std::stod(row[c_mu]), 0);
  }
  ASSERT_EQ(j["summaries"].size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    const json& s = j["summaries"][i];
    SCOPED_TRACE(s.dump());
    EXPECT_EQ(s["controller"], names[i]);
    EXPECT_EQ(s["runs"], n);
    int k = 0, total = 0;
    for (bool b : ok[names[i]]) k += b;
    EXPECT_EQ(s["successes"].get<int>(), k);
    for (const auto& [kind, count] : s["outcomes"].items()) total += count.get<int>();
    EXPECT_EQ(total, n);
    EXPECT_EQ(s["outcomes"]["success"].get<int>(), k);
    EXPECT_EQ(s["fn_min_ratio"]["n"].get<int>(), k);
    if (k > 0) {
      // The worst normal-force margin is the smallest over the successes in runs.csv.
      double worst = 1e300;
      for (const auto& row : csv.rows)
        if (row[c_ctl] == names[i] && row[c_ok] == "1")
          worst = std::min(worst, std::stod(row[c_fn]));
      EXPECT_DOUBLE_EQ(s["fn_min_ratio"]["min"].get<double>(), worst);
      EXPECT_LE(s["friction_use"]["max"].get<double>(), 1.0);
    }
  }
  // The pairs, in order, against a count over the worlds.
  ASSERT_EQ(j["pairs"].size(), 3u);
  std::size_t p = 0;
  for (std::size_t a = 0; a < 3; ++a)
    for (std::size_t b = a + 1; b < 3; ++b, ++p) {
      const json& pair = j["pairs"][p];
      SCOPED_TRACE(pair.dump());
      EXPECT_EQ(pair["a"], names[a]);
      EXPECT_EQ(pair["b"], names[b]);
      int both = 0, only_a = 0, only_b = 0, neither = 0;
      for (int w = 0; w < n; ++w) {
        const bool x = ok[names[a]][w], y = ok[names[b]][w];
        both += x && y;
        only_a += x && !y;
        only_b += !x && y;
        neither += !x && !y;
      }
      EXPECT_EQ(pair["worlds"], n);
      EXPECT_EQ(pair["both"], both);
      EXPECT_EQ(pair["only_a"], only_a);
      EXPECT_EQ(pair["only_b"], only_b);
      EXPECT_EQ(pair["neither"], neither);
      // Exact McNemar: 2 * P[Binomial(d, 1/2) <= min] with d discordant worlds (d <= 3 here).
      const int d = only_a + only_b, m = std::min(only_a, only_b);
      double tail = 0;
      for (int i = 0, binom = 1; i <= m; binom = binom * (d - i) / (i + 1), ++i) tail += binom;
      EXPECT_NEAR(pair["p_value"].get<double>(), std::min(1.0, 2 * tail / (1 << d)), 1e-12);
    }
  // "feedback" is the scene's own type, paper: the same experiment in every world.
  EXPECT_EQ(ok["feedback"], ok["paper"]);
  const json saved = json::parse(read_text(dir_ / "mc" / "result.json"));
  EXPECT_EQ(saved["summaries"], j["summaries"]);
  EXPECT_EQ(saved["pairs"], j["pairs"]);
}

}  // namespace
