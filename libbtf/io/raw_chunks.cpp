#include "libbtf/io/raw_chunks.h"

#include <libdeflate.h>
#include <omp.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <memory>
#include <optional>

#include "libbtf/core/error.h"
#include "libbtf/io/half.h"
#include "libbtf/io/hdf5.h"

namespace btf::h5 {

static_assert(std::endian::native == std::endian::little, "raw chunks hold little-endian values, copied as they are");

std::uint32_t Fletcher32(const std::uint8_t* data, std::size_t size) {
  // HDF5 adds word by word (sum1 += w; sum2 += sum1) and folds both sums every 360 words, the
  // block after which its 32-bit sums could overflow; they never do, so the exact sums of a
  // block give the same values: sum1 += sum w_i, sum2 += block * sum1 + sum (block - i) w_i. The
  // two per-block sums have no chain from word to word (vectorised) and stay below 2^32
  // (65535 * 360 * 361 / 2 < 2^32).
  std::uint64_t sum1 = 0, sum2 = 0;
  const auto fold = [](std::uint64_t s) { return (s & 0xffffu) + (s >> 16); };
  for (std::size_t words = size / 2; words > 0;) {
    const auto block = static_cast<std::uint32_t>(std::min<std::size_t>(words, 360));
    words -= block;
    std::uint32_t s1 = 0, s2 = 0;
    for (std::uint32_t i = 0; i < block; ++i) {
      const std::uint32_t w = (std::uint32_t(data[2 * i]) << 8) | data[2 * i + 1];
      s1 += w;
      s2 += (block - i) * w;
    }
    data += 2 * std::size_t(block);
    sum2 = fold(sum2 + std::uint64_t(block) * sum1 + s2);
    sum1 = fold(sum1 + s1);
  }
  if (size % 2) {
    sum1 += std::uint32_t(data[0]) << 8;
    sum2 += sum1;
    sum1 = fold(sum1);
    sum2 = fold(sum2);
  }
  return static_cast<std::uint32_t>((fold(sum2) << 16) | fold(sum1));
}

namespace {

// The filters libbtf writes, in the order it writes them (File::CreateFloatArray).
enum class Stage { kShuffle, kDeflate, kFletcher32 };

struct Plan {
  std::vector<hsize_t> dims, chunk;
  int split = 0;                    // dimensions before it have chunk extent 1, after it the whole extent
  std::size_t element = 0;          // stored bytes per value: 4 (float32) or 2 (float16)
  std::vector<Stage> stages;        // the pipeline in write order; stage i is filter i (mask bit i)
  bool has(Stage s) const { return std::find(stages.begin(), stages.end(), s) != stages.end(); }
};

// The plan for reading the slab raw, or nothing when H5Dread must read it.
std::optional<Plan> MakePlan(hid_t ds, const std::vector<hsize_t>& offset, const std::vector<hsize_t>& count) {
  Handle dcpl(H5Dget_create_plist(ds));
  if (!dcpl.valid() || H5Pget_layout(dcpl.id()) != H5D_CHUNKED) return std::nullopt;
  Plan p;
  Handle type(H5Dget_type(ds));
  if (H5Tequal(type.id(), H5T_IEEE_F32LE) > 0)
    p.element = 4;
  else if (H5Tequal(type.id(), HalfType()) > 0)
    p.element = 2;
  else
    return std::nullopt;
  Handle space(H5Dget_space(ds));
  const int rank = H5Sget_simple_extent_ndims(space.id());
  if (rank < 1 || std::size_t(rank) != offset.size() || offset.size() != count.size()) return std::nullopt;
  p.dims.resize(std::size_t(rank));
  p.chunk.resize(std::size_t(rank));
  H5Sget_simple_extent_dims(space.id(), p.dims.data(), nullptr);
  if (H5Pget_chunk(dcpl.id(), rank, p.chunk.data()) != rank) return std::nullopt;
  for (int d = 0; d < rank; ++d)
    if (p.chunk[std::size_t(d)] != p.dims[std::size_t(d)]) p.split = d;
  for (int d = 0; d < rank; ++d) {
    const std::size_t i = std::size_t(d);
    if (count[i] == 0 || (d < p.split && p.chunk[i] != 1)) return std::nullopt;
    if (d > p.split && (offset[i] != 0 || count[i] != p.dims[i])) return std::nullopt;
  }
  const std::size_t k = std::size_t(p.split);
  if (offset[k] % p.chunk[k] != 0 || (count[k] % p.chunk[k] != 0 && offset[k] + count[k] != p.dims[k]))
    return std::nullopt;
  const int filters = H5Pget_nfilters(dcpl.id());
  if (filters < 0) return std::nullopt;
  for (int i = 0; i < filters; ++i) {
    unsigned flags = 0, cd[8] = {};
    std::size_t cd_count = 8;
    const H5Z_filter_t id = H5Pget_filter2(dcpl.id(), unsigned(i), &flags, &cd_count, cd, 0, nullptr, nullptr);
    Stage s;
    if (id == H5Z_FILTER_SHUFFLE && cd_count >= 1 && cd[0] == p.element)
      s = Stage::kShuffle;
    else if (id == H5Z_FILTER_DEFLATE)
      s = Stage::kDeflate;
    else if (id == H5Z_FILTER_FLETCHER32)
      s = Stage::kFletcher32;
    else
      return std::nullopt;
    if (!p.stages.empty() && s <= p.stages.back()) return std::nullopt;  // another order: H5Dread
    p.stages.push_back(s);
  }
  return p;
}

enum class Fault { kNone, kChecksum, kInflate, kSize };

// Undoes the pipeline of one chunk (`raw`, `size` bytes as stored, `mask`: the filters skipped when
// it was written) and writes its first `valid` of `values` values into dst. `inflated` holds
// `values` * plan.element bytes.
Fault DecodeChunk(const Plan& plan, const std::uint8_t* raw, std::size_t size, std::uint32_t mask,
                  libdeflate_decompressor* inflater, std::uint8_t* inflated, std::size_t values, std::size_t valid,
                  float* dst) {
  const std::size_t bytes = values * plan.element;
  const std::uint8_t* data = raw;
  bool shuffled = false;
  for (std::size_t i = plan.stages.size(); i-- > 0;) {
    if (mask & (1u << i)) continue;  // an optional filter that failed when the chunk was written
    switch (plan.stages[i]) {
      case Stage::kFletcher32: {
        // The checksum follows the data, little-endian; HDF5 also accepts the byte-swapped form
        // written before HDF5 1.6.3.
        if (size < 4) return Fault::kSize;
        size -= 4;
        std::uint32_t stored;
        std::memcpy(&stored, data + size, 4);
        const std::uint32_t sum = Fletcher32(data, size);
        const std::uint32_t swapped = ((sum & 0x00ff00ffu) << 8) | ((sum & 0xff00ff00u) >> 8);
        if (stored != sum && stored != swapped) return Fault::kChecksum;
        break;
      }
      case Stage::kDeflate: {
        // A zlib stream (HDF5's deflate filter) that must inflate to exactly one chunk.
        const auto r = libdeflate_zlib_decompress(inflater, data, size, inflated, bytes, nullptr);
        if (r == LIBDEFLATE_SHORT_OUTPUT || r == LIBDEFLATE_INSUFFICIENT_SPACE) return Fault::kSize;
        if (r != LIBDEFLATE_SUCCESS) return Fault::kInflate;
        data = inflated;
        size = bytes;
        break;
      }
      case Stage::kShuffle:
        shuffled = true;  // the first filter written: undone while converting, below
        break;
    }
  }
  if (size != bytes) return Fault::kSize;
  // Shuffled: byte b of value e is at data[b * values + e] (HDF5's shuffle filter).
  if (plan.element == 4 && !shuffled) {
    std::memcpy(dst, data, valid * 4);
  } else if (plan.element == 4) {
    for (std::size_t e = 0; e < valid; ++e)
      dst[e] = std::bit_cast<float>(std::uint32_t(data[e]) | std::uint32_t(data[values + e]) << 8 |
                                    std::uint32_t(data[2 * values + e]) << 16 |
                                    std::uint32_t(data[3 * values + e]) << 24);
  } else {
    const std::size_t low = shuffled ? 1 : 2, high = shuffled ? values : 1;
    for (std::size_t e = 0; e < valid; ++e)
      dst[e] = HalfToFloat(std::uint16_t(data[low * e] | data[low * e + high] << 8));
  }
  return Fault::kNone;
}

// "chunk at view 3, light 17, y 0" (the dataset's dimension_names) or "chunk at [3, 17, 0, 0, 0]".
std::string ChunkName(const File& file, const std::string& name, const Plan& plan, const hsize_t* coord) {
  std::vector<std::string> names;
  if (file.HasAttr(name, "dimension_names")) {
    const std::string all = file.GetString(name, "dimension_names");
    for (std::size_t b = 0, e; b <= all.size(); b = e + 1) {
      e = std::min(all.find(',', b), all.size());
      names.push_back(all.substr(b, e - b));
    }
  }
  std::string s = fmt::format("dataset '{}', chunk at ", name);
  if (names.size() == plan.dims.size()) {
    for (int d = 0; d <= plan.split; ++d) s += fmt::format("{}{} {}", d ? ", " : "", names[std::size_t(d)], coord[d]);
  } else {
    s += "[";
    for (std::size_t d = 0; d < plan.dims.size(); ++d) s += fmt::format("{}{}", d ? ", " : "", coord[d]);
    s += "]";
  }
  return s;
}

}  // namespace

bool ReadRawChunks(const File& file, hid_t ds, const std::string& name, const std::vector<hsize_t>& offset,
                   const std::vector<hsize_t>& count, float* out, std::vector<std::uint8_t>& scratch) {
  const auto plan = MakePlan(ds, offset, count);
  if (!plan) return false;
  const std::size_t rank = plan->dims.size(), k = std::size_t(plan->split);
  std::size_t inner = 1, leading = 1;  // values per index of the split dimension; chunk rows of the slab
  for (std::size_t d = k + 1; d < rank; ++d) inner *= std::size_t(plan->dims[d]);
  for (std::size_t d = 0; d < k; ++d) leading *= std::size_t(count[d]);
  const std::size_t rows = std::size_t(plan->chunk[k]), slab_rows = std::size_t(count[k]);
  const std::size_t per_lead = (slab_rows + rows - 1) / rows, chunks = leading * per_lead;
  const std::size_t values = rows * inner, bytes = values * plan->element;
  // Bigger than deflate's worst case (zlib's compressBound) plus the checksum: not a chunk we
  // can read raw (H5Dread decides what it is).
  const std::size_t max_stored = bytes + bytes / 1024 + 64;

  // On this thread (HDF5): where each chunk is, and its raw bytes. An unallocated chunk (fill
  // values) or an implausible size leaves the whole slab to H5Dread.
  std::vector<hsize_t> coords(chunks * rank, 0);
  std::vector<std::size_t> begin(chunks + 1, 0);
  for (std::size_t t = 0; t < chunks; ++t) {
    hsize_t* c = &coords[t * rank];
    for (std::size_t d = k, lead = t / per_lead; d-- > 0; lead /= std::size_t(count[d]))
      c[d] = offset[d] + lead % std::size_t(count[d]);
    c[k] = offset[k] + hsize_t((t % per_lead) * rows);
    hsize_t stored = 0;
    if (H5Dget_chunk_storage_size(ds, c, &stored) < 0 || stored == 0 || stored > max_stored) return false;
    begin[t + 1] = begin[t] + std::size_t(stored);
  }
  scratch.resize(begin[chunks]);
  std::vector<std::uint32_t> masks(chunks, 0);
  for (std::size_t t = 0; t < chunks; ++t)
    if (H5Dread_chunk(ds, H5P_DEFAULT, &coords[t * rank], &masks[t], scratch.data() + begin[t]) < 0) {
      // ChunkName's HDF5 calls would replace the error stack ThrowUnreadable inspects (I/O or not).
      const hid_t stack = H5Eget_current_stack();
      const std::string chunk = ChunkName(file, name, *plan, &coords[t * rank]);
      H5Eset_current_stack(stack);  // (closes `stack`)
      ThrowUnreadable(file.path(), chunk);
    }

  // On the compute threads: one decompressor and one chunk buffer per thread, made here (no
  // allocation, nothing that throws, inside the parallel loop).
  const bool deflated = plan->has(Stage::kDeflate);
  const int threads = std::max(1, omp_get_max_threads());
  std::vector<std::unique_ptr<libdeflate_decompressor, decltype(&libdeflate_free_decompressor)>> inflaters;
  std::vector<std::vector<std::uint8_t>> inflated(static_cast<std::size_t>(threads));
  for (int i = 0; deflated && i < threads; ++i) {
    inflaters.emplace_back(libdeflate_alloc_decompressor(), &libdeflate_free_decompressor);
    if (!inflaters.back()) throw std::bad_alloc();
    inflated[std::size_t(i)].resize(bytes);
  }
  std::vector<Fault> faults(chunks, Fault::kNone);
#pragma omp parallel for schedule(dynamic) num_threads(threads)
  for (std::ptrdiff_t i = 0; i < std::ptrdiff_t(chunks); ++i) {
    const std::size_t t = std::size_t(i), th = std::size_t(omp_get_thread_num()), j = t % per_lead;
    const std::size_t valid = std::min(rows, slab_rows - j * rows) * inner;
    faults[t] = DecodeChunk(*plan, scratch.data() + begin[t], begin[t + 1] - begin[t], masks[t],
                            deflated ? inflaters[th].get() : nullptr, deflated ? inflated[th].data() : nullptr,
                            values, valid, out + ((t / per_lead) * slab_rows + j * rows) * inner);
  }
  // The first bad chunk in slab order: the same report for any thread count.
  for (std::size_t t = 0; t < chunks; ++t) {
    if (faults[t] == Fault::kNone) continue;
    const char* what = faults[t] == Fault::kChecksum ? "its Fletcher-32 checksum does not match"
                       : faults[t] == Fault::kInflate ? "its deflate stream is damaged"
                                                      : "it does not hold one chunk of values";
    ThrowBadInput("'{}': {} is corrupt ({}): the file was damaged after it was written; re-create it or copy it "
                  "again from a good copy",
                  file.path(), ChunkName(file, name, *plan, &coords[t * rank]), what);
  }
  return true;
}

}  // namespace btf::h5
