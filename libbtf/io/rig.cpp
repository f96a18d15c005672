#include "libbtf/io/rig.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>

#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"
#include "libbtf/io/json_util.h"

#include <opencv2/aruco/charuco.hpp>
#include <opencv2/core.hpp>

namespace btf {
namespace {

using json = nlohmann::json;

constexpr const char* kBoardFormat = "libbtf-board";
constexpr const char* kManifestFormat = "libbtf-manifest";
constexpr const char* kTruthFormat = "libbtf-truth";
constexpr const char* kRigVersion = "1.0.0";
constexpr int kRigMajor = 1;

json LoadJson(const std::filesystem::path& path) {
  const std::string text = ReadFileBytes(path, "JSON file");
  try {
    return json::parse(text);
  } catch (const json::exception& e) {
    ThrowBadInput("'{}': not valid JSON ({})", path.string(), e.what());
  }
}

// Accessor that names the file and the JSON path in every error.
class Node {
 public:
  Node(const std::filesystem::path* file, const json* j, std::string where)
      : file_(file), j_(j), where_(std::move(where)) {}

  [[noreturn]] void Fail(const std::string& what) const {
    ThrowBadInput("'{}': {}: {}", file_->string(), where_.empty() ? std::string("top level") : where_, what);
  }
  bool Has(const std::string& key) const { return j_->is_object() && j_->contains(key); }
  Node operator[](const std::string& key) const {
    if (!j_->is_object()) Fail("must be a JSON object");
    if (!j_->contains(key)) Fail(fmt::format("missing required field '{}'", key));
    return Node(file_, &(*j_)[key], where_.empty() ? key : where_ + "." + key);
  }
  Node At(std::size_t i) const {
    return Node(file_, &(*j_)[i], fmt::format("{}[{}]", where_, i));
  }
  std::size_t ArraySize(std::size_t expected = 0) const {
    if (!j_->is_array()) Fail("must be a JSON array");
    if (expected && j_->size() != expected) Fail(fmt::format("must have {} entries, found {}", expected, j_->size()));
    return j_->size();
  }
  double Double() const {
    if (!j_->is_number()) Fail("must be a number");
    const double v = j_->get<double>();
    if (!std::isfinite(v)) Fail("must be finite");
    return v;
  }
  int Int() const {
    if (!j_->is_number_integer()) Fail("must be an integer");
    return j_->get<int>();
  }
  std::string String() const {
    if (!j_->is_string()) Fail("must be a string");
    return j_->get<std::string>();
  }
  Vec2 Vector2() const {
    ArraySize(2);
    return Vec2(At(0).Double(), At(1).Double());
  }
  Vec3 Vector3() const {
    ArraySize(3);
    return Vec3(At(0).Double(), At(1).Double(), At(2).Double());
  }
  Vec3 UnitVector() const {
    const Vec3 v = Vector3();
    if (std::abs(v.norm() - 1) > 1e-3) Fail("must be a unit vector (length within 1e-3 of 1)");
    return v.normalized();
  }
  Eigen::Matrix3d Matrix3() const {
    ArraySize(3);
    Eigen::Matrix3d m;
    for (int r = 0; r < 3; ++r) m.row(r) = At(static_cast<std::size_t>(r)).Vector3().transpose();
    return m;
  }
  const json& raw() const { return *j_; }
  const std::string& where() const { return where_; }

 private:
  const std::filesystem::path* file_;
  const json* j_;
  std::string where_;
};

void CheckHeader(const Node& root, const char* format) {
  const std::string f = root["format"].String();
  if (f != format) root.Fail(fmt::format("'format' is '{}', expected '{}'", f, format));
  const std::string v = root["format_version"].String();
  int major = -1;
  try {
    major = std::stoi(v.substr(0, v.find('.')));
  } catch (...) {
    root.Fail(fmt::format("'format_version' '{}' is not MAJOR.MINOR.PATCH", v));
  }
  if (major < 0 || major > kRigMajor)
    root.Fail(fmt::format("'format_version' {} is newer than this reader ({}.x): update libbtf", v, kRigMajor));
}

json Header(const char* format) {
  json j;
  j["format"] = format;
  j["format_version"] = kRigVersion;
  return j;
}


json SamplingToJson(const Sampling& s) {
  json j;
  j["name"] = s.name();
  json dirs = json::array();
  for (const auto& d : s.directions()) dirs.push_back(ToJson(d));
  j["directions"] = dirs;
  return j;
}

Sampling SamplingFromJson(const Node& n) {
  const std::string name = n["name"].String();
  const Node dirs = n["directions"];
  const std::size_t count = dirs.ArraySize();
  if (count == 0) dirs.Fail("must not be empty");
  std::vector<Vec3> v;
  for (std::size_t i = 0; i < count; ++i) {
    v.push_back(dirs.At(i).UnitVector());
    if (v.back().z() <= 0) dirs.At(i).Fail("direction must lie in the upper hemisphere (z > 0)");
  }
  return Sampling(name, std::move(v));
}

void WriteJsonAtomic(const std::filesystem::path& path, const json& j) { WriteTextFileAtomic(path, j.dump(2) + "\n"); }

}  // namespace

void Board::Check(const std::string& source) const {
  if (family.empty()) ThrowBadInput("'{}': board family is empty", source);
  if (!(std::isfinite(sample_size_mm) && sample_size_mm >= 0 && sample_size_mm <= 2 * kMaxBoardMm))
    ThrowBadInput("'{}': sample_size_mm must be a number from 0 (a calibration target) to {:g}, found {}", source,
                  2 * kMaxBoardMm, sample_size_mm);
  if (border_bits < 1 || border_bits > 2) ThrowBadInput("'{}': border_bits must be 1 or 2, found {}", source, border_bits);
  if (markers.empty()) ThrowBadInput("'{}': the board has no markers", source);
  std::set<int> ids;
  for (std::size_t i = 0; i < markers.size(); ++i) {
    const Marker& m = markers[i];
    if (m.id < 0) ThrowBadInput("'{}': markers[{}]: id {} is negative", source, i, m.id);
    if (!ids.insert(m.id).second) ThrowBadInput("'{}': markers[{}]: duplicate marker id {}", source, i, m.id);
    if (!(std::abs(m.height_mm) <= kMaxBoardMm))
      ThrowBadInput("'{}': markers[{}] (id {}): height_mm is {}; it must be finite and within +-{:g} mm", source, i,
                    m.id, m.height_mm, kMaxBoardMm);
    double area2 = 0;  // shoelace, twice the signed area
    for (int k = 0; k < 4; ++k) {
      const Vec2& p = m.corners_mm[k];
      if (!(std::abs(p.x()) <= kMaxBoardMm && std::abs(p.y()) <= kMaxBoardMm))
        ThrowBadInput("'{}': markers[{}] (id {}): corner {} is ({}, {}); corners must be finite and within +-{:g} mm "
                      "of the origin",
                      source, i, m.id, k, p.x(), p.y(), kMaxBoardMm);
      const Vec2& a = m.corners_mm[k];
      const Vec2& b = m.corners_mm[(k + 1) % 4];
      area2 += a.x() * b.y() - a.y() * b.x();
    }
    if (std::abs(area2) < 1e-6)
      ThrowBadInput("'{}': markers[{}] (id {}): corners are degenerate (zero area)", source, i, m.id);
  }
}

Board MakeAprilGridBoard(const AprilGrid& grid, const std::string& family, int border_bits) {
  Board b;
  b.family = family;
  b.border_bits = border_bits;
  b.sample_size_mm = 0;
  b.grid = grid;
  const double s = grid.tag_size_mm, pitch = s * (1 + grid.spacing);
  const double w = grid.cols * s + (grid.cols - 1) * grid.spacing * s, h = grid.rows * s + (grid.rows - 1) * grid.spacing * s;
  for (int r = 0; r < grid.rows; ++r)
    for (int c = 0; c < grid.cols; ++c) {
      Marker m;
      m.id = grid.first_id + r * grid.cols + c;
      const Vec2 o(-w / 2 + c * pitch, -h / 2 + r * pitch);  // bottom-left corner of the tag
      m.corners_mm = {o, o + Vec2(s, 0), o + Vec2(s, s), o + Vec2(0, s)};
      b.markers.push_back(m);
    }
  return b;
}

namespace {

// OpenCV's PREDEFINED_DICTIONARY_NAME of a ChArUco dictionary name; bad input names `source`.
int CharucoDictionary(const std::string& name, const std::string& source) {
  const std::string names[] = {"DICT_4X4_50", "DICT_4X4_100", "DICT_4X4_250", "DICT_4X4_1000", "DICT_5X5_50",
                               "DICT_5X5_100", "DICT_5X5_250", "DICT_5X5_1000", "DICT_6X6_50", "DICT_6X6_100",
                               "DICT_6X6_250", "DICT_6X6_1000", "DICT_7X7_50", "DICT_7X7_100", "DICT_7X7_250",
                               "DICT_7X7_1000", "DICT_ARUCO_ORIGINAL"};
  for (int i = 0; i < static_cast<int>(std::size(names)); ++i)
    if (name == names[i]) return i;  // OpenCV's PREDEFINED_DICTIONARY_NAME order
  ThrowBadInput("'{}': field 'dictionary' is '{}': use one of DICT_4X4_50 .. DICT_7X7_1000, DICT_ARUCO_ORIGINAL",
                source, name);
}

}  // namespace

namespace {

// A ChArUco definition, checked before OpenCV builds the board: CharucoBoard::create matches every
// chessboard corner against every marker, so an absurd size costs seconds before a mismatch that
// the sizes alone show. Fields are named as in Kalibr's YAML, or as in our board JSON with `json`.
// Returns the dictionary's id.
int CheckCharuco(const CharucoDefinition& c, const std::string& source, bool json = false) {
  const auto name = [json](const char* yaml, const char* ours) { return json ? ours : yaml; };
  if (c.squares_x < 2 || c.squares_y < 2 || c.squares_x * static_cast<long>(c.squares_y) > 100000)
    ThrowBadInput("'{}': fields '{}' and '{}' must be >= 2 (and at most 100000 squares), found {} x {}", source,
                  name("squaresX", "charuco.squares_x"), name("squaresY", "charuco.squares_y"), c.squares_x,
                  c.squares_y);
  if (!(c.square_mm > 0 && 0.5 * std::max(c.squares_x, c.squares_y) * c.square_mm <= kMaxBoardMm))
    ThrowBadInput("'{}': field '{}' must be > 0 {}, and the board must lie within +-{:g} mm of its centre", source,
                  name("squareSize", "charuco.square_mm"), name("(metres)", "(mm)"), kMaxBoardMm);
  if (!(c.marker_mm > 0 && c.marker_mm < c.square_mm))
    ThrowBadInput("'{}': field '{}' must be > 0 and below {}", source, name("markerSize", "charuco.marker_mm"),
                  name("squareSize", "square_mm"));
  const int dict = CharucoDictionary(c.dictionary, source);
  // OpenCV 4.6 puts a marker in every white square: squares_x * squares_y / 2 of them, rounded down.
  const long needed = c.squares_x * static_cast<long>(c.squares_y) / 2;
  const int available =
      cv::aruco::getPredefinedDictionary(static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(dict))->bytesList.rows;
  if (needed > available)
    ThrowBadInput("'{}': the board needs {} markers but {} has {}", source, needed, c.dictionary, available);
  return dict;
}

}  // namespace

Board MakeCharucoBoard(const CharucoDefinition& c, const std::string& source) {
  const int dict = CheckCharuco(c, source);
  const cv::Ptr<cv::aruco::CharucoBoard> cb = cv::aruco::CharucoBoard::create(
      c.squares_x, c.squares_y, static_cast<float>(c.square_mm), static_cast<float>(c.marker_mm),
      cv::aruco::getPredefinedDictionary(static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(dict)));
  BTF_CHECK(static_cast<long>(cb->ids.size()) == c.squares_x * static_cast<long>(c.squares_y) / 2);
  Board b;
  b.family = "aruco:" + c.dictionary;
  b.sample_size_mm = 0;
  b.charuco = c;
  // OpenCV's board frame: x right, y down the printed board, corners TL, TR, BR, BL of each marker.
  // Ours: y up, origin at the board's centre, corners LB, RB, RT, LT.
  const double cx = 0.5 * c.squares_x * c.square_mm, cy = 0.5 * c.squares_y * c.square_mm;
  for (std::size_t i = 0; i < cb->ids.size(); ++i) {
    Marker m;
    m.id = cb->ids[i];
    const auto& o = cb->objPoints[i];
    const int from[4] = {3, 2, 1, 0};
    for (int k = 0; k < 4; ++k) m.corners_mm[k] = Vec2(o[static_cast<std::size_t>(from[k])].x - cx, cy - o[static_cast<std::size_t>(from[k])].y);
    b.markers.push_back(m);
  }
  b.Check(source);
  return b;
}

std::vector<Vec2> CharucoCornersMm(const CharucoDefinition& c) {
  MakeCharucoBoard(c, "ChArUco definition");  // validates c and the dictionary
  const cv::Ptr<cv::aruco::CharucoBoard> cb = cv::aruco::CharucoBoard::create(
      c.squares_x, c.squares_y, static_cast<float>(c.square_mm), static_cast<float>(c.marker_mm),
      cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50));  // the corners do not depend on the dictionary
  const double cx = 0.5 * c.squares_x * c.square_mm, cy = 0.5 * c.squares_y * c.square_mm;
  std::vector<Vec2> out;
  for (const auto& p : cb->chessboardCorners) out.emplace_back(p.x - cx, cy - p.y);  // as the markers above
  return out;
}

std::vector<std::uint8_t> ArucoMarkerModules(const std::string& dictionary, int id, int border_bits, int* side) {
  const cv::Ptr<cv::aruco::Dictionary> d = cv::aruco::getPredefinedDictionary(
      static_cast<cv::aruco::PREDEFINED_DICTIONARY_NAME>(CharucoDictionary(dictionary, "ArUco marker")));
  if (id < 0 || id >= d->bytesList.rows) ThrowUsage("marker id {} is outside {} (0..{})", id, dictionary, d->bytesList.rows - 1);
  if (border_bits < 1 || border_bits > 2) ThrowUsage("invalid option 'border_bits': {} (1 or 2)", border_bits);
  *side = d->markerSize + 2 * border_bits;
  cv::Mat img;
  cv::aruco::drawMarker(d, id, *side, img, border_bits);  // one pixel per module
  std::vector<std::uint8_t> out(static_cast<std::size_t>(*side) * *side);
  for (int r = 0; r < *side; ++r)
    for (int c = 0; c < *side; ++c) out[static_cast<std::size_t>(r * *side + c)] = img.at<unsigned char>(r, c) > 127;
  return out;
}

namespace {

// OpenCV 4.6's YAML parser is not safe on arbitrary text: it recurses once per nesting level
// without a bound (a file nested 40,000 levels deep overflowed the stack) and loops forever on
// some short inputs with tags (found by fuzz_rig). A Kalibr target is one flat mapping of scalars,
// so only that reaches the parser: every line is blank, a comment, "---", or `key: value` at
// column 0 with a key of letters, digits and '_' and a value that is empty, quoted on the line, or
// plain without brackets, braces, commas or a leading tag, anchor, alias or block indicator;
// printable ASCII only. Nothing nests, so the parser's depth is 1.
void CheckFlatYaml(const std::string& text, const std::filesystem::path& path) {
  std::size_t line_start = 0;
  for (int line = 1; line_start < text.size(); ++line) {
    std::size_t end = text.find('\n', line_start);
    if (end == std::string::npos) end = text.size();
    std::string l = text.substr(line_start, end - line_start);
    line_start = end + 1;
    if (!l.empty() && l.back() == '\r') l.pop_back();
    const auto fail = [&](const std::string& what) {
      ThrowBadInput("'{}': line {} {}: a Kalibr target is one flat mapping of 'key: value' lines (no nesting, lists, "
                    "tags or anchors)",
                    path.string(), line, what);
    };
    for (const char ch : l)
      if (!(ch == '\t' || (ch >= 0x20 && ch < 0x7f))) fail("holds a byte that is not printable ASCII");
    const std::size_t first = l.find_first_not_of(" \t");
    if (first == std::string::npos || l[first] == '#' || l == "---") continue;
    if (first > 0) fail("is indented (a nested block)");
    std::size_t i = 0;
    while (i < l.size() && (std::isalnum(static_cast<unsigned char>(l[i])) || l[i] == '_')) ++i;
    if (i == 0 || i >= l.size() || l[i] != ':' || (i + 1 < l.size() && l[i + 1] != ' ' && l[i + 1] != '\t'))
      fail("is not 'key: value'");
    i = l.find_first_not_of(" \t", i + 1);
    if (i == std::string::npos || l[i] == '#') continue;  // an empty value
    if (l[i] == '\'' || l[i] == '"') {
      const char q = l[i];
      for (++i; i < l.size() && l[i] != q; ++i)
        if (q == '"' && l[i] == '\\') ++i;
      if (i >= l.size()) fail("has a quoted value that does not end on the line");
      i = l.find_first_not_of(" \t", i + 1);
      if (i != std::string::npos && l[i] != '#') fail("has text after its quoted value");
      continue;
    }
    if (std::strchr("!&*|>%@`?-", l[i]) && !(l[i] == '-' && i + 1 < l.size() && l[i + 1] != ' ' && l[i + 1] != '\t'))
      fail(fmt::format("has a value starting with '{}' (a tag, anchor, alias, block or list)", l[i]));
    std::size_t comment = l.find(" #", i);
    comment = std::min(comment, l.find("\t#", i));
    if (l.substr(i, comment == std::string::npos ? std::string::npos : comment - i).find_first_of("[]{},") !=
        std::string::npos)
      fail("has a flow collection ([ ] { } ,) in its value");
  }
}

Board KalibrTargetFromYaml(const cv::FileStorage& fs, const std::filesystem::path& path);

// Kalibr's target YAML through OpenCV's FileStorage (which wants a %YAML:1.0 directive first).
Board ReadKalibrTarget(const std::filesystem::path& path) {
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(path, ec);
  if (!ec && bytes > kMaxBoardYamlBytes)
    ThrowBadInput("'{}' is {} bytes; a Kalibr target file is a few lines (at most {} bytes are read)", path.string(),
                  bytes, kMaxBoardYamlBytes);
  std::ifstream in(path);
  if (!in) ThrowIo("cannot open '{}': check that the file exists and is readable", path.string());
  std::stringstream text;
  text << in.rdbuf();
  CheckFlatYaml(text.str(), path);
  cv::FileStorage fs;
  try {
    fs.open("%YAML:1.0\n" + text.str(), cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
  } catch (const cv::Exception& e) {
    ThrowBadInput("'{}': not valid YAML ({}; line numbers count one extra line)", path.string(), e.err);
  }
  if (!fs.isOpened()) ThrowBadInput("'{}': not valid YAML", path.string());
  // OpenCV asserts (cv::Exception) where a top level is not a mapping (found by fuzz_rig).
  try {
    if (!fs.root().isMap())
      ThrowBadInput("'{}': not a Kalibr target: the top level must be a mapping of fields (target_type: ...)",
                    path.string());
    return KalibrTargetFromYaml(fs, path);
  } catch (const cv::Exception& e) {
    ThrowBadInput("'{}': not a Kalibr target: every YAML document must be a mapping of fields ({})", path.string(),
                  e.err);
  }
}

// The fields of a parsed Kalibr target (ReadKalibrTarget).
Board KalibrTargetFromYaml(const cv::FileStorage& fs, const std::filesystem::path& path) {
  const auto field = [&](const char* key) {
    const cv::FileNode n = fs[key];
    if (n.empty()) ThrowBadInput("'{}': missing required field '{}'", path.string(), key);
    return n;
  };
  const auto number = [&](const char* key) {
    const cv::FileNode n = field(key);
    if (!n.isReal() && !n.isInt()) ThrowBadInput("'{}': field '{}' must be a number", path.string(), key);
    const double v = static_cast<double>(n);
    if (!std::isfinite(v)) ThrowBadInput("'{}': field '{}' must be finite", path.string(), key);
    return v;
  };
  const auto integer = [&](const char* key) {
    const cv::FileNode n = field(key);
    if (!n.isInt()) ThrowBadInput("'{}': field '{}' must be an integer", path.string(), key);
    return static_cast<int>(n);
  };
  const cv::FileNode type = field("target_type");
  if (!type.isString()) ThrowBadInput("'{}': field 'target_type' must be a string", path.string());
  const std::string t = static_cast<std::string>(type);
  if (t == "charuco") {
    const cv::FileNode dn = field("dictionary");
    if (!dn.isString()) ThrowBadInput("'{}': field 'dictionary' must be a string (e.g. DICT_5X5_100)", path.string());
    CharucoDefinition c;
    c.squares_x = integer("squaresX");
    c.squares_y = integer("squaresY");
    c.square_mm = 1000 * number("squareSize");
    c.marker_mm = 1000 * number("markerSize");
    c.dictionary = static_cast<std::string>(dn);
    return MakeCharucoBoard(c, path.string());
  }
  if (t != "aprilgrid")
    ThrowBadInput("'{}': field 'target_type' is '{}': 'aprilgrid' (Kalibr) or 'charuco' are supported "
                  "(checkerboard and circlegrid have no ids)",
                  path.string(), t);
  AprilGrid g;
  g.rows = integer("tagRows");
  g.cols = integer("tagCols");
  g.tag_size_mm = 1000 * number("tagSize");
  g.spacing = number("tagSpacing");
  if (g.rows < 1 || g.cols < 1 || g.rows * static_cast<long>(g.cols) > 100000)
    ThrowBadInput("'{}': fields 'tagRows' and 'tagCols' must be 1..100000 tags in all, found {} x {}", path.string(),
                  g.rows, g.cols);
  if (!(g.tag_size_mm > 0)) ThrowBadInput("'{}': field 'tagSize' must be > 0 (metres)", path.string());
  if (!(g.spacing > 0 && g.spacing < 10)) ThrowBadInput("'{}': field 'tagSpacing' must be in (0, 10) (gap / tag size)", path.string());
  if (!(0.5 * std::max(g.rows, g.cols) * g.tag_size_mm * (1 + g.spacing) <= kMaxBoardMm))
    ThrowBadInput("'{}': fields 'tagSize' ({:g} m) and 'tagSpacing' give a grid reaching past +-{:g} mm of its centre",
                  path.string(), g.tag_size_mm / 1000, kMaxBoardMm);
  // Optional extensions (not Kalibr's): the family and border (Kalibr: tag36h11, 2 bits).
  std::string family = "tag36h11";
  int border = 2;
  if (!fs["tagFamily"].empty()) family = static_cast<std::string>(fs["tagFamily"]);
  if (!fs["borderBits"].empty()) border = integer("borderBits");
  if (!fs["firstId"].empty()) g.first_id = integer("firstId");
  if (border < 1 || border > 2) ThrowBadInput("'{}': field 'borderBits' must be 1 or 2", path.string());
  Board b = MakeAprilGridBoard(g, family, border);
  b.Check(path.string());
  return b;
}

}  // namespace

Board ReadBoard(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  for (auto& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  if (ext == ".yaml" || ext == ".yml") return ReadKalibrTarget(path);
  const json j = LoadJson(path);
  const Node root(&path, &j, "");
  CheckHeader(root, kBoardFormat);
  Board b;
  b.family = root["family"].String();
  b.sample_size_mm = root["sample_size_mm"].Double();
  if (root.Has("border_bits")) b.border_bits = root["border_bits"].Int();
  if (root.Has("charuco")) {
    const Node c = root["charuco"];
    b.charuco.squares_x = c["squares_x"].Int();
    b.charuco.squares_y = c["squares_y"].Int();
    b.charuco.square_mm = c["square_mm"].Double();
    b.charuco.marker_mm = c["marker_mm"].Double();
    b.charuco.dictionary = c["dictionary"].String();
    CheckCharuco(b.charuco, path.string(), /*json=*/true);
  }
  if (root.Has("aprilgrid")) {
    const Node g = root["aprilgrid"];
    b.grid.rows = g["rows"].Int();
    b.grid.cols = g["cols"].Int();
    b.grid.tag_size_mm = g["tag_size_mm"].Double();
    b.grid.spacing = g["spacing"].Double();
    b.grid.first_id = g.Has("first_id") ? g["first_id"].Int() : 0;
    if (!b.grid.valid() || !(b.grid.tag_size_mm > 0) || !(b.grid.spacing > 0)) g.Fail("rows, cols, tag_size_mm and spacing must be > 0");
    if (b.grid.rows * static_cast<long>(b.grid.cols) > 100000 ||
        !(0.5 * std::max(b.grid.rows, b.grid.cols) * b.grid.tag_size_mm * (1 + b.grid.spacing) <= kMaxBoardMm))
      g.Fail(fmt::format("rows x cols must be at most 100000 tags and the grid must lie within +-{:g} mm of its centre",
                         kMaxBoardMm));
  }
  const Node ms = root["markers"];
  const std::size_t n = ms.ArraySize();
  for (std::size_t i = 0; i < n; ++i) {
    const Node m = ms.At(i);
    Marker mk;
    mk.id = m["id"].Int();
    const Node c = m["corners_mm"];
    c.ArraySize(4);
    for (int k = 0; k < 4; ++k) mk.corners_mm[k] = c.At(static_cast<std::size_t>(k)).Vector2();
    mk.height_mm = m.Has("height_mm") ? m["height_mm"].Double() : 0.0;
    b.markers.push_back(mk);
  }
  b.Check(path.string());
  return b;
}

void WriteBoard(const std::filesystem::path& path, const Board& board) {
  board.Check(path.string());
  json j = Header(kBoardFormat);
  j["family"] = board.family;
  j["units"] = "mm";
  j["corner_order"] = "left-bottom, right-bottom, right-top, left-top of the upright tag (AprilTag order)";
  j["sample_size_mm"] = board.sample_size_mm;
  if (board.border_bits != 1) j["border_bits"] = board.border_bits;  // written only when not the default
  if (board.charuco.valid())
    j["charuco"] = json{{"squares_x", board.charuco.squares_x},
                        {"squares_y", board.charuco.squares_y},
                        {"square_mm", board.charuco.square_mm},
                        {"marker_mm", board.charuco.marker_mm},
                        {"dictionary", board.charuco.dictionary}};
  if (board.grid.valid())
    j["aprilgrid"] = json{{"rows", board.grid.rows},
                          {"cols", board.grid.cols},
                          {"tag_size_mm", board.grid.tag_size_mm},
                          {"spacing", board.grid.spacing},
                          {"first_id", board.grid.first_id}};
  json ms = json::array();
  for (const auto& m : board.markers) {
    json jm;
    jm["id"] = m.id;
    jm["corners_mm"] = json::array();
    for (const auto& c : m.corners_mm) jm["corners_mm"].push_back(ToJson(c));
    jm["height_mm"] = m.height_mm;
    ms.push_back(jm);
  }
  j["markers"] = ms;
  WriteJsonAtomic(path, j);
}

namespace {
CameraModel CameraFromJson(const Node& n) {
  CameraModel c;
  c.width = n["width"].Int();
  c.height = n["height"].Int();
  if (c.width < 1 || c.height < 1) n.Fail("width and height must be >= 1");
  c.fx = n["fx"].Double();
  c.fy = n["fy"].Double();
  if (!(c.fx > 0 && c.fy > 0)) n.Fail("fx and fy must be > 0");
  c.cx = n["cx"].Double();
  c.cy = n["cy"].Double();
  c.model = n.Has("model") ? n["model"].String() : "radtan";
  if (c.model != "radtan" && c.model != "fisheye") n["model"].Fail("must be 'radtan' or 'fisheye'");
  c.k1 = n.Has("k1") ? n["k1"].Double() : 0.0;
  c.k2 = n.Has("k2") ? n["k2"].Double() : 0.0;
  c.k3 = n.Has("k3") ? n["k3"].Double() : 0.0;
  if (c.fisheye()) {
    c.k4 = n.Has("k4") ? n["k4"].Double() : 0.0;
  } else {
    c.p1 = n.Has("p1") ? n["p1"].Double() : 0.0;
    c.p2 = n.Has("p2") ? n["p2"].Double() : 0.0;
  }
  return c;
}
json CameraToJson(const CameraModel& c) {
  json j{{"width", c.width}, {"height", c.height}, {"fx", c.fx}, {"fy", c.fy},
         {"cx", c.cx},       {"cy", c.cy},         {"k1", c.k1}, {"k2", c.k2}};
  if (c.fisheye())
    j["model"] = c.model, j["k3"] = c.k3, j["k4"] = c.k4;  // radtan (no "model") as before
  else if (c.has_extended_distortion())
    j["p1"] = c.p1, j["p2"] = c.p2, j["k3"] = c.k3;  // only when used
  return j;
}
}  // namespace

CameraFile ReadCameraFile(const std::filesystem::path& path) {
  const json j = LoadJson(path);
  const Node root(&path, &j, "");
  CameraFile f;
  CameraModel& c = f.camera;
  c.model = root.Has("model") ? root["model"].String() : "radtan";
  if (c.model != "radtan" && c.model != "fisheye") root["model"].Fail("must be 'radtan' or 'fisheye'");
  const Node size = root["image_size"];
  size.ArraySize(2);
  c.width = size.At(0).Int();
  c.height = size.At(1).Int();
  if (c.width < 1 || c.height < 1) size.Fail("width and height must be >= 1");
  c.fx = root["fx"].Double();
  c.fy = root["fy"].Double();
  if (!(c.fx > 0 && c.fy > 0)) root.Fail("fx and fy must be > 0");
  c.cx = root["cx"].Double();
  c.cy = root["cy"].Double();
  c.k1 = root["k1"].Double();
  c.k2 = root["k2"].Double();
  c.k3 = root["k3"].Double();
  if (c.fisheye()) {
    c.k4 = root["k4"].Double();
  } else {
    c.p1 = root["p1"].Double();
    c.p2 = root["p2"].Double();
  }
  f.rms_px = root.Has("rms_px") ? root["rms_px"].Double() : 0.0;
  return f;
}

void WriteCameraFile(const std::filesystem::path& path, const CameraFile& f, const nlohmann::json& extra) {
  const CameraModel& c = f.camera;
  json j = Header("libbtf-camera");
  j["model"] = c.model;
  j["convention"] = "OpenCV: pixel centres at integer coordinates, (0,0) = centre of the top-left pixel";
  j["image_size"] = json::array({c.width, c.height});
  j["fx"] = c.fx, j["fy"] = c.fy, j["cx"] = c.cx, j["cy"] = c.cy;
  if (c.fisheye())
    j["k1"] = c.k1, j["k2"] = c.k2, j["k3"] = c.k3, j["k4"] = c.k4;
  else
    j["k1"] = c.k1, j["k2"] = c.k2, j["p1"] = c.p1, j["p2"] = c.p2, j["k3"] = c.k3;
  j["rms_px"] = f.rms_px;
  if (extra.is_object())
    for (const auto& [k, v] : extra.items()) j[k] = v;
  WriteJsonAtomic(path, j);
}

std::vector<std::filesystem::path> ManifestFiles(const Manifest& manifest, const std::filesystem::path& manifest_path) {
  const std::filesystem::path dir = manifest_path.parent_path();
  std::vector<std::filesystem::path> files;
  for (const std::string* f : {&manifest.board_file, &manifest.dark_frame, &manifest.flat_field})
    if (!f->empty()) files.push_back(dir / *f);
  for (const PhotoEntry& p : manifest.photos) {
    files.push_back(dir / p.file);
    for (const BracketExposure& b : p.brackets) files.push_back(dir / b.file);
  }
  return files;
}

Manifest ReadManifest(const std::filesystem::path& path) {
  const json j = LoadJson(path);
  const Node root(&path, &j, "");
  CheckHeader(root, kManifestFormat);
  Manifest m;
  m.board_file = root["board"].String();
  if (m.board_file.empty()) root["board"].Fail("must name the board file");
  m.views = SamplingFromJson(root["views"]);
  m.lights = SamplingFromJson(root["lights"]);
  m.bit_depth = root["bit_depth"].Int();
  if (m.bit_depth != 0 && m.bit_depth != 8 && m.bit_depth != 16) root["bit_depth"].Fail("must be 0 (float), 8 or 16");
  if (root.Has("transfer")) {
    m.transfer = root["transfer"].String();
    if (m.transfer != "linear" && m.transfer != "srgb") root["transfer"].Fail("must be 'linear' or 'srgb'");
  }
  for (const auto& [key, field] : {std::pair{"dark_frame", &m.dark_frame}, std::pair{"flat_field", &m.flat_field}})
    if (root.Has(key)) {
      *field = root[key].String();
      if (field->empty()) root[key].Fail("must name a photo file (or be left out)");
    }
  if (root.Has("extra")) m.extra = root["extra"].raw();
  const Node ps = root["photos"];
  const std::size_t n = ps.ArraySize();
  for (std::size_t i = 0; i < n; ++i) {
    const Node p = ps.At(i);
    PhotoEntry e;
    if (p.Has("brackets")) {  // several exposures of this (view, light): file and exposure per exposure
      const Node bs = p["brackets"];
      const std::size_t nb = bs.ArraySize();
      if (nb < 2) bs.Fail(fmt::format("lists {} exposure(s): a bracket needs at least 2 (else give file and exposure)", nb));
      for (std::size_t b = 0; b < nb; ++b) {
        const Node x = bs.At(b);
        BracketExposure be;
        be.file = x["file"].String();
        if (be.file.empty()) x["file"].Fail("must name the photo file");
        be.exposure = x["exposure"].Double();
        if (!(be.exposure > 0)) x["exposure"].Fail("must be > 0");
        e.brackets.push_back(be);
      }
      e.file = e.brackets[0].file;
      e.exposure = e.brackets[0].exposure;
    } else {
      e.file = p["file"].String();
      if (e.file.empty()) p["file"].Fail("must name the photo file");
      e.exposure = p["exposure"].Double();
      if (!(e.exposure > 0)) p["exposure"].Fail("must be > 0");
    }
    e.view_index = p["view_index"].Int();
    e.light_index = p["light_index"].Int();
    if (e.view_index < 0 || e.view_index >= m.views.size())
      p["view_index"].Fail(fmt::format("{} is outside the view sampling (0..{})", e.view_index, m.views.size() - 1));
    if (e.light_index < 0 || e.light_index >= m.lights.size())
      p["light_index"].Fail(fmt::format("{} is outside the light sampling (0..{})", e.light_index, m.lights.size() - 1));
    e.view_dir = p["view_dir"].UnitVector();
    e.light_dir = p["light_dir"].UnitVector();
    e.light_intensity = p["light_intensity"].Double();
    if (!(e.light_intensity > 0)) p["light_intensity"].Fail("must be > 0");
    e.light_distance_mm = p.Has("light_distance_mm") ? p["light_distance_mm"].Double() : 0.0;
    if (e.light_distance_mm < 0) p["light_distance_mm"].Fail("must be >= 0 (0 = directional light)");
    e.camera_distance_mm = p.Has("camera_distance_mm") ? p["camera_distance_mm"].Double() : 0.0;
    if (e.camera_distance_mm < 0) p["camera_distance_mm"].Fail("must be >= 0");
    e.camera = CameraFromJson(p["camera"]);
    m.photos.push_back(std::move(e));
  }
  return m;
}

void WriteManifest(const std::filesystem::path& path, const Manifest& m) {
  json j = Header(kManifestFormat);
  j["board"] = m.board_file;
  j["views"] = SamplingToJson(m.views);
  j["lights"] = SamplingToJson(m.lights);
  j["bit_depth"] = m.bit_depth;
  if (!m.transfer.empty()) j["transfer"] = m.transfer;
  if (!m.dark_frame.empty()) j["dark_frame"] = m.dark_frame;
  if (!m.flat_field.empty()) j["flat_field"] = m.flat_field;
  j["pixel_value"] = "exposure * radiance; radiance = BTF(1/sr) * irradiance";
  json ps = json::array();
  for (const auto& e : m.photos) {
    json jp{{"view_index", e.view_index},
            {"light_index", e.light_index},
            {"view_dir", ToJson(e.view_dir)},
            {"light_dir", ToJson(e.light_dir)},
            {"light_intensity", e.light_intensity},
            {"light_distance_mm", e.light_distance_mm},
            {"camera_distance_mm", e.camera_distance_mm},
            {"camera", CameraToJson(e.camera)}};
    if (e.brackets.empty()) {
      jp["file"] = e.file;
      jp["exposure"] = e.exposure;
    } else {
      jp["brackets"] = json::array();
      for (const auto& b : e.brackets) jp["brackets"].push_back(json{{"file", b.file}, {"exposure", b.exposure}});
    }
    ps.push_back(jp);
  }
  j["photos"] = ps;
  j["extra"] = m.extra;
  WriteJsonAtomic(path, j);
}

std::vector<PhotoTruth> ReadTruth(const std::filesystem::path& path) {
  const json j = LoadJson(path);
  const Node root(&path, &j, "");
  CheckHeader(root, kTruthFormat);
  const Node ps = root["photos"];
  const std::size_t n = ps.ArraySize();
  std::vector<PhotoTruth> out;
  for (std::size_t i = 0; i < n; ++i) {
    const Node p = ps.At(i);
    PhotoTruth t;
    t.file = p["file"].String();
    t.image_from_plate = p["plate_to_image"].Matrix3();
    t.camera_from_plate_rotation = p["rotation"].Matrix3();
    t.camera_from_plate_translation = p["translation"].Vector3();
    const Node ms = p["markers"];
    const std::size_t nm = ms.ArraySize();
    for (std::size_t k = 0; k < nm; ++k) {
      const Node mk = ms.At(k);
      const int id = mk["id"].Int();
      const Node c = mk["corners_px"];
      c.ArraySize(4);
      std::array<Vec2, 4> corners;
      for (int q = 0; q < 4; ++q) corners[q] = c.At(static_cast<std::size_t>(q)).Vector2();
      if (!t.marker_corners_px.emplace(id, corners).second) mk["id"].Fail(fmt::format("duplicate marker id {}", id));
    }
    if (p.Has("charuco_corners")) {
      const Node cs = p["charuco_corners"];
      const std::size_t nc = cs.ArraySize();
      for (std::size_t k = 0; k < nc; ++k) {
        const Node ck = cs.At(k);
        const int id = ck["id"].Int();
        if (!t.charuco_corners_px.emplace(id, ck["pixel_px"].Vector2()).second)
          ck["id"].Fail(fmt::format("duplicate corner id {}", id));
      }
    }
    out.push_back(std::move(t));
  }
  return out;
}

void WriteTruth(const std::filesystem::path& path, const std::vector<PhotoTruth>& truth) {
  json j = Header(kTruthFormat);
  j["conventions"] =
      "plate_to_image maps plate mm (x, y, 1) on the material surface z = 0 to pixels (OpenCV: (0,0) = centre "
      "of the top-left pixel); rotation/translation: camera_from_plate (OpenCV camera: x right, y down, z "
      "forward); corners in the board's order";
  json ps = json::array();
  for (const auto& t : truth) {
    json jm = json::array();
    for (const auto& [id, corners] : t.marker_corners_px) {
      json c = json::array();
      for (const auto& p : corners) c.push_back(ToJson(p));
      jm.push_back(json{{"id", id}, {"corners_px", c}});
    }
    json jp{{"file", t.file},
            {"plate_to_image", ToJson(t.image_from_plate)},
            {"rotation", ToJson(t.camera_from_plate_rotation)},
            {"translation", ToJson(t.camera_from_plate_translation)},
            {"markers", jm}};
    if (!t.charuco_corners_px.empty()) {
      json jc = json::array();
      for (const auto& [id, p] : t.charuco_corners_px) jc.push_back(json{{"id", id}, {"pixel_px", ToJson(p)}});
      jp["charuco_corners"] = jc;
    }
    ps.push_back(jp);
  }
  j["photos"] = ps;
  WriteJsonAtomic(path, j);
}

bool ProjectToPixel(const CameraModel& camera, const Eigen::Matrix3d& R, const Vec3& t, const Vec3& p, Vec2* pixel) {
  const Vec3 c = R * p + t;
  if (!(c.z() > 1e-9)) return false;
  const double x = c.x() / c.z(), y = c.y() / c.z();
  const double r2 = x * x + y * y;
  if (camera.fisheye()) {  // cv::fisheye::projectPoints, alpha = 0
    const double r = std::sqrt(r2), th = std::atan(r), t2 = th * th;
    const double thd = th * (1 + t2 * (camera.k1 + t2 * (camera.k2 + t2 * (camera.k3 + t2 * camera.k4))));
    const double s = r > 1e-8 ? thd / r : 1.0;
    *pixel = Vec2(camera.fx * x * s + camera.cx, camera.fy * y * s + camera.cy);
    return true;
  }
  if (camera.has_extended_distortion()) {  // OpenCV radtan; the branch keeps k1/k2-only results bit for bit
    const double f = 1 + camera.k1 * r2 + camera.k2 * r2 * r2 + camera.k3 * r2 * r2 * r2;
    const double xd = x * f + 2 * camera.p1 * x * y + camera.p2 * (r2 + 2 * x * x);
    const double yd = y * f + camera.p1 * (r2 + 2 * y * y) + 2 * camera.p2 * x * y;
    *pixel = Vec2(camera.fx * xd + camera.cx, camera.fy * yd + camera.cy);
    return true;
  }
  const double f = 1 + camera.k1 * r2 + camera.k2 * r2 * r2;
  *pixel = Vec2(camera.fx * x * f + camera.cx, camera.fy * y * f + camera.cy);
  return true;
}

bool UndistortNormalized(const CameraModel& camera, const Vec2& d, Vec2* ray) {
  if (camera.fisheye()) {
    const double thd = d.norm();
    if (!(thd > 1e-8)) {
      *ray = d;
      return std::isfinite(thd);
    }
    const double k1 = camera.k1, k2 = camera.k2, k3 = camera.k3, k4 = camera.k4;
    double th = std::min(thd, 1.5);  // Newton from theta = theta_d (OpenCV's start), inside (0, pi/2)
    for (int it = 0; it < 20; ++it) {
      const double t2 = th * th;
      const double f = th * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - thd;
      const double df = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)));
      if (!(df > 0)) return false;  // past the lens's fold: theta_d(theta) no longer increases
      const double step = f / df;
      th -= step;
      if (!(th > 0 && th < 0.5 * kPi)) return false;  // no ray in front of the camera maps here
      if (std::abs(step) < 1e-14) break;
    }
    const double t2 = th * th;
    if (std::abs(th * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - thd) > 1e-9) return false;
    *ray = d * (std::tan(th) / thd);
    return true;
  }
  double x = d.x(), y = d.y();
  if (!camera.has_extended_distortion()) {
    if (camera.k1 != 0 || camera.k2 != 0)
      for (int it = 0; it < 20; ++it) {
        const double r2 = x * x + y * y;
        const double s = 1 + camera.k1 * r2 + camera.k2 * r2 * r2;
        x = d.x() / s;
        y = d.y() / s;
      }
  } else {  // cv::undistortPoints' iteration
    for (int it = 0; it < 20; ++it) {
      const double r2 = x * x + y * y;
      const double icdist = 1 / (1 + ((camera.k3 * r2 + camera.k2) * r2 + camera.k1) * r2);
      const double dx = 2 * camera.p1 * x * y + camera.p2 * (r2 + 2 * x * x);
      const double dy = camera.p1 * (r2 + 2 * y * y) + 2 * camera.p2 * x * y;
      x = (d.x() - dx) * icdist;
      y = (d.y() - dy) * icdist;
    }
  }
  *ray = Vec2(x, y);
  return std::isfinite(x) && std::isfinite(y);
}

Eigen::Matrix3d PlaneHomography(const CameraModel& camera, const Eigen::Matrix3d& R, const Vec3& t, double plane_z) {
  Eigen::Matrix3d K;
  K << camera.fx, 0, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1;
  Eigen::Matrix3d M;
  // (x, y, z0) -> R (x, y, z0) + t = r1 x + r2 y + (t + z0 r3).
  M.col(0) = R.col(0);
  M.col(1) = R.col(1);
  M.col(2) = t + plane_z * R.col(2);
  Eigen::Matrix3d H = K * M;
  return H / H(2, 2);
}

}  // namespace btf
