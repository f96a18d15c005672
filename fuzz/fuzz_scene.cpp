// module: compress
// Fuzzes the scene file reader (scene.json for btf-compress --scene). Whatever it accepts must
// give direction subsets within the sampling and survive ToJson -> FromJson.
#include "fuzz/fuzz_util.h"
#include "libbtf/compress/scene.h"
#include "libbtf/core/error.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  btf::fuzz::TempInput in(data, size, ".json");
  btf::SceneSpec s;
  try {
    s = btf::SceneSpec::Load(in.path());
  } catch (const btf::Error&) {
    return 0;
  }
  static const btf::Sampling bonn = btf::Sampling::Bonn81();
  for (const auto* cones : {&s.views, &s.lights})
    for (int i : btf::NeededDirections(bonn, *cones))
      if (i < 0 || i >= bonn.size()) __builtin_trap();
  try {
    btf::SceneSpec::FromJson(s.ToJson(), "round trip");
  } catch (const btf::Error&) {
    __builtin_trap();  // the writer produced a scene its own reader refuses
  }
  return 0;
}
