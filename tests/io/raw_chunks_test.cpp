// The raw chunk reader (libbtf/io/raw_chunks.h) against HDF5's own filter pipeline (H5Dread):
// bit-identical values on every layout libbtf writes, H5Dread for anything else, and corrupt
// chunks refused with an error naming the file, the dataset and the chunk.
#include "libbtf/io/raw_chunks.h"

#include <gtest/gtest.h>
#include <libdeflate.h>
#include <omp.h>

#include <cstring>
#include <fstream>
#include <random>

#include "libbtf/io/dataset_io.h"
#include "tests/test_util.h"

namespace btf {
namespace {

constexpr const char* kData = "/btf/data";

// Reads the whole /btf/data of `path` through ReadRawChunks directly; false when it declines.
bool ReadRaw(const std::filesystem::path& path, const std::string& name, std::vector<float>& out) {
  const h5::File f = h5::File::Open(path);
  const auto dims = f.Dims(name);
  std::size_t n = 1;
  for (auto d : dims) n *= std::size_t(d);
  out.assign(n, -1.0f);
  h5::Handle ds(H5Dopen2(f.id(), name.c_str(), H5P_DEFAULT));
  std::vector<std::uint8_t> scratch;
  return h5::ReadRawChunks(f, ds.id(), name, std::vector<hsize_t>(dims.size(), 0), dims, out.data(), scratch);
}

// Both reading paths, on 1 and on 2 threads, give the same bits.
void ExpectPathsAgree(const std::filesystem::path& path, bool raw_applies) {
  DatasetReadOptions hdf5;
  hdf5.raw_chunks = false;
  const Dataset reference = ReadDataset(path, hdf5);
  std::vector<float> direct;
  ASSERT_EQ(ReadRaw(path, kData, direct), raw_applies) << path;
  if (raw_applies) {
    EXPECT_EQ(std::memcmp(direct.data(), reference.data().data(), direct.size() * 4), 0);
  }
  const int threads = omp_get_max_threads();
  for (int t : {1, 2}) {
    omp_set_num_threads(t);
    const Dataset raw = ReadDataset(path);
    ASSERT_EQ(raw.size(), reference.size());
    EXPECT_EQ(std::memcmp(raw.data().data(), reference.data().data(), raw.size() * 4), 0) << path << ", " << t << " threads";
    DatasetReader reader(path);
    std::vector<float> img(raw.image_size());
    const int v = raw.num_views() - 1, l = raw.num_lights() - 1;
    reader.ReadImage(v, l, img.data());
    EXPECT_TRUE(std::equal(img.begin(), img.end(), reference.image(v, l).begin()));
  }
  omp_set_num_threads(threads);
}

// Deterministic values with some texture (a smooth ramp and hashed noise), so shuffle and deflate
// have real work; `random_bits` makes them incompressible (HDF5 1.10.8 then stores a deflate
// stream longer than the chunk: 3087 stored bytes for a 3072-byte chunk here).
Dataset TexturedDataset(int views, int lights, int height, int width, bool random_bits = false) {
  Dataset d = test::MakeTestDataset(views, lights, height, width);
  std::mt19937 rng(7);
  for (float& x : d.data()) {
    if (random_bits) {
      std::uint32_t bits = rng();
      bits = (bits & 0x807fffffu) | ((bits % 200u + 20u) << 23);  // finite, exponent 20..219
      std::memcpy(&x, &bits, 4);
    } else {
      x += 1e-4f * float(rng() % 1000);
    }
  }
  return d;
}

TEST(RawChunks, EveryLayoutWeWriteReadsBitIdenticalToHdf5) {
  const auto dir = test::TempDir();
  int n = 0;
  for (auto storage : {h5::Storage::kFloat32, h5::Storage::kFloat16})
    for (int level : {0, 1, 4}) {
      DatasetWriteOptions o;
      o.storage = storage;
      o.deflate_level = level;
      const auto path = dir / fmt::format("d{}.h5", n++);
      WriteDataset(path, TexturedDataset(3, 4, 5, 6), o);
      ExpectPathsAgree(path, true);
    }
}

TEST(RawChunks, ImagesSplitAlongYWithAPartialLastChunk) {
  // 1024 x 3 floats per row: 341 rows per 4 MiB chunk, so 400 rows are a chunk of 341 and an
  // edge chunk holding 59 (stored padded to 341).
  const auto path = test::TempDir() / "split.h5";
  DatasetWriteOptions o;
  o.deflate_level = 1;
  WriteDataset(path, TexturedDataset(1, 2, 400, 1024), o);
  {
    const h5::File f = h5::File::Open(path);
    h5::Handle ds(H5Dopen2(f.id(), kData, H5P_DEFAULT));
    h5::Handle dcpl(H5Dget_create_plist(ds.id()));
    hsize_t chunk[5];
    ASSERT_EQ(H5Pget_chunk(dcpl.id(), 5, chunk), 5);
    ASSERT_EQ(chunk[2], 341u);
  }
  ExpectPathsAgree(path, true);
}

TEST(RawChunks, IncompressibleChunksStoredWithoutDeflateReadIdentically) {
  const auto path = test::TempDir() / "noise.h5";
  WriteDataset(path, TexturedDataset(2, 3, 16, 16, true));
  ExpectPathsAgree(path, true);
}

TEST(RawChunks, StoredChecksumIsHdf5sFletcher32OfTheChunk) {
  const auto path = test::TempDir() / "sum.h5";
  WriteDataset(path, TexturedDataset(2, 3, 7, 9));
  const h5::File f = h5::File::Open(path);
  h5::Handle ds(H5Dopen2(f.id(), kData, H5P_DEFAULT));
  for (hsize_t l = 0; l < 3; ++l) {
    const hsize_t at[5] = {1, l, 0, 0, 0};
    hsize_t size = 0;
    ASSERT_GE(H5Dget_chunk_storage_size(ds.id(), at, &size), 0);
    std::vector<std::uint8_t> raw(size);
    std::uint32_t mask = 0, stored = 0;
    ASSERT_GE(H5Dread_chunk(ds.id(), H5P_DEFAULT, at, &mask, raw.data()), 0);
    std::memcpy(&stored, raw.data() + size - 4, 4);
    EXPECT_EQ(h5::Fletcher32(raw.data(), size - 4), stored) << "light " << l;
  }
  // HDF5's algorithm by hand on "abcde": words 0x6162, 0x6364 and the odd byte as 0x6500.
  const std::uint8_t text[] = {'a', 'b', 'c', 'd', 'e'};
  EXPECT_EQ(h5::Fletcher32(text, 5), 0x4ff029c7u);
}

// File::WriteFloats / WriteDoubles / WriteInts store an array above the compact size in one chunk
// written with H5Dwrite_chunk and a checksum computed here: the file must hold the bytes HDF5's own
// pipeline (H5Dwrite through the fletcher32 filter) stores for the same array, read back through
// that pipeline with the checksum verified, and a damaged byte must be refused.
TEST(RawChunks, OneChunkWritesStoreWhatHdf5sPipelineStores) {
  const auto dir = test::TempDir();
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> uni(-2, 2);
  std::vector<float> values(3 * 5001);  // 60,012 bytes: above the compact layout's 32 KiB
  for (float& v : values) v = uni(rng);
  const std::vector<hsize_t> dims{3, 5001};
  {
    h5::File f = h5::File::Create(dir / "ours.h5");
    f.WriteFloats("x", dims, values.data());
    f.Close();
  }
  {  // the same layout through HDF5's pipeline
    h5::File f = h5::File::Create(dir / "hdf5.h5");
    h5::Handle space(H5Screate_simple(2, dims.data(), nullptr));
    h5::Handle dcpl(H5Pcreate(H5P_DATASET_CREATE));
    ASSERT_GE(H5Pset_chunk(dcpl.id(), 2, dims.data()), 0);
    ASSERT_GE(H5Pset_fletcher32(dcpl.id()), 0);
    h5::Handle ds(H5Dcreate2(f.id(), "x", H5T_IEEE_F32LE, space.id(), H5P_DEFAULT, dcpl.id(), H5P_DEFAULT));
    ASSERT_GE(H5Dwrite(ds.id(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), 0);
    ds.reset();
    f.Close();
  }
  auto raw_chunk = [](const std::filesystem::path& path) {
    const h5::File f = h5::File::Open(path);
    h5::Handle ds(H5Dopen2(f.id(), "x", H5P_DEFAULT));
    const hsize_t at[2] = {0, 0};
    hsize_t size = 0;
    EXPECT_GE(H5Dget_chunk_storage_size(ds.id(), at, &size), 0);
    std::vector<std::uint8_t> raw(size);
    std::uint32_t mask = 1;
    EXPECT_GE(H5Dread_chunk(ds.id(), H5P_DEFAULT, at, &mask, raw.data()), 0);
    EXPECT_EQ(mask, 0u);  // every filter applied
    return raw;
  };
  const std::vector<std::uint8_t> ours = raw_chunk(dir / "ours.h5");
  EXPECT_EQ(ours.size(), values.size() * 4 + 4);
  EXPECT_EQ(ours, raw_chunk(dir / "hdf5.h5"));
  // Read back through the pipeline (the filter verifies the checksum).
  std::vector<float> back(values.size());
  {
    const h5::File f = h5::File::Open(dir / "ours.h5");
    h5::Handle ds(H5Dopen2(f.id(), "x", H5P_DEFAULT));
    ASSERT_GE(H5Dread(ds.id(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, back.data()), 0);
  }
  EXPECT_EQ(back, values);
  // One value's byte flipped in the file: the checksum refuses the chunk.
  std::string bytes;
  {
    std::ifstream in(dir / "ours.h5", std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  std::string needle(reinterpret_cast<const char*>(values.data() + 1000), 16);
  const std::size_t at = bytes.find(needle);
  ASSERT_NE(at, std::string::npos);
  bytes[at] = char(bytes[at] ^ 0x20);
  {
    std::ofstream out(dir / "damaged.h5", std::ios::binary);
    out << bytes;
  }
  const h5::File f = h5::File::Open(dir / "damaged.h5");
  h5::Handle ds(H5Dopen2(f.id(), "x", H5P_DEFAULT));
  EXPECT_LT(H5Dread(ds.id(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, back.data()), 0);
}

// HDF5's loop, word by word in 32-bit sums folded every 360 words, against the blocked sums
// Fletcher32 forms: equal on random bytes of every length around the block size and on all-0xff
// bytes (the largest sums).
TEST(RawChunks, BlockedFletcher32EqualsHdf5sWordByWordLoop) {
  const auto serial = [](const std::uint8_t* d, std::size_t size) {
    std::uint32_t s1 = 0, s2 = 0;
    const auto fold = [](std::uint32_t s) { return (s & 0xffffu) + (s >> 16); };
    for (std::size_t words = size / 2; words > 0;) {
      const std::size_t block = std::min<std::size_t>(words, 360);
      words -= block;
      for (std::size_t i = 0; i < block; ++i, d += 2) s1 += (std::uint32_t(d[0]) << 8) | d[1], s2 += s1;
      s1 = fold(s1), s2 = fold(s2);
    }
    if (size % 2) s1 += std::uint32_t(d[0]) << 8, s2 += s1, s1 = fold(s1), s2 = fold(s2);
    return (fold(s2) << 16) | fold(s1);
  };
  std::mt19937 rng(5);
  std::vector<std::uint8_t> bytes(5000);
  for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
  const std::vector<std::uint8_t> ones(5000, 0xff);
  for (std::size_t n : {0u, 1u, 2u, 719u, 720u, 721u, 722u, 1441u, 4999u, 5000u}) {
    EXPECT_EQ(h5::Fletcher32(bytes.data(), n), serial(bytes.data(), n)) << n;
    EXPECT_EQ(h5::Fletcher32(ones.data(), n), serial(ones.data(), n)) << n;
  }
}

// Replaces /btf/data of a written dataset by the same values under another dataset creation
// property list (layout, filters) and file type, written with H5Dwrite.
void Restore(const std::filesystem::path& path, const Dataset& d, const std::function<void(hid_t dcpl)>& setup,
             hid_t file_type = H5T_IEEE_F32LE) {
  const h5::File f = h5::File::OpenForUpdate(path);
  ASSERT_GE(H5Ldelete(f.id(), kData, H5P_DEFAULT), 0);
  const hsize_t dims[5] = {hsize_t(d.num_views()), hsize_t(d.num_lights()), hsize_t(d.height()), hsize_t(d.width()),
                           hsize_t(d.channels())};
  h5::Handle space(H5Screate_simple(5, dims, nullptr));
  h5::Handle dcpl(H5Pcreate(H5P_DATASET_CREATE));
  setup(dcpl.id());
  h5::Handle ds(H5Dcreate2(f.id(), kData, file_type, space.id(), H5P_DEFAULT, dcpl.id(), H5P_DEFAULT));
  ASSERT_TRUE(ds.valid());
  ASSERT_GE(H5Dwrite(ds.id(), H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, d.data().data()), 0);
}

TEST(RawChunks, OtherPipelinesAndLayoutsReadCorrectly) {
  const auto dir = test::TempDir();
  const Dataset d = TexturedDataset(3, 4, 5, 6);
  const hsize_t image[5] = {1, 1, 5, 6, 3}, slot[5] = {1, 4, 5, 6, 3}, three[5] = {1, 3, 5, 6, 3},
                columns[5] = {1, 1, 5, 3, 3};
  struct Case {
    const char* name;
    std::function<void(hid_t)> setup;
    bool raw;  // the raw path applies
    hid_t type = H5T_IEEE_F32LE;
  };
  const std::vector<Case> cases = {
      {"deflate alone", [&](hid_t p) { H5Pset_chunk(p, 5, image); H5Pset_deflate(p, 6); }, true},
      {"shuffle + deflate, no checksum", [&](hid_t p) { H5Pset_chunk(p, 5, image); H5Pset_shuffle(p); H5Pset_deflate(p, 2); }, true},
      {"no filters", [&](hid_t p) { H5Pset_chunk(p, 5, image); }, true},
      {"one chunk per view slot", [&](hid_t p) { H5Pset_chunk(p, 5, slot); H5Pset_deflate(p, 1); H5Pset_fletcher32(p); }, true},
      {"checksum before deflate", [&](hid_t p) { H5Pset_chunk(p, 5, image); H5Pset_fletcher32(p); H5Pset_deflate(p, 1); }, false},
      {"three lights per chunk (an edge chunk)", [&](hid_t p) { H5Pset_chunk(p, 5, three); H5Pset_deflate(p, 1); }, true},
      {"chunks split along x", [&](hid_t p) { H5Pset_chunk(p, 5, columns); H5Pset_deflate(p, 1); }, false},
      {"contiguous", [&](hid_t) {}, false},
      {"big-endian floats", [&](hid_t p) { H5Pset_chunk(p, 5, image); H5Pset_shuffle(p); H5Pset_deflate(p, 1); }, false,
       H5T_IEEE_F32BE},
  };
  int n = 0;
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const auto path = dir / fmt::format("o{}.h5", n++);
    WriteDataset(path, d);
    Restore(path, d, c.setup, c.type);
    ExpectPathsAgree(path, c.raw);
    EXPECT_EQ(ReadDataset(path).data(), d.data());
  }
}

// A file from another writer whose chunks were not all written: H5Dread would return fill values
// (zeros) for the missing ones. Both read paths refuse it, naming the file, the dataset and the
// first missing chunk; the chunks that were written still read.
TEST(RawChunks, UnwrittenChunksAreRefusedNotReadAsZeros) {
  const auto path = test::TempDir() / "sparse.h5";
  const Dataset d = TexturedDataset(3, 4, 5, 6);
  WriteDataset(path, d);
  {
    const h5::File f = h5::File::OpenForUpdate(path);
    ASSERT_GE(H5Ldelete(f.id(), kData, H5P_DEFAULT), 0);
    const hsize_t dims[5] = {3, 4, 5, 6, 3}, image[5] = {1, 1, 5, 6, 3}, first[5] = {0, 0, 0, 0, 0};
    const hsize_t view0[5] = {1, 4, 5, 6, 3};
    h5::Handle space(H5Screate_simple(5, dims, nullptr));
    h5::Handle dcpl(H5Pcreate(H5P_DATASET_CREATE));
    H5Pset_chunk(dcpl.id(), 5, image);
    H5Pset_deflate(dcpl.id(), 1);
    h5::Handle ds(H5Dcreate2(f.id(), kData, H5T_IEEE_F32LE, space.id(), H5P_DEFAULT, dcpl.id(), H5P_DEFAULT));
    ASSERT_TRUE(ds.valid());
    h5::Handle mem(H5Screate_simple(5, view0, nullptr));
    ASSERT_GE(H5Sselect_hyperslab(space.id(), H5S_SELECT_SET, first, nullptr, view0, nullptr), 0);
    ASSERT_GE(H5Dwrite(ds.id(), H5T_NATIVE_FLOAT, mem.id(), space.id(), H5P_DEFAULT, d.data().data()), 0);  // view 0 only
  }
  for (const bool raw : {true, false}) {
    DatasetReadOptions o;
    o.raw_chunks = raw;
    ExitCode code{};
    const std::string e = test::ErrorOf([&] { ReadDataset(path, o); }, &code);
    EXPECT_EQ(code, ExitCode::kBadInput) << e;
    for (const std::string part : {path.string(), std::string("/btf/data"), std::string("(1, 0, 0, 0, 0)"), std::string("never written")})
      EXPECT_NE(e.find(part), std::string::npos) << part << ": " << e;
  }
  // View 0 was written: a reader of that slot alone gets its values.
  const h5::File f = h5::File::Open(path);
  std::vector<float> slot(4 * 5 * 6 * 3);
  f.ReadSlab(kData, {0, 0, 0, 0, 0}, {1, 4, 5, 6, 3}, slot.data());
  EXPECT_TRUE(std::equal(slot.begin(), slot.end(), d.data().begin()));
}

// Where chunk (view, light) of /btf/data starts in the file, and its stored size.
std::pair<haddr_t, hsize_t> ChunkLocation(const std::filesystem::path& path, hsize_t view, hsize_t light, hsize_t y = 0) {
  const h5::File f = h5::File::Open(path);
  h5::Handle ds(H5Dopen2(f.id(), kData, H5P_DEFAULT));
  const hsize_t at[5] = {view, light, y, 0, 0};
  unsigned mask = 0;
  haddr_t addr = 0;
  hsize_t size = 0;
  EXPECT_GE(H5Dget_chunk_info_by_coord(ds.id(), at, &mask, &addr, &size), 0);
  return {addr, size};
}

void FlipByte(const std::filesystem::path& path, std::uint64_t at) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(std::streamoff(at));
  const char c = char(f.get() ^ 0x5a);
  f.seekp(std::streamoff(at));
  f.put(c);
}

TEST(RawChunks, CorruptChunkIsRefusedNamingFileDatasetAndChunk) {
  const auto dir = test::TempDir();
  for (int level : {0, 4}) {
    DatasetWriteOptions o;
    o.deflate_level = level;
    const auto path = dir / fmt::format("bad{}.h5", level);
    WriteDataset(path, TexturedDataset(3, 4, 5, 6), o);
    const auto [addr, size] = ChunkLocation(path, 1, 2);
    FlipByte(path, addr + size / 2);
    ExitCode code{};
    const std::string msg = test::ErrorOf([&] { ReadDataset(path); }, &code);
    EXPECT_EQ(code, ExitCode::kBadInput) << msg;
    for (const std::string& part :
         std::vector<std::string>{path.string(), "'/btf/data'", "chunk at view 1, light 2 is corrupt", "Fletcher-32", "copy it again"})
      EXPECT_NE(msg.find(part), std::string::npos) << "missing '" << part << "' in: " << msg;
    // HDF5 refuses it too (its own message): no reading path returns the damaged values.
    DatasetReadOptions hdf5;
    hdf5.raw_chunks = false;
    EXPECT_NE(test::ErrorOf([&] { ReadDataset(path, hdf5); }), "");
  }
}

TEST(RawChunks, DamagedDeflateStreamAndWrongSizeAreRefused) {
  // Without a checksum the inflate itself must notice: a flipped byte breaks the stream (its
  // Adler-32 or its codes), and a valid stream of the wrong length is not one chunk.
  const auto dir = test::TempDir();
  const Dataset d = TexturedDataset(2, 2, 5, 6);
  const hsize_t image[5] = {1, 1, 5, 6, 3};
  const auto deflate_only = [&](hid_t p) { H5Pset_chunk(p, 5, image); H5Pset_deflate(p, 6); };
  const auto damaged = dir / "stream.h5";
  WriteDataset(damaged, d);
  Restore(damaged, d, deflate_only);
  const auto [addr, size] = ChunkLocation(damaged, 1, 0);
  FlipByte(damaged, addr + size / 2);
  std::string msg = test::ErrorOf([&] { ReadDataset(damaged); });
  // (no dimension_names on this dataset: the chunk by its coordinates)
  EXPECT_NE(msg.find("chunk at [1, 0, 0, 0, 0] is corrupt"), std::string::npos) << msg;

  const auto short_chunk = dir / "short.h5";
  WriteDataset(short_chunk, d);
  Restore(short_chunk, d, deflate_only);
  {
    std::vector<float> half_image(d.image_size() / 2, 1.0f);
    std::vector<std::uint8_t> z(4096);
    libdeflate_compressor* c = libdeflate_alloc_compressor(6);
    z.resize(libdeflate_zlib_compress(c, half_image.data(), half_image.size() * 4, z.data(), z.size()));
    libdeflate_free_compressor(c);
    ASSERT_GT(z.size(), 0u);
    const h5::File f = h5::File::OpenForUpdate(short_chunk);
    h5::Handle ds(H5Dopen2(f.id(), kData, H5P_DEFAULT));
    const hsize_t at[5] = {0, 1, 0, 0, 0};
    ASSERT_GE(H5Dwrite_chunk(ds.id(), H5P_DEFAULT, 0, at, z.size(), z.data()), 0);
  }
  ExitCode code{};
  msg = test::ErrorOf([&] { ReadDataset(short_chunk); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(msg.find("chunk at [0, 1, 0, 0, 0]"), std::string::npos) << msg;
  EXPECT_NE(msg.find("does not hold one chunk"), std::string::npos) << msg;
}

TEST(RawChunks, ChunkStoredWithoutItsOptionalDeflateIsReadAsStored) {
  // The filter mask of a chunk whose optional deflate was skipped when it was written (bit 0:
  // the first filter): both paths must read its bytes as they are.
  const auto path = test::TempDir() / "mask.h5";
  Dataset d = TexturedDataset(2, 2, 5, 6);
  const hsize_t image[5] = {1, 1, 5, 6, 3};
  WriteDataset(path, d);
  Restore(path, d, [&](hid_t p) { H5Pset_chunk(p, 5, image); H5Pset_deflate(p, 6); });
  for (float& x : d.image(1, 1)) x = -x;
  {
    const h5::File f = h5::File::OpenForUpdate(path);
    h5::Handle ds(H5Dopen2(f.id(), kData, H5P_DEFAULT));
    const hsize_t at[5] = {1, 1, 0, 0, 0};
    ASSERT_GE(H5Dwrite_chunk(ds.id(), H5P_DEFAULT, 1, at, d.image_size() * 4, d.image(1, 1).data()), 0);
  }
  ExpectPathsAgree(path, true);
  EXPECT_EQ(ReadDataset(path).data(), d.data());
}

TEST(RawChunks, CorruptEdgeChunkOfASplitImageIsNamedByItsRow) {
  const auto path = test::TempDir() / "split.h5";
  DatasetWriteOptions o;
  o.deflate_level = 1;
  WriteDataset(path, TexturedDataset(1, 2, 400, 1024), o);
  const auto [addr, size] = ChunkLocation(path, 0, 1, 341);
  FlipByte(path, addr + size / 3);
  const std::string msg = test::ErrorOf([&] { ReadDataset(path); });
  EXPECT_NE(msg.find("chunk at view 0, light 1, y 341 is corrupt"), std::string::npos) << msg;
}

}  // namespace
}  // namespace btf
