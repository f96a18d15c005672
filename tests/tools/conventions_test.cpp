// The conventions every tool shares (docs/architecture.md, "Options, summaries and tools" and
// "JSON output"): --version, and one envelope and timing schema in every --json document.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "libbtf/core/version.h"
#include "tests/test_util.h"

namespace btf {
namespace {

TEST(ToolConventions, EveryToolPrintsItsVersion) {
  for (const char* tool : {"btf-info", "btf-synth", "btf-register", "btf-compress", "btf-eval", "btf-convert"}) {
    std::string out;
    ASSERT_EQ(test::RunCommand(test::Tool(tool) + " --version", &out), 0) << tool;
    EXPECT_EQ(out, std::string(tool) + " " + Version() + "\n") << tool;
  }
}

// Checks the envelope and returns the document.
nlohmann::json CheckEnvelope(const std::string& command, const std::string& tool) {
  std::string out;
  EXPECT_EQ(test::RunCommand(command + " --json --quiet", &out), 0) << command;
  const nlohmann::json j = nlohmann::json::parse(out);
  EXPECT_EQ(j.value("tool", ""), tool) << command;
  EXPECT_EQ(j.value("version", ""), Version()) << command;
  EXPECT_EQ(j.value("schema_version", 0), kJsonSchemaVersion) << command;
  EXPECT_TRUE(j.contains("options") && j["options"].is_object()) << command;
  // Outside mpirun: one rank, and its figures (docs/scaling.md).
  EXPECT_EQ(j.value("ranks", 0), 1) << command;
  EXPECT_EQ(j.value("per_rank", nlohmann::json::array()).size(), 1u) << command;
  if (j.contains("per_rank") && !j["per_rank"].empty()) {
    EXPECT_EQ(j["per_rank"][0].value("rank", -1), 0) << command;
    EXPECT_GT(j["per_rank"][0].value("peak_rss_bytes", 0.0), 0) << command;
    EXPECT_GE(j["per_rank"][0].value("seconds", -1.0), 0) << command;
  }
  return j;
}

// The timing schema: {"phase": s, ..., "total": s}, total = the sum of the phases.
void CheckSeconds(const nlohmann::json& seconds, const std::string& what) {
  ASSERT_TRUE(seconds.is_object()) << what;
  ASSERT_TRUE(seconds.contains("total")) << what;
  double sum = 0;
  for (const auto& [k, v] : seconds.items()) {
    ASSERT_TRUE(v.is_number()) << what << " " << k;
    EXPECT_GE(v.get<double>(), 0) << what << " " << k;
    if (k != "total") sum += v.get<double>();
  }
  if (seconds.size() > 1) {  // phases and their total (a bare {"total": s} has no phases)
    EXPECT_NEAR(seconds["total"].get<double>(), sum, 1e-9 + 1e-12 * sum) << what;
  }
}

TEST(ToolConventions, EveryJsonDocumentHasTheEnvelopeAndTimingSchema) {
  const auto dir = test::TempDir();
  const std::string d = dir.string() + "/";
  const std::string synth = test::Tool("btf-synth"), comp = test::Tool("btf-compress");
  auto j = CheckEnvelope(synth + " btf --views 0,1,7 --lights 0,3,9,20 --resolution 8 --samples 1 -o " + d + "a.h5",
                         "btf-synth");
  CheckSeconds(j["seconds"], "btf-synth btf");
  // Effective options: given values and the options struct's defaults, subcommands nested.
  EXPECT_EQ(j["options"]["btf"]["resolution"], 8);
  EXPECT_EQ(j["options"]["btf"]["samples"], 1);
  EXPECT_EQ(j["options"]["btf"]["model"], "irawan2006");
  EXPECT_TRUE(j["options"]["btf"]["tiles"].is_number());

  j = CheckEnvelope(comp + " " + d + "a.h5 --method lpca --clusters 2 --components 2 -o " + d + "c.h5", "btf-compress");
  CheckSeconds(j["seconds"], "btf-compress");
  EXPECT_EQ(j["options"]["method"], "lpca");
  EXPECT_EQ(j["options"]["clusters"], 2);
  EXPECT_EQ(j["options"]["seed"], 1);  // CompressOptions' default
  j = CheckEnvelope(comp + " decode " + d + "c.h5 -o " + d + "dec.h5", "btf-compress");
  CheckSeconds(j["seconds"], "btf-compress decode");
  j = CheckEnvelope(comp + " export " + d + "c.h5 -o " + d + "export", "btf-compress");
  CheckSeconds(j["seconds"], "btf-compress export");
  j = CheckEnvelope(test::Tool("btf-eval") + " compare " + d + "a.h5 " + d + "c.h5", "btf-eval");
  CheckSeconds(j["seconds"], "btf-eval compare");
  EXPECT_EQ(j["options"]["compare"]["metric"], "rel");
  j = CheckEnvelope(test::Tool("btf-eval") + " stability --only directions/", "btf-eval");
  CheckSeconds(j["seconds"], "btf-eval stability");
  for (const auto& c : j["cases"]) CheckSeconds(c["seconds"], "stability case");
  j = CheckEnvelope(test::Tool("btf-info") + " " + d + "c.h5", "btf-info");
  j = CheckEnvelope(test::Tool("btf-convert") + " " + d + "a.h5 -o " + d + "a.btf", "btf-convert");
  CheckSeconds(j["seconds"], "btf-convert");
  EXPECT_EQ(j["options"]["storage"], "float32");  // ConvertOptions' default
  j = CheckEnvelope(test::Tool("btf-register") + " run " + test::SourceDir() +
                        "/sample_data/photos/manifest.json --resolution 8 -o " + d + "reg.h5",
                    "btf-register");
  CheckSeconds(j["seconds"], "btf-register run");
}

TEST(ToolConventions, ListOptionsTakeCommaSeparatedValues) {
  const auto dir = test::TempDir();
  const std::string d = dir.string() + "/";
  ASSERT_EQ(test::RunCommand(test::Tool("btf-synth") + " btf --views 0,1 --lights 0,3,9 --resolution 4 --samples 1 "
                                                       "--quiet -o " + d + "a.h5"),
            0);
  std::string out;
  ASSERT_EQ(test::RunCommand(test::Tool("btf-eval") + " sweep " + d + "a.h5 -o " + d + "sweep --methods pca-view " +
                                 "--components 1,2 --runs 1 --no-ssim --no-render --json --quiet",
                             &out),
            0);
  const auto j = nlohmann::json::parse(out);
  EXPECT_EQ(j["points"].size(), 2u);
  EXPECT_EQ(j["options"]["sweep"]["components"], nlohmann::json::array({1, 2}));
  EXPECT_EQ(j["options"]["sweep"]["methods"], nlohmann::json::array({"pca-view"}));
}

}  // namespace
}  // namespace btf
