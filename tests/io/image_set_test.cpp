// Image sets imported into datasets (ImportImageSet, btf-convert --layout): small sets built in
// the test with known content, read back exactly; bad sets refused naming the files.
#include <gtest/gtest.h>

#include <zip.h>

#include <cmath>
#include <functional>

#include "libbtf/core/error.h"
#include "libbtf/io/convert.h"
#include "libbtf/io/dataset_io.h"
#include "libbtf/io/image_io.h"
#include "tests/io/bonn_test.h"
#include "tests/test_util.h"

namespace btf {
namespace {

constexpr double kDeg = 3.14159265358979323846 / 180;

// Every texel and channel differs: value = 1 + v + 0.1 l + 0.01 y + 0.001 x + 0.0001 c (exact in
// float32 EXR only up to rounding of the literal, which the test computes the same way).
float Known(int v, int l, int y, int x, int c) { return float(1 + v + 0.1 * l + 0.01 * y + 0.001 * x + 0.0001 * c); }

Image KnownImage(int v, int l, int w = 4, int h = 3) {
  Image img(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = Known(v, l, y, x, c);
  return img;
}


ConvertOptions Pattern(const std::string& p) {
  ConvertOptions o;
  o.layout = "pattern";
  o.pattern = p;
  return o;
}

// Views (theta, phi) and lights, in the order the import sorts them (theta, then phi).
const std::vector<std::pair<int, int>> kViews = {{0, 0}, {15, 60}}, kLights = {{0, 0}, {30, 30}, {45, 20}};

// Every image of a 2-view, 3-light set of KnownImage(v, l) came through exactly.
void ExpectKnownImages(const Dataset& d) {
  for (int v = 0; v < 2; ++v)
    for (int l = 0; l < 3; ++l)
      for (int y = 0; y < 3; ++y)
        for (int x = 0; x < 4; ++x)
          for (int c = 0; c < 3; ++c)
            ASSERT_EQ(d.image(v, l)[(std::size_t(y) * 4 + x) * 3 + c], Known(v, l, y, x, c)) << v << l << y << x << c;
}

TEST(ImageSet, PatternFolderGivesTheImagesExactly) {
  const auto dir = test::TempDir();
  // Written in reverse order, views in folders; a stray file is ignored.
  for (int v = 1; v >= 0; --v)
    for (int l = 2; l >= 0; --l) {
      const auto folder = dir / "set" / fmt::format("tv{}_pv{}", kViews[v].first, kViews[v].second);
      std::filesystem::create_directories(folder);
      WriteImage(folder / fmt::format("tl{}_pl{}.exr", kLights[l].first, kLights[l].second), KnownImage(v, l));
    }
  test::Bytes().Text("notes").Save(dir / "set" / "README.txt");
  const ConvertSummary s = ImportImageSet(Pattern("tv{tv}_pv{pv}/tl{tl}_pl{pl}.exr"), dir / "set", dir / "out.h5");
  EXPECT_EQ(s.missing_images, 0u);
  EXPECT_EQ(s.input_kind, "image-set:pattern");
  const Dataset d = ReadDataset(dir / "out.h5");
  ASSERT_EQ(d.num_views(), 2);
  ASSERT_EQ(d.num_lights(), 3);
  ASSERT_EQ(d.width(), 4);
  ASSERT_EQ(d.height(), 3);
  for (int v = 0; v < 2; ++v)
    EXPECT_LT((d.views()[v] - DirectionFromAngles(kViews[v].first * kDeg, kViews[v].second * kDeg)).norm(), 1e-6);
  for (int l = 0; l < 3; ++l)
    EXPECT_LT((d.lights()[l] - DirectionFromAngles(kLights[l].first * kDeg, kLights[l].second * kDeg)).norm(), 1e-6);
  ExpectKnownImages(d);
  EXPECT_EQ(d.info().units, "relative");
  EXPECT_EQ(d.info().provenance["layout"], "pattern");
}

TEST(ImageSet, Ubo2003JpegIsDecodedFromSrgbAndMissingImagesAreNamed) {
  const auto dir = test::TempDir();
  const auto set = dir / "ubo" / "tv015_pv060";
  std::filesystem::create_directories(set);
  // Bonn 81: view 2 = (15, 60), light 0 = (0, 0), light 7 = (30, 0). Flat grey images: JPEG keeps
  // a flat grey block exactly (only the DC term, Cb = Cr = 128), so the 8-bit code survives.
  ImageWriteOptions jpg;
  jpg.has_format = true;
  jpg.format = PixelFormat::kUint8;
  jpg.jpeg_quality = 100;
  const std::vector<std::pair<int, int>> stored = {{0, 40}, {7, 200}};  // light, code
  for (const auto& [l, code] : stored) {
    Image img(8, 8, 3);
    for (auto& p : img.pixels) p = float(code) / 255.0f;
    const int t = l == 0 ? 0 : 30;
    WriteImage(set / fmt::format("{:05d} tl{:03d} pl000 tv015 pv060.jpg", 81 * l + 2, t), img, jpg);
  }
  ConvertOptions o;
  o.layout = "ubo2003";
  ExitCode code{};
  const std::string e = test::ErrorOf([&] { ImportImageSet(o, dir / "ubo", dir / "out.h5"); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(e.find("6559 of 6561 images are missing"), std::string::npos) << e;
  EXPECT_NE(e.find("'00000 tl000 pl000 tv000 pv000.jpg'"), std::string::npos) << e;
  EXPECT_NE(e.find("--allow-missing"), std::string::npos) << e;
  EXPECT_FALSE(std::filesystem::exists(dir / "out.h5"));
  o.allow_missing = true;
  const ConvertSummary s = ImportImageSet(o, dir / "ubo", dir / "out.h5");
  EXPECT_EQ(s.missing_images, 6559u);
  const Dataset d = ReadDataset(dir / "out.h5");
  EXPECT_EQ(d.views().name(), Sampling::Bonn81().name());
  EXPECT_EQ(d.info().provenance["missing_images"], 6559);
  // The decoder's sRGB curve and SrgbToLinear differ in float rounding (1e-6); neighbouring 8-bit
  // codes are 6e-3 apart at code 200, so the code is exact.
  for (const auto& [l, c] : stored)
    for (float x : d.image(2, l)) ASSERT_NEAR(x, SrgbToLinear(float(c) / 255.0f), 1e-6) << l;
  for (float x : d.image(2, 1)) ASSERT_EQ(x, 0.0f);  // missing: 0
  for (float x : d.image(0, 0)) ASSERT_EQ(x, 0.0f);
}

// A Radiance RGBE file built byte by byte (flat scanlines, width < 8 so no run-length encoding),
// resolution line "-Y H +X W" (top row first); `pixels` hold values exact in RGBE.
void SaveHdr(const std::filesystem::path& path, int w, int h, const std::function<float(int x, int y, int c)>& value) {
  test::Bytes f;
  f.Text("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n").Text(fmt::format("-Y {} +X {}\n", h, w));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float rgb[3];
      for (int c = 0; c < 3; ++c) rgb[c] = value(x, y, c);
      int e = 0;
      std::frexp(std::max({rgb[0], rgb[1], rgb[2]}), &e);
      for (float v : rgb) f.U8(std::uint8_t(std::ldexp(v, 8 - e)));
      f.U8(std::uint8_t(e + 128));
    }
  f.Save(path);
}

TEST(ImageSet, AtriumHdrIsReadAsStored) {
  const auto dir = test::TempDir();
  std::filesystem::create_directories(dir / "atrium");
  // Bonn 81 view 8 = (30, 30), light 1 = (15, 0): image number 81 + 8 = 89. Values k/8 with a
  // shared exponent: exact in RGBE.
  auto value = [](int x, int y, int c) { return float(1 + x + 3 * y + 7 * c) / 8.0f; };
  SaveHdr(dir / "atrium" / "00089 tl015 pl000 tv030 pv030.hdr", 3, 2, value);
  ConvertOptions o;
  o.layout = "atrium";
  o.allow_missing = true;
  ImportImageSet(o, dir / "atrium", dir / "out.h5");
  const Dataset d = ReadDataset(dir / "out.h5");
  ASSERT_EQ(d.width(), 3);
  ASSERT_EQ(d.height(), 2);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x)
      for (int c = 0; c < 3; ++c) ASSERT_EQ(d.image(8, 1)[(std::size_t(y) * 3 + x) * 3 + c], value(x, y, c)) << x << y << c;
}

TEST(ImageSet, BadSetsAreRefusedNamingTheFiles) {
  const auto dir = test::TempDir();
  const auto set = dir / "set";
  std::filesystem::create_directories(set);
  for (int v = 0; v < 2; ++v)
    for (int l = 0; l < 3; ++l)
      WriteImage(set / fmt::format("tl{}_pl{}_tv{}_pv{}.exr", kLights[l].first, kLights[l].second, kViews[v].first,
                                   kViews[v].second),
                 KnownImage(v, l));
  const ConvertOptions p = Pattern("tl{tl}_pl{pl}_tv{tv}_pv{pv}.exr");
  ImportImageSet(p, set, dir / "ok.h5");  // the complete set imports
  auto refused = [&](const ConvertOptions& o, const std::string& words, ExitCode want = ExitCode::kBadInput) {
    ExitCode code{};
    const std::string e = test::ErrorOf([&] { ImportImageSet(o, set, dir / "out.h5"); }, &code);
    EXPECT_EQ(code, want) << e;
    EXPECT_NE(e.find(words), std::string::npos) << e;
    EXPECT_FALSE(std::filesystem::exists(dir / "out.h5"));
  };
  // An image larger than --max-pixels (4 x 3 = 12 pixels each) is refused before it is read.
  ConvertOptions small = p;
  small.max_pixels = 11;
  refused(small, "claims 4 x 3 = 12 pixels, over the limit of 11 (--max-pixels)");
  small.max_pixels = 12;
  ImportImageSet(small, set, dir / "ok12.h5");
  // Another image of a different size; then the same (view, light) under two names.
  WriteImage(set / "tl30_pl30_tv15_pv60.exr", KnownImage(1, 1, 5, 3));
  refused(p, "tl30_pl30_tv15_pv60.exr' is 5 x 3 with 3 channels");
  WriteImage(set / "tl30_pl30_tv15_pv60.exr", KnownImage(1, 1));
  WriteImage(set / "tl30.0_pl30_tv15_pv60.exr", KnownImage(1, 1));
  refused(p, "are both view (theta 15, phi 60) light (theta 30, phi 30)");
  std::filesystem::remove(set / "tl30.0_pl30_tv15_pv60.exr");
  // A missing image of a pattern set is named by its directions.
  std::filesystem::remove(set / "tl45_pl20_tv0_pv0.exr");
  refused(p, "1 of 6 images are missing (view (theta 0, phi 0) light (theta 45, phi 20))");
  // Nothing matches; a folder that is a file; theta beyond the horizon; a pattern without a field.
  refused(Pattern("{tv}_{pv}_{tl}_{pl}.png"), "no file in");
  ExitCode code{};
  EXPECT_NE(test::ErrorOf([&] { ImportImageSet(p, set / "tl0_pl0_tv0_pv0.exr", dir / "out.h5"); }, &code)
                .find("is neither a folder nor a readable zip archive"),
            std::string::npos);
  EXPECT_EQ(code, ExitCode::kBadInput);
  WriteImage(set / "tl95_pl0_tv0_pv0.exr", KnownImage(0, 0));
  refused(p, "theta 95 degrees is outside [0, 90)");
  std::filesystem::remove(set / "tl95_pl0_tv0_pv0.exr");
  refused(Pattern("tl{tl}_pl{pl}_tv{tv}.exr"), "must hold each of the fields", ExitCode::kUsage);
  ConvertOptions bdi = p;
  bdi.to = "bdi";
  refused(bdi, "imported into a dataset", ExitCode::kUsage);
  // UBO2003: a number that disagrees with the directions, a direction outside Bonn 81.
  const auto ubo = dir / "ubo";
  std::filesystem::create_directories(ubo);
  ConvertOptions u;
  u.layout = "ubo2003";
  u.allow_missing = true;
  Image grey(8, 8, 3);
  WriteImage(ubo / "00005 tl000 pl000 tv015 pv060.jpg", grey);  // view 2: should be 00002
  EXPECT_NE(test::ErrorOf([&] { ImportImageSet(u, ubo, dir / "out.h5"); }).find("image number 5 disagrees"), std::string::npos);
  std::filesystem::remove(ubo / "00005 tl000 pl000 tv015 pv060.jpg");
  WriteImage(ubo / "00002 tl000 pl000 tv016 pv060.jpg", grey);
  EXPECT_NE(test::ErrorOf([&] { ImportImageSet(u, ubo, dir / "out.h5"); }).find("view direction (theta 16, phi 60) is not one"),
            std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(dir / "out.h5"));
}

// CRC-32 (ISO 3309, the zip one), bit by bit: independent of zlib and libzip.
std::uint32_t Crc32(const std::vector<char>& data) {
  std::uint32_t crc = 0xffffffffu;
  for (char ch : data) {
    crc ^= std::uint8_t(ch);
    for (int k = 0; k < 8; ++k) crc = crc & 1 ? (crc >> 1) ^ 0xedb88320u : crc >> 1;
  }
  return ~crc;
}

std::vector<char> FileBytes(const std::filesystem::path& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

// A zip archive of stored (uncompressed) entries, written byte by byte from PKWARE's APPNOTE
// (4.3.7 local file header, 4.3.12 central directory header, 4.3.16 end of central directory).
test::Bytes StoredZip(const std::vector<std::pair<std::string, std::vector<char>>>& entries) {
  test::Bytes zip, central;
  for (const auto& [name, data] : entries) {
    const std::uint32_t offset = std::uint32_t(zip.size()), crc = Crc32(data), size = std::uint32_t(data.size());
    zip.U32(0x04034b50).U16(20).U16(0).U16(0).U16(0).U16(0x21).U32(crc).U32(size).U32(size);
    zip.U16(std::uint16_t(name.size())).U16(0).Text(name);
    zip.b.insert(zip.b.end(), data.begin(), data.end());
    central.U32(0x02014b50).U16(20).U16(20).U16(0).U16(0).U16(0).U16(0x21).U32(crc).U32(size).U32(size);
    central.U16(std::uint16_t(name.size())).U16(0).U16(0).U16(0).U16(0).U32(0).U32(offset).Text(name);
  }
  const std::uint32_t cd_offset = std::uint32_t(zip.size()), cd_size = std::uint32_t(central.size());
  zip.Append(central);
  zip.U32(0x06054b50).U16(0).U16(0).U16(std::uint16_t(entries.size())).U16(std::uint16_t(entries.size()));
  zip.U32(cd_size).U32(cd_offset).U16(0);
  return zip;
}

// The pattern set of PatternFolderGivesTheImagesExactly, zipped (stored entries, built byte by
// byte, under a top folder as real archives have): the same dataset, bit for bit.
TEST(ImageSet, ZipArchiveBuiltByteByByteGivesTheImagesExactly) {
  const auto dir = test::TempDir();
  std::vector<std::pair<std::string, std::vector<char>>> entries = {{"set/", {}}};
  for (int v = 1; v >= 0; --v)
    for (int l = 2; l >= 0; --l) {
      const auto file = dir / "img.exr";
      WriteImage(file, KnownImage(v, l));
      entries.emplace_back(fmt::format("set/tv{}_pv{}/tl{}_pl{}.exr", kViews[v].first, kViews[v].second,
                                       kLights[l].first, kLights[l].second),
                           FileBytes(file));
    }
  entries.emplace_back("set/README.txt", std::vector<char>{'h', 'i'});
  StoredZip(entries).Save(dir / "set.zip");
  const ConvertSummary s = ImportImageSet(Pattern("set/tv{tv}_pv{pv}/tl{tl}_pl{pl}.exr"), dir / "set.zip", dir / "out.h5");
  EXPECT_EQ(s.missing_images, 0u);
  const Dataset d = ReadDataset(dir / "out.h5");
  ASSERT_EQ(d.num_views(), 2);
  ASSERT_EQ(d.num_lights(), 3);
  ExpectKnownImages(d);

  // One flipped byte inside an entry's data fails its CRC: named as archive:entry, nothing written.
  test::Bytes bad = StoredZip(entries);
  const std::string victim = "set/tv15_pv60/tl30_pl30.exr";
  const auto at = std::search(bad.b.begin(), bad.b.end(), victim.begin(), victim.end()) - bad.b.begin();
  bad.b[std::size_t(at) + victim.size() + 40] ^= 0x5a;
  bad.Save(dir / "bad.zip");
  ExitCode code{};
  std::string e = test::ErrorOf([&] { ImportImageSet(Pattern("set/tv{tv}_pv{pv}/tl{tl}_pl{pl}.exr"), dir / "bad.zip", dir / "o.h5"); },
                                &code);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(e.find((dir / "bad.zip").string() + ":" + victim + "': the zip entry is corrupt"), std::string::npos) << e;
  EXPECT_FALSE(std::filesystem::exists(dir / "o.h5"));
  // A truncated archive (its central directory cut off) is refused as a whole.
  bad = StoredZip(entries);
  bad.b.resize(bad.b.size() - 30);
  bad.Save(dir / "cut.zip");
  e = test::ErrorOf([&] { ImportImageSet(Pattern("set/tv{tv}_pv{pv}/tl{tl}_pl{pl}.exr"), dir / "cut.zip", dir / "o.h5"); }, &code);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(e.find("cut.zip' is neither a folder nor a readable zip archive"), std::string::npos) << e;
  EXPECT_FALSE(std::filesystem::exists(dir / "o.h5"));
}

// A UBO2003 set as Bonn ships it: a deflated zip with a folder per view (written by libzip, an
// independent writer), JPEG decoded from sRGB as from a folder.
TEST(ImageSet, DeflatedUbo2003ZipIsReadAsTheFolder) {
  const auto dir = test::TempDir();
  const auto folder = dir / "ubo" / "tv015_pv060";
  std::filesystem::create_directories(folder);
  Image img(8, 8, 3);
  for (auto& p : img.pixels) p = 120.0f / 255.0f;
  ImageWriteOptions jpg;
  jpg.jpeg_quality = 100;
  const std::string name = "00083 tl015 pl000 tv015 pv060.jpg";  // light 1 (15, 0), view 2 (15, 60)
  WriteImage(folder / name, img, jpg);
  const std::vector<char> bytes = FileBytes(folder / name);
  int err = 0;
  zip_t* z = zip_open((dir / "ubo.zip").c_str(), ZIP_CREATE | ZIP_TRUNCATE, &err);
  ASSERT_NE(z, nullptr);
  zip_source_t* src = zip_source_buffer(z, bytes.data(), bytes.size(), 0);
  ASSERT_GE(zip_file_add(z, ("tv015_pv060/" + name).c_str(), src, ZIP_FL_ENC_UTF_8), 0);
  ASSERT_EQ(zip_set_file_compression(z, 0, ZIP_CM_DEFLATE, 9), 0);
  ASSERT_EQ(zip_close(z), 0);
  ConvertOptions o;
  o.layout = "ubo2003";
  o.allow_missing = true;
  ImportImageSet(o, dir / "ubo", dir / "folder.h5");
  ImportImageSet(o, dir / "ubo.zip", dir / "zip.h5");
  const Dataset a = ReadDataset(dir / "folder.h5"), b = ReadDataset(dir / "zip.h5");
  const auto ia = a.image(2, 1), ib = b.image(2, 1);
  EXPECT_TRUE(std::equal(ia.begin(), ia.end(), ib.begin(), ib.end()));
  for (float x : b.image(2, 1)) ASSERT_NEAR(x, SrgbToLinear(120.0f / 255.0f), 1e-6);
}

// ubo2014-images: UBO2014 Dome 1 directions, NNNNN = 151 light + view, angles with decimals and
// matched within 0.5 degrees (Bonn stores them to about 0.5 degrees).
TEST(ImageSet, Ubo2014ImagesUseTheDome1Sampling) {
  const auto dir = test::TempDir();
  std::filesystem::create_directories(dir / "set");
  // Dome 1: index 0 the pole, 1-6 theta 11 (phi 15 + 60 k), 7-18 theta 23.5 (phi 30 k). Light 8 =
  // (23.5, 30), view 2 = (11, 75); the file's angles are off by 0.3 degrees.
  WriteImage(dir / "set" / "01210 tl23.8 pl30.2 tv11 pv75.exr", KnownImage(2, 8));
  ConvertOptions o;
  o.layout = "ubo2014-images";
  o.allow_missing = true;
  const ConvertSummary s = ImportImageSet(o, dir / "set", dir / "out.h5");
  EXPECT_EQ(s.missing_images, 151u * 151u - 1u);
  const Dataset d = ReadDataset(dir / "out.h5");
  EXPECT_EQ(d.views().name(), Sampling::Ubo151().name());
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 4; ++x)
      for (int c = 0; c < 3; ++c) ASSERT_EQ(d.image(2, 8)[(std::size_t(y) * 4 + x) * 3 + c], Known(2, 8, y, x, c));
  // Without --allow-missing the first missing names are given in this layout's naming; a number
  // that disagrees with 151 light + view is refused.
  o.allow_missing = false;
  std::string e = test::ErrorOf([&] { ImportImageSet(o, dir / "set", dir / "o.h5"); });
  EXPECT_NE(e.find("22800 of 22801 images are missing ('00000 tl0 pl0 tv0 pv0.*'"), std::string::npos) << e;
  WriteImage(dir / "set" / "00081 tl11 pl15 tv0 pv0.exr", KnownImage(0, 1));  // light 1 view 0: 151, not 81
  o.allow_missing = true;
  e = test::ErrorOf([&] { ImportImageSet(o, dir / "set", dir / "o.h5"); });
  EXPECT_NE(e.find("image number 81 disagrees with its directions (light 1, view 0: 151 x light + view = 151)"),
            std::string::npos)
      << e;
}

}  // namespace
}  // namespace btf
