// flatland identify on the command line: bad input is one line naming the option or file:line,
// exit 2, nothing written (docs/CLI.md, docs/IDENTIFY.md).
#include "cli_support.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

namespace {

using flatland_test::CliTestBase;
namespace fs = std::filesystem;
using flatland_test::Result;
using flatland_test::write_text;

class CliIdentify : public CliTestBase {
 protected:
  std::string scene() const {
    return std::string(FLATLAND_ASSET_DIR) + "/scenes/airtable-5deg.yaml";
  }
  /// A plain recording of `rows` rows (t, theta, s_h, sigma), valid unless edited.
  void write_plain(const std::string& name, int rows = 8) const {
    std::string text = "t,theta,s_h,sigma\n";
    for (int i = 0; i < rows; ++i)
      text += std::to_string(0.1 * i) + "," + std::to_string(0.01 * i) + ",-1,0.001\n";
    write_text(dir_ / name, text);
  }
  /// Exit 2, exactly one line on stderr holding `expected`, and no --out directory.
  void expect_refused(const std::string& args, const std::string& expected) const {
    const Result r = run("identify " + args + " --out out");
    EXPECT_EQ(r.code, 2) << args << "\n" << r.err;
    const auto lines = flatland_test::lines_of(r.err);
    ASSERT_EQ(lines.size(), 1u) << args << "\n" << r.err;
    EXPECT_EQ(lines[0].rfind("flatland: error: ", 0), 0u) << lines[0];
    EXPECT_NE(lines[0].find(expected), std::string::npos)
        << "expected '" << expected << "' in: " << lines[0];
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_FALSE(fs::exists(dir_ / "out")) << args;
  }
};

TEST_F(CliIdentify, UnknownParameterNamesAreRefused) {
  write_plain("a.csv");
  expect_refused(scene() + " a.csv --unknowns mu_kinetic,friction",
                 "--unknowns: unknown parameter 'friction' (known: mu_static, mu_kinetic");
  expect_refused(scene() + " a.csv --unknowns drag,drag", "--unknowns: 'drag' given twice");
  expect_refused(scene() + " a.csv --unknowns ,", "--unknowns: an empty name");
}

TEST_F(CliIdentify, BadOptionsAreRefused) {
  write_plain("a.csv");
  expect_refused(scene() + " a.csv --unknowns drag --segment 0", "--segment");
  expect_refused(scene() + " a.csv --unknowns drag --segment -1", "--segment");
  expect_refused(scene() + " a.csv --unknowns drag --max-iterations 0", "--max-iterations");
  expect_refused(scene() + " a.csv --unknowns drag --format csv", "--format: unknown format 'csv'");
  expect_refused(scene() + " a.csv --unknowns drag --encoder a.csv",
                 "--encoder: 1 given but only 0 track.csv recordings take one");
  expect_refused("nope.yaml a.csv --unknowns drag", "nope.yaml");
  expect_refused(scene() + " --unknowns drag", "recordings");
}

TEST_F(CliIdentify, BadRecordingsNameFileAndLine) {
  write_plain("good.csv");
  expect_refused(scene() + " missing.csv --unknowns drag", "RECORDING: no such file: missing.csv");
  expect_refused(scene() + " good.csv --unknowns drag --validate gone.csv",
                 "--validate: no such file: gone.csv");
  write_text(dir_ / "text.csv", "t,theta,s_h,sigma\n0,0,-1,0.001\n0.1,x,-1,0.001\n");
  expect_refused(scene() + " text.csv --unknowns drag", "text.csv:3: theta: not a number: 'x'");
  write_text(dir_ / "back.csv",
             "t,theta,s_h,sigma\n0,0,-1,0.001\n0.2,0,-1,0.001\n0.1,0,-1,0.001\n0.3,0,-1,0.001\n");
  expect_refused(scene() + " back.csv --unknowns drag",
                 "back.csv:4: t 0.1 is not after the previous row's 0.2");
  write_text(dir_ / "nan.csv",
             "t,theta,s_h,sigma\n0,0,-1,0.001\n0.1,0,nan,0.001\n0.2,0,-1,0.001\n0.3,0,-1,0.001\n");
  expect_refused(scene() + " nan.csv --unknowns drag", "nan.csv:3: s_h: not finite");
  write_plain("short.csv", 3);
  expect_refused(scene() + " short.csv --unknowns drag", "short.csv: 3 data rows");
  write_text(dir_ / "nosigma.csv", "t,theta,s_h\n0,0,-1\n0.1,0,-1\n0.2,0,-1\n0.3,0,-1\n");
  expect_refused(scene() + " nosigma.csv --unknowns drag", "no sigma column and no sigma given");
  write_text(dir_ / "what.csv", "a,b,c\n1,2,3\n");
  expect_refused(scene() + " what.csv --unknowns drag",
                 "cannot tell the recording's format from its header");
  write_text(dir_ / "track.csv",
             "frame,t,u,v,sigma_px,quality,state,s_h\n0,0,300,200,0.1,0.9,found,\n");
  expect_refused(scene() + " track.csv --unknowns drag --camera x.yaml",
                 "track.csv recording (track.csv) needs the joint's encoder log");
  write_text(dir_ / "px.csv", "t,u,v,theta,sigma_px\n0,300,200,0,0.1\n");
  expect_refused(scene() + " px.csv --unknowns drag", "--camera: required");
  fs::create_directories(dir_ / "run");
  expect_refused(scene() + " run --unknowns drag", "log.csv: no such file");
}

TEST_F(CliIdentify, AnExistingOutputDirectoryIsKept) {
  write_plain("a.csv");
  fs::create_directories(dir_ / "out");
  write_text(dir_ / "out" / "keep.txt", "mine");
  const Result r = run("identify " + scene() + " a.csv --unknowns drag --out out");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;
  EXPECT_EQ(flatland_test::read_text(dir_ / "out" / "keep.txt"), "mine");
}

TEST_F(CliIdentify, IsListedAndHasHelp) {
  const Result list = run("--help");
  EXPECT_NE(list.out.find("identify"), std::string::npos);
  const Result help = run("identify --help");
  EXPECT_EQ(help.code, 0) << help.err;
  for (const char* option : {"--unknowns", "--segment", "--out", "--json", "--validate", "--camera",
                             "--encoder", "--sigma", "--format"})
    EXPECT_NE(help.out.find(option), std::string::npos) << option;
}

}  // namespace
