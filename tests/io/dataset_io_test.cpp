#include "libbtf/io/dataset_io.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "libbtf/core/error.h"
#include "tests/test_util.h"

namespace btf {
namespace {

Dataset SmallDataset() {
  Dataset d = test::MakeTestDataset(3, 4, 5, 6);
  d.info().cos_theta_i_included = true;
  d.info().texel_size_mm = 0.25;
  d.info().provenance = {{"tool", "test"}, {"seed", 7}};
  return d;
}

TEST(DatasetIo, RoundTripFloat32IsExact) {
  const auto path = test::TempDir() / "d.h5";
  const Dataset d = SmallDataset();
  WriteDataset(path, d);
  const Dataset r = ReadDataset(path);
  ASSERT_EQ(r.num_views(), 3);
  ASSERT_EQ(r.num_lights(), 4);
  ASSERT_EQ(r.height(), 5);
  ASSERT_EQ(r.width(), 6);
  ASSERT_EQ(r.channels(), 3);
  EXPECT_EQ(r.data(), d.data());
  EXPECT_TRUE(r.info().cos_theta_i_included);
  EXPECT_EQ(r.info().texel_size_mm, 0.25);
  EXPECT_EQ(r.info().provenance["seed"], 7);
  EXPECT_EQ(r.info().channel_names, (std::vector<std::string>{"R", "G", "B"}));
  for (int i = 0; i < 3; ++i) EXPECT_LT((r.views()[i] - d.views()[i]).norm(), 1e-15);
  EXPECT_EQ(r.views().name(), d.views().name());
}

TEST(DatasetIo, Float16StorageKeepsThreeSignificantDigits) {
  const auto path = test::TempDir() / "h.h5";
  const Dataset d = SmallDataset();
  DatasetWriteOptions opt;
  opt.storage = h5::Storage::kFloat16;
  WriteDataset(path, d, opt);
  DatasetReader reader(path);
  EXPECT_EQ(reader.header().storage, "float16");
  const Dataset r = ReadDataset(path);
  // binary16 has an 11-bit significand: relative rounding error <= 2^-11.
  for (std::size_t i = 0; i < d.size(); ++i)
    EXPECT_LE(std::abs(r.data()[i] - d.data()[i]), std::abs(d.data()[i]) * std::ldexp(1.0, -11) + 1e-7);
}

TEST(DatasetIo, PartialReadsMatchTheWholeDataset) {
  const auto path = test::TempDir() / "p.h5";
  const Dataset d = SmallDataset();
  WriteDataset(path, d);
  DatasetReader reader(path);
  std::vector<float> img(d.image_size()), slot(d.image_size() * 4);
  reader.ReadImage(2, 3, img.data());
  EXPECT_TRUE(std::equal(img.begin(), img.end(), d.image(2, 3).begin()));
  reader.ReadViewSlot(1, slot.data());
  EXPECT_TRUE(std::equal(slot.begin(), slot.end(), d.view_slot(1).begin()));
  EXPECT_THROW(reader.ReadImage(3, 0, img.data()), Error);  // out of range view
}

TEST(DatasetIo, DatasetIsChunkedPerImageWithShuffleDeflateAndChecksums) {
  const auto path = test::TempDir() / "c.h5";
  WriteDataset(path, SmallDataset());
  const h5::File f = h5::File::Open(path);
  h5::Handle ds(H5Dopen2(f.id(), "/btf/data", H5P_DEFAULT));
  h5::Handle dcpl(H5Dget_create_plist(ds.id()));
  hsize_t chunk[5];
  ASSERT_EQ(H5Pget_chunk(dcpl.id(), 5, chunk), 5);
  EXPECT_EQ(chunk[0], 1u);
  EXPECT_EQ(chunk[1], 1u);
  EXPECT_EQ(chunk[2], 5u);
  EXPECT_EQ(chunk[3], 6u);
  ASSERT_EQ(H5Pget_nfilters(dcpl.id()), 3);
  std::vector<H5Z_filter_t> filters;
  for (unsigned i = 0; i < 3; ++i) {
    unsigned flags = 0, config = 0;
    std::size_t n = 0;
    filters.push_back(H5Pget_filter2(dcpl.id(), i, &flags, &n, nullptr, 0, nullptr, &config));
  }
  EXPECT_EQ(filters, (std::vector<H5Z_filter_t>{H5Z_FILTER_SHUFFLE, H5Z_FILTER_DEFLATE, H5Z_FILTER_FLETCHER32}));
  EXPECT_EQ(f.GetString("/btf/data", "dimension_names"), "view,light,y,x,channel");
}

// Copies a good file and lets the test damage it.
std::filesystem::path WriteGood(const std::filesystem::path& dir) {
  const auto path = dir / "good.h5";
  WriteDataset(path, SmallDataset());
  return path;
}

void ExpectBadInput(const std::filesystem::path& path, const std::string& fragment) {
  try {
    ReadDataset(path);
    FAIL() << "expected an error for " << path;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput) << e.what();
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(DatasetIo, RefusesNewerMajorVersion) {
  const auto dir = test::TempDir();
  const auto path = WriteGood(dir);
  {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    h5::Handle f(H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT));
    H5Adelete(f.id(), "format_version");
    h5::Handle t(H5Tcopy(H5T_C_S1));
    H5Tset_size(t.id(), 5);
    h5::Handle sp(H5Screate(H5S_SCALAR));
    h5::Handle a(H5Acreate2(f.id(), "format_version", t.id(), sp.id(), H5P_DEFAULT, H5P_DEFAULT));
    H5Awrite(a.id(), t.id(), "2.0.0");
  }
  ExpectBadInput(path, "newer");
}

TEST(DatasetIo, RefusesMissingRequiredDataset) {
  const auto dir = test::TempDir();
  const auto path = WriteGood(dir);
  {
    h5::Handle f(H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT));
    H5Ldelete(f.id(), "/btf/light_directions", H5P_DEFAULT);
  }
  ExpectBadInput(path, "light_directions");
}

TEST(DatasetIo, RefusesTruncatedAndForeignFiles) {
  const auto dir = test::TempDir();
  const auto path = WriteGood(dir);
  const auto size = std::filesystem::file_size(path);
  std::filesystem::copy_file(path, dir / "trunc.h5");
  std::filesystem::resize_file(dir / "trunc.h5", size / 2);
  EXPECT_THROW(ReadDataset(dir / "trunc.h5"), Error);
  {
    std::ofstream f(dir / "text.h5");
    f << "not an hdf5 file\n";
  }
  ExpectBadInput(dir / "text.h5", "not an HDF5 file");
  try {
    ReadDataset(dir / "missing.h5");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kIo);
  }
}

TEST(DatasetIo, FailedWriteLeavesExistingFileUntouched) {
  const auto dir = test::TempDir();
  const auto path = WriteGood(dir);
  const auto before = std::filesystem::file_size(path);
  {
    DatasetWriter w(path, Sampling::Bonn81(), Sampling::Bonn81(), 4, 4, 3, DatasetInfo{});
    // Destroyed without Commit(), as when an exception unwinds a producer.
  }
  EXPECT_EQ(std::filesystem::file_size(path), before);
  EXPECT_NO_THROW(ReadDataset(path));
  for (const auto& e : std::filesystem::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << "stray temporary " << e.path();
}

}  // namespace
}  // namespace btf

namespace btf {
namespace {

TEST(DatasetIo, RefusesFilesWithoutMetadataChecksums) {
  // An HDF5 file with superblock version 0 (no metadata checksums) is refused before HDF5 parses
  // its metadata (docs/format.md: HDF5 1.10.8 is not memory-safe on damaged unchecksummed metadata).
  const auto path = test::TempDir() / "old.h5";
  h5::Handle fapl(H5Pcreate(H5P_FILE_ACCESS));
  H5Pset_libver_bounds(fapl.id(), H5F_LIBVER_EARLIEST, H5F_LIBVER_V18);
  { h5::Handle f(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.id())); }
  ExpectBadInput(path, "superblock version 0");
}

// Limits (docs/errors.md): a header claiming ~10^12 texels per image is refused before anything
// is allocated, naming the limit and how to raise it. The file itself is small: HDF5 allocates
// chunks only when they are written.
TEST(DatasetIo, HeaderClaimingAbsurdSizeIsRefusedBeforeAllocating) {
  const auto path = test::TempDir() / "huge.h5";
  {
    DatasetWriter w(path, Sampling::Bonn81(), Sampling::Bonn81(), 1 << 20, 1 << 20, 3, DatasetInfo{});
    w.Commit();
  }
  ASSERT_LT(std::filesystem::file_size(path), 1u << 20);
  ExpectBadInput(path, "BTF_MAX_BYTES");
  ExpectBadInput(path, "one view slot");
}

}  // namespace
}  // namespace btf
