#pragma once
// Test shorthand for generating a whole BTF in memory (GenerateBtf writes to an out-parameter).
#include "libbtf/synth/btf_generator.h"

namespace btf::test {

inline Dataset GenerateDataset(const SvbrdfModel& model, const BtfOptions& o, BtfSummary* summary = nullptr) {
  Dataset d;
  const BtfSummary s = GenerateBtf(o, model, &d);
  if (summary) *summary = s;
  return d;
}

}  // namespace btf::test
