#pragma once
// Bonn's full-matrix factorisations written as Bonn `.btf` files: FMF (`!FMF12FCER`, one
// truncated SVD of the (channels x lights x views) x texels matrix) and DFMF (`!DFMF08FCR`, one
// per YUV channel), either factorised from any view-slot source by the streaming randomised SVD
// of fmf_codec.h, or from an fmf / dfmf codec's own factors (docs/format.md, "Writing FMF and DFMF").
#include <filesystem>
#include <string>

#include "libbtf/compress/codec.h"
#include "libbtf/compress/fmf_codec.h"
#include "libbtf/io/convert.h"
#include "libbtf/io/slot_source.h"

namespace btf {

// decorrelate = false writes FMF, true DFMF (colour model 1, YUV; needs 3 channels).
using FmfWriteOptions = FmfSvdOptions;

// Writes `input` as FMF or DFMF with float32 factors (scalar_size 4), atomically. Values must be
// finite (btf::Error, bad input, naming the item; nothing written).
ConvertSummary WriteFmf(const FmfWriteOptions& options, const SlotSource& input, const std::filesystem::path& path,
                        const Reporter& reporter = {});

// Writes an fmf codec as FMF and a dfmf codec as DFMF, its factors as they are (no second
// factorisation). A log codec becomes FMF with dynamic-range reduction if its epsilon is Bonn's
// 1e-5 (kBonnEpsilon); other log codecs and other methods are refused (btf::Error, usage).
// `input_name` is what the summary calls the codec.
ConvertSummary WriteFmf(const Codec& codec, const std::string& input_name, const std::filesystem::path& path,
                        const Reporter& reporter = {});

}  // namespace btf
