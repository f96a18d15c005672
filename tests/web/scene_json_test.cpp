// The viewer's scene.json holds what every choice of the page needs, whatever the start flags:
// started under the point light, its "environment (sky)" choice still has the sky's samples.
#include <gtest/gtest.h>

#include "libbtf/web/web.h"

namespace btf {
namespace {

TEST(ViewerScene, EveryLightingChoiceHasItsDataWhateverTheStartScene) {
  for (const std::string scene : {"patch-point", "cylinder-env"}) {
    const RenderOptions o = WebSceneOptions(scene, 64, 48);
    const nlohmann::json j = ViewerSceneJson(o, 1.0);
    EXPECT_EQ(j.at("lighting"), o.lighting) << scene;
    const auto& env = j.at("environment");
    EXPECT_EQ(env.at("directions").size(), std::size_t(o.environment_samples)) << scene;
    EXPECT_EQ(env.at("radiance_solid_angle").size(), std::size_t(o.environment_samples)) << scene;
    double sum = 0;
    for (const auto& r : env.at("radiance_solid_angle")) sum += r.at(0).get<double>();
    EXPECT_GT(sum, 0) << scene << ": a black sky";
    EXPECT_EQ(j.at("light").at("position").size(), 3u) << scene;
  }
}

}  // namespace
}  // namespace btf
