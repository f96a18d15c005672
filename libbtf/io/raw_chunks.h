#pragma once
// Reading a chunked float dataset without HDF5's filter pipeline: the raw bytes of the
// chunks are read with H5Dread_chunk on the calling thread (the only thread that calls HDF5), then
// each chunk is checked (Fletcher-32), inflated (libdeflate), unshuffled and converted to float on
// the compute threads (OpenMP). File::ReadSlab uses it for the datasets libbtf writes
// (docs/btf-compress.md, "Reading"); the file format does not change.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "libbtf/io/hdf5.h"

namespace btf::h5 {

// Fletcher-32 as HDF5 computes it for its fletcher32 filter (H5_checksum_fletcher32): the bytes
// are summed as big-endian 16-bit words (an odd last byte as the high byte of a word), sums folded
// to 16 bits every 360 words and twice at the end; the result is sum2 << 16 | sum1.
std::uint32_t Fletcher32(const std::uint8_t* data, std::size_t size);

// Reads the hyperslab [offset, offset + count) of dataset `ds` (`name` in `file`) into `out`
// as float when the raw path applies, and returns true. It applies when the dataset is chunked
// with chunks of shape 1 x ... x 1 x rows x (whole trailing dimensions), the slab covers whole
// chunks along the split dimension and whole trailing dimensions, the stored type is IEEE float32
// or libbtf's float16 (little-endian), the filter pipeline is an ordered subset of shuffle,
// deflate, fletcher32 (what libbtf writes), and every chunk of the slab is allocated. Otherwise it
// reads nothing and returns false (the caller uses H5Dread). A chunk that fails its checksum, does
// not inflate or inflates to the wrong size throws btf::Error (bad input) naming the file, the
// dataset and the chunk's coordinates (by the dataset's dimension_names when it has them); a
// failed read of the file throws as ThrowUnreadable does. `scratch` holds the raw chunks (kept by
// the caller to reuse its memory between reads).
bool ReadRawChunks(const File& file, hid_t ds, const std::string& name, const std::vector<hsize_t>& offset,
                   const std::vector<hsize_t>& count, float* out, std::vector<std::uint8_t>& scratch);

}  // namespace btf::h5
