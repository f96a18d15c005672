// The entry points that know every libbtf BTF file (codec_source.h): OpenSource's kinds and its
// codec, and DescribeFile, btf-info's summary of each format.
#include "libbtf/compress/codec_source.h"

#include <gtest/gtest.h>

#include "libbtf/core/error.h"
#include "libbtf/io/bonn.h"
#include "libbtf/io/file_kind.h"
#include "libbtf/io/hdf5.h"
#include "tests/codec_util.h"
#include "tests/compress/synthetic.h"
#include "tests/test_util.h"

namespace btf {
namespace {

TEST(CodecSource, OpenSourceAndDescribeFileKnowDatasetsCodecsAndBonnFiles) {
  const Dataset d = test::PerViewLowRank(test::BonnSubset(3), test::BonnSubset(5), 4, 4, 2, 1e-3);
  const auto dir = test::TempDir();
  const auto dataset = dir / "d.h5", codec_file = dir / "c.h5", bonn = dir / "b.btf";
  WriteDataset(dataset, d);
  CompressOptions o;
  o.components = 2;
  WriteCodec(codec_file, test::CompressDataset(d, o));
  WriteBdi(bonn, *MemorySource(d));

  for (const auto& path : {dataset, codec_file, bonn}) {
    const auto source = OpenSource(path);
    EXPECT_EQ(source->kind(), FileFormatOf(path)) << path;
    // A codec file alone opens as a CodecSource.
    EXPECT_EQ(dynamic_cast<const CodecSource*>(source.get()) != nullptr, path == codec_file) << path;
    EXPECT_EQ(DescribeFile(path, false)["format"], FileFormatOf(path)) << path;
  }
  // The codec a CodecSource keeps is the file's, and its slots are the codec's decoded slots.
  const auto source = OpenCodecSource(codec_file);
  const Codec read = ReadCodec(codec_file);
  EXPECT_EQ(source->codec().DecodeAll().data(), read.DecodeAll().data());
  std::vector<float> slot(source->slot_size());
  source->ReadViewSlot(1, slot.data());
  const Dataset all = read.DecodeAll();
  EXPECT_TRUE(std::equal(slot.begin(), slot.end(), all.data().begin() + source->slot_size()));

  // DescribeFile: each format's own summary (with the value scan where asked), a codec's with its path.
  EXPECT_EQ(DescribeFile(dataset, true), DescribeDatasetFile(dataset, true));
  EXPECT_TRUE(DescribeFile(dataset, true).contains("values"));
  EXPECT_FALSE(DescribeFile(dataset, false).contains("values"));
  EXPECT_EQ(DescribeFile(bonn, true), DescribeBonnFile(bonn, true));
  nlohmann::json want = read.Describe();
  want["path"] = codec_file.string();
  EXPECT_EQ(DescribeFile(codec_file, true), want);
  EXPECT_EQ(source->Describe(), want);
}

TEST(CodecSource, DescribeFileRefusesAnotherFormatNamingIt) {
  const auto path = test::TempDir() / "other.h5";
  {
    h5::File f = h5::File::Create(path);
    f.SetAttr("/", "format", std::string("libbtf-other"));
    f.Close();
  }
  try {
    DescribeFile(path, false);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("holds format 'libbtf-other'"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace btf
