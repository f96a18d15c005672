#pragma once
// Codecs (libbtf/compress/codec.h) seen through the evaluation interfaces: a SlotSource for the
// metrics and a BtfEvaluator for the renderer.
#include <filesystem>
#include <memory>

#include "libbtf/compress/codec.h"
#include "libbtf/eval/render.h"
#include "libbtf/eval/source.h"

namespace btf {

// A codec file, decoded one view slot at a time (Codec::DecodeViewSlot).
std::unique_ptr<SlotSource> OpenCodecSource(const std::filesystem::path& path);
// An in-memory codec (must outlive the source); `name` labels it in messages.
std::unique_ptr<SlotSource> CodecSource(const Codec& codec, std::string name);

// The codec's arbitrary-direction decoder (Codec::Value: barycentric over the three nearest views
// x lights, nearest texel so it matches DatasetEvaluator). The codec must outlive the evaluator.
std::unique_ptr<BtfEvaluator> CodecEvaluator(const Codec& codec);

}  // namespace btf
