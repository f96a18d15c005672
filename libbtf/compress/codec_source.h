#pragma once
// Codecs seen as view-slot sources (libbtf/io/slot_source.h), and the one entry point that opens
// any libbtf BTF file as a source.
#include <filesystem>
#include <memory>

#include "libbtf/compress/codec.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/slot_source.h"

namespace btf {

// A codec file, decoded one view slot at a time (Codec::DecodeViewSlot).
std::unique_ptr<SlotSource> OpenCodecSource(const std::filesystem::path& path);

// Opens a dataset or codec file, chosen by its "format" attribute (FileFormatOf), or a Bonn .btf
// file (libbtf/io/bonn.h, recognised by its signature). Other libbtf formats and foreign files
// throw btf::Error (bad input) naming the file. `read` applies to datasets.
std::unique_ptr<SlotSource> OpenSource(const std::filesystem::path& path, const DatasetReadOptions& read = {});

// What btf-compress (and libbtf.compress) compresses: a Bonn .btf file (recognised by its
// signature, decoded one view slot at a time) or else a dataset file (a codec is refused: it
// would be compressed twice).
std::unique_ptr<SlotSource> OpenCompressInput(const std::filesystem::path& path, const DatasetReadOptions& read = {});

}  // namespace btf
