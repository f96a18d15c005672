// Mitsuba .wv parser, writer, validation and the built-in weave presets.
#include "libbtf/synth/weave_pattern.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "libbtf/core/directions.h"
#include "libbtf/core/error.h"
#include "tests/test_util.h"

namespace btf {
namespace {

// Message and code of the btf::Error thrown by f (fails the test if none is thrown).
template <typename F>
std::pair<ExitCode, std::string> Thrown(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return {e.code(), e.what()};
  }
  ADD_FAILURE() << "no btf::Error thrown";
  return {ExitCode::kOk, ""};
}

// A small valid pattern in Mitsuba's own style (comments, degrees, $variables).
const char* kPlain = R"(/* a plain weave */
weave {
  name = "test plain",
  tileWidth = 2, tileHeight = 2,
  alpha = 0.015, beta = 4, ss = 0.5, hWidth = 0.5,
  warpArea = 1, weftArea = 1,
  dWarpUmaxOverDWarp = 8, dWarpUmaxOverDWeft = 8,
  dWeftUmaxOverDWarp = 6, dWeftUmaxOverDWeft = 6, period = 50,
  pattern { 3, 2,
            1, 4 },
  yarn { type = warp, umax = 22, kappa = -0.7, width = 1, length = 1, centerU = 0.25, centerV = 0.25,
         kd = $warp_kd, ks = {0.3, 0.3, 0.3} },
  yarn { type = warp, umax = 22, kappa = -0.7, width = 1, length = 1, centerU = 0.75, centerV = 0.75,
         kd = $warp_kd, ks = {0.3, 0.3, 0.3} },
  yarn { type = weft, psi = $twist, umax = 16, kappa = -0.7, width = 1, length = 1, centerU = 0.25, centerV = 0.75,
         kd = {0.1, 0.2, 0.3}, ks = {0.3, 0.3, 0.3} },
  yarn { type = weft, psi = $twist, umax = 16, kappa = -0.7, width = 1, length = 1, centerU = 0.75, centerV = 0.25,
         kd = {0.1, 0.2, 0.3}, ks = {0.3, 0.3, 0.3} }
}
)";

const nlohmann::json kVars = {{"warp_kd", {0.5, 0.45, 0.38}}, {"twist", 20}};

TEST(WeavePattern, ParsesMitsubaSyntaxWithVariables) {
  const WeavePattern p = ParseWeavePattern(kPlain, "plain.wv", kVars);
  EXPECT_EQ(p.name, "test plain");
  EXPECT_EQ(p.tile_width, 2);
  EXPECT_EQ(p.tile_height, 2);
  EXPECT_DOUBLE_EQ(p.alpha, 0.015);
  EXPECT_DOUBLE_EQ(p.beta, 4);
  EXPECT_DOUBLE_EQ(p.ss, 0.5);
  EXPECT_DOUBLE_EQ(p.period, 50);
  // Angles are stored in radians (the text is in degrees).
  EXPECT_NEAR(p.d_warp_umax_over_d_warp, DegToRad(8), 1e-15);
  EXPECT_NEAR(p.d_weft_umax_over_d_weft, DegToRad(6), 1e-15);
  ASSERT_EQ(p.yarns.size(), 4u);
  EXPECT_EQ(p.pattern, (std::vector<int>{3, 2, 1, 4}));
  EXPECT_EQ(p.yarns[0].type, WeaveYarn::Type::kWarp);
  EXPECT_EQ(p.yarns[2].type, WeaveYarn::Type::kWeft);
  EXPECT_NEAR(p.yarns[0].umax, DegToRad(22), 1e-15);
  EXPECT_NEAR(p.yarns[2].psi, DegToRad(20), 1e-15);
  EXPECT_DOUBLE_EQ(p.yarns[0].kd[1], 0.45);
  EXPECT_DOUBLE_EQ(p.yarns[2].kd[2], 0.3);
  EXPECT_TRUE(std::isnan(p.yarns[0].alpha));  // no per-yarn override: the weave's value applies
  EXPECT_DOUBLE_EQ(p.AlphaOf(p.yarns[0]), 0.015);
  // Top row of the text is the top of the tile: cell (0, 0) = yarn 3.
  EXPECT_EQ(&p.YarnAt(0, 0), &p.yarns[2]);
}

void ExpectSame(const WeavePattern& a, const WeavePattern& b) {
  // The writer prints 17 significant digits; angles go through a degree conversion and back.
  constexpr double kTol = 1e-13;
  EXPECT_EQ(a.name, b.name);
  EXPECT_EQ(a.tile_width, b.tile_width);
  EXPECT_EQ(a.tile_height, b.tile_height);
  EXPECT_EQ(a.pattern, b.pattern);
  for (auto [x, y] : {std::pair{a.alpha, b.alpha}, {a.beta, b.beta}, {a.ss, b.ss}, {a.h_width, b.h_width},
                      {a.warp_area, b.warp_area}, {a.weft_area, b.weft_area}, {a.fineness, b.fineness},
                      {a.period, b.period}, {a.d_warp_umax_over_d_warp, b.d_warp_umax_over_d_warp},
                      {a.d_warp_umax_over_d_weft, b.d_warp_umax_over_d_weft},
                      {a.d_weft_umax_over_d_warp, b.d_weft_umax_over_d_warp},
                      {a.d_weft_umax_over_d_weft, b.d_weft_umax_over_d_weft}})
    EXPECT_NEAR(x, y, kTol);
  ASSERT_EQ(a.yarns.size(), b.yarns.size());
  for (std::size_t i = 0; i < a.yarns.size(); ++i) {
    const auto &p = a.yarns[i], &q = b.yarns[i];
    EXPECT_EQ(p.type, q.type);
    for (auto [x, y] : {std::pair{p.psi, q.psi}, {p.umax, q.umax}, {p.kappa, q.kappa}, {p.width, q.width},
                        {p.length, q.length}, {p.center_u, q.center_u}, {p.center_v, q.center_v}})
      EXPECT_NEAR(x, y, kTol);
    for (int c = 0; c < 3; ++c) {
      EXPECT_DOUBLE_EQ(p.kd[c], q.kd[c]);
      EXPECT_DOUBLE_EQ(p.ks[c], q.ks[c]);
    }
    for (auto [x, y] : {std::pair{p.alpha, q.alpha}, {p.beta, q.beta}, {p.ss, q.ss}}) {
      EXPECT_EQ(std::isnan(x), std::isnan(y));
      if (!std::isnan(x)) {
        EXPECT_DOUBLE_EQ(x, y);
      }
    }
  }
}

TEST(WeavePattern, RoundTripEveryPreset) {
  for (const auto& name : WeavePresetNames()) {
    SCOPED_TRACE(name);
    const WeavePattern p = WeavePreset(name);
    const std::string text = FormatWeavePattern(p);
    ExpectSame(p, ParseWeavePattern(text, "roundtrip:" + name));
  }
  const WeavePattern q = ParseWeavePattern(kPlain, "plain.wv", kVars);
  ExpectSame(q, ParseWeavePattern(FormatWeavePattern(q), "roundtrip"));
}

TEST(WeavePattern, LoadsFromFileAndReportsMissingFile) {
  const auto dir = test::TempDir();
  const auto path = dir / "plain.wv";
  std::ofstream(path) << kPlain;
  const WeavePattern p = LoadWeavePattern(path, kVars);
  EXPECT_EQ(p.yarns.size(), 4u);
  const auto [code, msg] = Thrown([&] { LoadWeavePattern(dir / "missing.wv"); });
  EXPECT_EQ(code, ExitCode::kIo);
  EXPECT_NE(msg.find("missing.wv"), std::string::npos) << msg;
}

TEST(WeavePattern, SyntaxErrorsNameFileAndLine) {
  struct Case {
    std::string text, expect_in_message;
  };
  const std::vector<Case> cases = {
      {"weave {\n  name = \"x\",\n  tileWidht = 2\n}", "bad.wv:3: unknown weave item 'tileWidht'"},
      {"weave {\n  tileWidth = 2.5\n}", "bad.wv:2: expected an integer for 'tileWidth'"},
      {"weave {\n tileWidth = 1, tileHeight = 1,\n pattern { 1 },\n yarn { type = wrap }\n}",
       "bad.wv:4: yarn type must be 'warp' or 'weft'"},
      {"weave {\n yarn { umax = $nope }\n}", "bad.wv:2: variable '$nope' is not defined"},
      {"weave {\n tileWidth = 1\n", "bad.wv:3: expected ',' or '}' after 'tileWidth', found end of file"},
      {"/* never closed\nweave {}", "bad.wv:1: unterminated comment"},
      {"weave {\n yarn { kd = {1, 2} }\n}", "bad.wv:2: expected ','"},
      {"weave { tileWidth = 1 } extra", "unexpected 'extra'"},
      {"weave {\n yarn { colour = 1 }\n}", "bad.wv:2: unknown yarn item 'colour'"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.text);
    const auto [code, msg] = Thrown([&] { ParseWeavePattern(c.text, "bad.wv"); });
    EXPECT_EQ(code, ExitCode::kBadInput);
    EXPECT_NE(msg.find(c.expect_in_message), std::string::npos) << msg;
  }
}

// Replaces the first occurrence of `from` in the plain pattern.
std::string PlainWith(const std::string& from, const std::string& to) {
  std::string s = kPlain;
  const auto pos = s.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  return s.replace(pos, from.size(), to);
}

TEST(WeavePattern, SemanticErrorsNameTheItem) {
  struct Case {
    std::string text, expect;
  };
  const std::vector<Case> cases = {
      {PlainWith("pattern { 3, 2,", "pattern { 3, 2, 1,"), "'pattern' has 5 entries, expected tileWidth x tileHeight = 4"},
      {PlainWith("pattern { 3, 2,", "pattern { 5, 2,"), "refers to yarn 5, but only yarns 1..4 exist"},
      {PlainWith("kappa = -0.7", "kappa = -1"), "yarn 1 (warp): kappa = -1 must be > -1"},
      {PlainWith("kappa = -0.7", "kappa = -1.5"), "yarn 1 (warp): kappa = -1.5 must be > -1"},
      {PlainWith("umax = 16", "umax = 0"), "yarn 3 (weft): a staple yarn (psi != 0) needs umax > 0"},
      {PlainWith("ss = 0.5", "ss = 1"), "ss must lie in [0, 1)"},
      {PlainWith("hWidth = 0.5", "hWidth = 0"), "hWidth must lie in (0, 1]"},
      {PlainWith("centerU = 0.25, centerV = 0.25", "centerU = 0.75, centerV = 0.25"),
       "pattern cell (column 0, row 1 from the top) lies outside the segment of yarn 1"},
      {PlainWith("umax = 22", "umax = 95"), "umax must lie in [0, 90] degrees"},
      {PlainWith("warpArea = 1", "warpArea = 0"), "warpArea must be > 0"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.expect);
    const auto [code, msg] = Thrown([&] { ParseWeavePattern(c.text, "sem.wv", kVars); });
    EXPECT_EQ(code, ExitCode::kBadInput);
    EXPECT_NE(msg.find(c.expect), std::string::npos) << msg;
    EXPECT_NE(msg.find("sem.wv"), std::string::npos) << msg;
  }
  // A staple umax of exactly 0 is rejected, a filament one is legal (its highlight is empty).
  EXPECT_NO_THROW(ParseWeavePattern(PlainWith("umax = 22", "umax = 0"), "f.wv", kVars));
}

TEST(WeavePattern, UnknownPresetListsTheKnownOnes) {
  const auto [code, msg] = Thrown([] { WeavePreset("cotton_velour"); });
  EXPECT_EQ(code, ExitCode::kUsage);
  EXPECT_NE(msg.find("cotton_denim"), std::string::npos) << msg;
  EXPECT_NE(msg.find("velvet"), std::string::npos) << msg;
}

// The six Mitsuba/Lux presets: warpArea:weftArea equals the pattern's warp:weft cell count
// (docs/btf-synth.md, "Irawan 2012"); our Sadeghi layouts are built so that it does too.
TEST(WeavePattern, PresetAreasMatchCellCounts) {
  ASSERT_EQ(WeavePresetNames().size(), 12u);
  for (const auto& name : WeavePresetNames()) {
    SCOPED_TRACE(name);
    const WeavePattern p = WeavePreset(name);
    int warp = 0, weft = 0;
    for (int idx : p.pattern) (p.yarns[static_cast<std::size_t>(idx - 1)].type == WeaveYarn::Type::kWarp ? warp : weft)++;
    EXPECT_NEAR(p.warp_area / (p.warp_area + p.weft_area), static_cast<double>(warp) / (warp + weft), 1e-12);
  }
}

}  // namespace
}  // namespace btf
