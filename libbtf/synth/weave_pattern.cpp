#include "libbtf/synth/weave_pattern.h"

#include <cctype>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>

#include <fmt/format.h>

#include "libbtf/core/directions.h"
#include "libbtf/core/atomic_file.h"
#include "libbtf/core/error.h"

namespace btf {
namespace {

// ---------------------------------------------------------------------------------------------
// Tokenizer for the .wv text: identifiers, numbers, "strings", $variables, { } = , and /* */.
struct Token {
  enum Kind { kIdent, kNumber, kString, kVariable, kPunct, kEnd } kind = kEnd;
  std::string text;
  int line = 1;
};

class Lexer {
 public:
  Lexer(const std::string& text, const std::string& source) : s_(text), source_(source) {}

  Token Next() {
    SkipSpaceAndComments();
    Token t;
    t.line = line_;
    if (pos_ >= s_.size()) return t;
    const char c = s_[pos_];
    if (std::isalpha(static_cast<unsigned char>(c)) || c == '_') {
      t.kind = Token::kIdent;
      while (pos_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[pos_])) || s_[pos_] == '_')) t.text += s_[pos_++];
    } else if (c == '$') {
      t.kind = Token::kVariable;
      ++pos_;
      while (pos_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[pos_])) || s_[pos_] == '_')) t.text += s_[pos_++];
      if (t.text.empty()) Fail(t.line, "'$' must be followed by a variable name");
    } else if (std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '+' || c == '.') {
      t.kind = Token::kNumber;
      const char* begin = s_.c_str() + pos_;
      char* end = nullptr;
      std::strtod(begin, &end);
      if (end == begin) Fail(t.line, "malformed number near '{}'", s_.substr(pos_, 12));
      t.text.assign(begin, static_cast<std::size_t>(end - begin));
      pos_ += static_cast<std::size_t>(end - begin);
    } else if (c == '"') {
      t.kind = Token::kString;
      ++pos_;
      while (pos_ < s_.size() && s_[pos_] != '"') {
        if (s_[pos_] == '\n') ++line_;
        t.text += s_[pos_++];
      }
      if (pos_ >= s_.size()) Fail(t.line, "unterminated string");
      ++pos_;
    } else if (c == '{' || c == '}' || c == '=' || c == ',') {
      t.kind = Token::kPunct;
      t.text = std::string(1, c);
      ++pos_;
    } else {
      Fail(t.line, "unexpected character '{}'", std::string(1, c));
    }
    return t;
  }

  template <typename... Args>
  [[noreturn]] void Fail(int line, fmt::format_string<Args...> f, Args&&... args) const {
    ThrowBadInput("weave pattern {}:{}: {} (see docs/btf-synth.md for the .wv grammar)", source_, line,
                  fmt::format(f, std::forward<Args>(args)...));
  }

 private:
  void SkipSpaceAndComments() {
    while (pos_ < s_.size()) {
      const char c = s_[pos_];
      if (c == '\n') {
        ++line_;
        ++pos_;
      } else if (std::isspace(static_cast<unsigned char>(c))) {
        ++pos_;
      } else if (c == '/' && pos_ + 1 < s_.size() && s_[pos_ + 1] == '*') {
        const int start = line_;
        pos_ += 2;
        while (pos_ + 1 < s_.size() && !(s_[pos_] == '*' && s_[pos_ + 1] == '/')) {
          if (s_[pos_] == '\n') ++line_;
          ++pos_;
        }
        if (pos_ + 1 >= s_.size()) Fail(start, "unterminated comment");
        pos_ += 2;
      } else {
        break;
      }
    }
  }

  const std::string& s_;
  std::string source_;
  std::size_t pos_ = 0;
  int line_ = 1;
};

class Parser {
 public:
  Parser(const std::string& text, const std::string& source, const nlohmann::json& vars)
      : lex_(text, source), vars_(vars) {
    Advance();
  }

  WeavePattern Parse() {
    WeavePattern p;
    ExpectIdent("weave");
    Expect("{");
    ParseItems([&](const Token& key) { ParseWeaveItem(key, p); });
    if (cur_.kind != Token::kEnd) lex_.Fail(cur_.line, "unexpected '{}' after the end of 'weave {{ ... }}'", cur_.text);
    return p;
  }

 private:
  void Advance() { cur_ = lex_.Next(); }
  static std::string Describe(const Token& t) {
    return t.kind == Token::kEnd ? std::string("end of file") : "'" + t.text + "'";
  }
  void Expect(const char* punct) {
    if (cur_.kind != Token::kPunct || cur_.text != punct) lex_.Fail(cur_.line, "expected '{}', found {}", punct, Describe(cur_));
    Advance();
  }
  void ExpectIdent(const char* word) {
    if (cur_.kind != Token::kIdent || cur_.text != word) lex_.Fail(cur_.line, "expected '{}', found {}", word, Describe(cur_));
    Advance();
  }
  bool IsPunct(const char* p) const { return cur_.kind == Token::kPunct && cur_.text == p; }

  // `item (, item)* [,] }` : Mitsuba's grammar has no trailing comma, its writer emits one; accept both.
  template <typename F>
  void ParseItems(F&& item) {
    if (IsPunct("}")) lex_.Fail(cur_.line, "empty block");
    for (;;) {
      if (cur_.kind != Token::kIdent) lex_.Fail(cur_.line, "expected an item name, found {}", Describe(cur_));
      const Token key = cur_;
      Advance();
      item(key);
      if (IsPunct(",")) {
        Advance();
        if (IsPunct("}")) break;
        continue;
      }
      if (IsPunct("}")) break;
      lex_.Fail(cur_.line, "expected ',' or '}}' after '{}', found {}", key.text, Describe(cur_));
    }
    Advance();  // '}'
  }

  const nlohmann::json& Variable(const Token& t) {
    if (!vars_.is_object() || !vars_.contains(t.text))
      lex_.Fail(t.line, "variable '${}' is not defined (pass it in the model parameters under \"variables\")", t.text);
    return vars_.at(t.text);
  }

  double Float(const char* what) {
    const Token t = cur_;
    Advance();
    if (t.kind == Token::kNumber) return std::strtod(t.text.c_str(), nullptr);
    if (t.kind == Token::kVariable) {
      const auto& v = Variable(t);
      if (!v.is_number()) lex_.Fail(t.line, "variable '${}' used for '{}' must be a number", t.text, what);
      return v.get<double>();
    }
    lex_.Fail(t.line, "expected a number for '{}', found {}", what, Describe(t));
  }

  int Int(const char* what, int min_value) {
    const Token t = cur_;
    Advance();
    if (t.kind != Token::kNumber || t.text.find_first_of(".eE") != std::string::npos)
      lex_.Fail(t.line, "expected an integer for '{}', found {}", what, Describe(t));
    const long v = std::strtol(t.text.c_str(), nullptr, 10);
    if (v < min_value || v > 1000000) lex_.Fail(t.line, "'{}' = {} is out of range (>= {})", what, v, min_value);
    return static_cast<int>(v);
  }

  Rgb Color(const char* what) {
    if (cur_.kind == Token::kVariable) {
      const Token t = cur_;
      Advance();
      const auto& v = Variable(t);
      if (v.is_number()) return {v.get<double>(), v.get<double>(), v.get<double>()};
      if (v.is_array() && v.size() == 3 && v[0].is_number() && v[1].is_number() && v[2].is_number())
        return {v[0].get<double>(), v[1].get<double>(), v[2].get<double>()};
      lex_.Fail(t.line, "variable '${}' used for '{}' must be a number or [r, g, b]", t.text, what);
    }
    Rgb c{};
    Expect("{");
    for (int i = 0; i < 3; ++i) {
      c[static_cast<std::size_t>(i)] = Float(what);
      if (i < 2) Expect(",");
    }
    Expect("}");
    return c;
  }

  void ParseWeaveItem(const Token& key, WeavePattern& p) {
    const std::string& k = key.text;
    if (k == "yarn") {
      Expect("{");
      WeaveYarn y;
      ParseItems([&](const Token& yk) { ParseYarnItem(yk, y); });
      p.yarns.push_back(y);
      return;
    }
    if (k == "pattern") {
      Expect("{");
      p.pattern.clear();
      for (;;) {
        p.pattern.push_back(Int("pattern", 1));
        if (IsPunct(",")) {
          Advance();
          continue;
        }
        Expect("}");
        break;
      }
      return;
    }
    Expect("=");
    if (k == "name") {
      if (cur_.kind != Token::kString) lex_.Fail(cur_.line, "expected a quoted string for 'name', found {}", Describe(cur_));
      p.name = cur_.text;
      Advance();
    } else if (k == "tileWidth") {
      p.tile_width = Int("tileWidth", 1);
    } else if (k == "tileHeight") {
      p.tile_height = Int("tileHeight", 1);
    } else if (k == "alpha") {
      p.alpha = Float("alpha");
    } else if (k == "beta") {
      p.beta = Float("beta");
    } else if (k == "ss") {
      p.ss = Float("ss");
    } else if (k == "hWidth") {
      p.h_width = Float("hWidth");
    } else if (k == "warpArea") {
      p.warp_area = Float("warpArea");
    } else if (k == "weftArea") {
      p.weft_area = Float("weftArea");
    } else if (k == "fineness") {
      p.fineness = Float("fineness");
    } else if (k == "period") {
      p.period = Float("period");
    } else if (k == "dWarpUmaxOverDWarp") {
      p.d_warp_umax_over_d_warp = DegToRad(Float("dWarpUmaxOverDWarp"));
    } else if (k == "dWarpUmaxOverDWeft") {
      p.d_warp_umax_over_d_weft = DegToRad(Float("dWarpUmaxOverDWeft"));
    } else if (k == "dWeftUmaxOverDWarp") {
      p.d_weft_umax_over_d_warp = DegToRad(Float("dWeftUmaxOverDWarp"));
    } else if (k == "dWeftUmaxOverDWeft") {
      p.d_weft_umax_over_d_weft = DegToRad(Float("dWeftUmaxOverDWeft"));
    } else {
      lex_.Fail(key.line,
                "unknown weave item '{}' (known: name, tileWidth, tileHeight, alpha, beta, ss, hWidth, warpArea, "
                "weftArea, dWarpUmaxOverDWarp, dWarpUmaxOverDWeft, dWeftUmaxOverDWarp, dWeftUmaxOverDWeft, "
                "fineness, period, pattern, yarn)",
                k);
    }
  }

  void ParseYarnItem(const Token& key, WeaveYarn& y) {
    const std::string& k = key.text;
    Expect("=");
    if (k == "type") {
      if (cur_.kind == Token::kIdent && (cur_.text == "warp" || cur_.text == "weft")) {
        y.type = cur_.text == "warp" ? WeaveYarn::Type::kWarp : WeaveYarn::Type::kWeft;
        Advance();
      } else {
        lex_.Fail(cur_.line, "yarn type must be 'warp' or 'weft', found {}", Describe(cur_));
      }
    } else if (k == "psi") {
      y.psi = DegToRad(Float("psi"));
    } else if (k == "umax") {
      y.umax = DegToRad(Float("umax"));
    } else if (k == "kappa") {
      y.kappa = Float("kappa");
    } else if (k == "width") {
      y.width = Float("width");
    } else if (k == "length") {
      y.length = Float("length");
    } else if (k == "centerU") {
      y.center_u = Float("centerU");
    } else if (k == "centerV") {
      y.center_v = Float("centerV");
    } else if (k == "kd") {
      y.kd = Color("kd");
    } else if (k == "ks") {
      y.ks = Color("ks");
    } else if (k == "alpha") {
      y.alpha = Float("alpha");
    } else if (k == "beta") {
      y.beta = Float("beta");
    } else if (k == "ss") {
      y.ss = Float("ss");
    } else {
      lex_.Fail(key.line,
                "unknown yarn item '{}' (known: type, psi, umax, kappa, width, length, centerU, centerV, kd, ks; "
                "libbtf extension: alpha, beta, ss)",
                k);
    }
  }

  Lexer lex_;
  const nlohmann::json& vars_;
  Token cur_;
};

std::string Num(double v) { return fmt::format("{:.17g}", v); }
std::string Col(const Rgb& c) { return fmt::format("{{{}, {}, {}}}", Num(c[0]), Num(c[1]), Num(c[2])); }

// ---------------------------------------------------------------------------------------------
// Presets. The six Mitsuba/Lux fabrics are kept as .wv text (values from the Lux/LuxCore preset
// tables, as docs/btf-synth.md lists them); their colors are our choice (no published RGB).
struct PresetText {
  const char* name;
  const char* text;
};

const PresetText kTextPresets[] = {
    {"cotton_denim", R"(weave {
  name = "cotton denim", tileWidth = 3, tileHeight = 6,
  alpha = 0.01, beta = 4, ss = 0, hWidth = 0.5, warpArea = 5, weftArea = 1, fineness = 3,
  pattern { 1, 3, 8,  1, 3, 5,  1, 7, 5,  1, 4, 5,  6, 4, 5,  2, 4, 5 },
  /* warp: indigo-dyed; weft: undyed (our colours) */
  yarn { type = warp, psi = -30, umax = 12, kappa = 0, width = 1, length = 5, centerU = 0.1667, centerV = 0.75, kd = {0.06, 0.09, 0.25}, ks = {0.08, 0.08, 0.1} },
  yarn { type = warp, psi = -30, umax = 12, kappa = 0, width = 1, length = 5, centerU = 0.1667, centerV = -0.25, kd = {0.06, 0.09, 0.25}, ks = {0.08, 0.08, 0.1} },
  yarn { type = warp, psi = -30, umax = 12, kappa = 0, width = 1, length = 5, centerU = 0.5, centerV = 1.0833, kd = {0.06, 0.09, 0.25}, ks = {0.08, 0.08, 0.1} },
  yarn { type = warp, psi = -30, umax = 12, kappa = 0, width = 1, length = 5, centerU = 0.5, centerV = 0.0833, kd = {0.06, 0.09, 0.25}, ks = {0.08, 0.08, 0.1} },
  yarn { type = warp, psi = -30, umax = 12, kappa = 0, width = 1, length = 5, centerU = 0.8333, centerV = 0.4167, kd = {0.06, 0.09, 0.25}, ks = {0.08, 0.08, 0.1} },
  yarn { type = weft, psi = -30, umax = 38, kappa = 0, width = 1, length = 1, centerU = 0.1667, centerV = 0.25, kd = {0.6, 0.58, 0.52}, ks = {0.05, 0.05, 0.05} },
  yarn { type = weft, psi = -30, umax = 38, kappa = 0, width = 1, length = 1, centerU = 0.5, centerV = 0.5833, kd = {0.6, 0.58, 0.52}, ks = {0.05, 0.05, 0.05} },
  yarn { type = weft, psi = -30, umax = 38, kappa = 0, width = 1, length = 1, centerU = 0.8333, centerV = 0.9167, kd = {0.6, 0.58, 0.52}, ks = {0.05, 0.05, 0.05} }
})"},
    {"polyester_lining", R"(weave {
  name = "polyester lining cloth", tileWidth = 2, tileHeight = 2,
  alpha = 0.015, beta = 4, ss = 0.5, hWidth = 0.5, warpArea = 1, weftArea = 1,
  dWarpUmaxOverDWarp = 8, dWarpUmaxOverDWeft = 8, dWeftUmaxOverDWarp = 6, dWeftUmaxOverDWeft = 6, period = 50,
  pattern { 3, 2,  1, 4 },
  /* beige lining (our colours) */
  yarn { type = warp, umax = 22, kappa = -0.7, width = 1, length = 1, centerU = 0.25, centerV = 0.25, kd = {0.5, 0.45, 0.38}, ks = {0.3, 0.3, 0.3} },
  yarn { type = warp, umax = 22, kappa = -0.7, width = 1, length = 1, centerU = 0.75, centerV = 0.75, kd = {0.5, 0.45, 0.38}, ks = {0.3, 0.3, 0.3} },
  yarn { type = weft, umax = 16, kappa = -0.7, width = 1, length = 1, centerU = 0.25, centerV = 0.75, kd = {0.5, 0.45, 0.38}, ks = {0.3, 0.3, 0.3} },
  yarn { type = weft, umax = 16, kappa = -0.7, width = 1, length = 1, centerU = 0.75, centerV = 0.25, kd = {0.5, 0.45, 0.38}, ks = {0.3, 0.3, 0.3} }
})"},
    {"silk_charmeuse", R"(weave {
  name = "silk charmeuse", tileWidth = 5, tileHeight = 10,
  alpha = 0.02, beta = 7.3, ss = 0.5, hWidth = 0.5, warpArea = 9, weftArea = 1, fineness = 3,
  pattern { 10, 2, 4, 6, 8,  1, 2, 4, 6, 8,  1, 2, 4, 13, 8,  1, 2, 4, 7, 8,  1, 11, 4, 7, 8,
            1, 3, 4, 7, 8,  1, 3, 4, 7, 14,  1, 3, 4, 7, 9,  1, 3, 12, 7, 9,  1, 3, 5, 7, 9 },
  /* deep red silk (our colours) */
  yarn { type = warp, umax = 40, kappa = 2, width = 1, length = 9, centerU = 0.1, centerV = 0.45, kd = {0.25, 0.02, 0.05}, ks = {0.6, 0.6, 0.6} },
  yarn { type = warp, umax = 40, kappa = 2, width = 1, length = 9, centerU = 0.3, centerV = 1.05, kd = {0.25, 0.02, 0.05}, ks = {0.6, 0.6, 0.6} },
  yarn { type = warp, umax = 40, kappa = 2, width = 1, length = 9, centerU = 0.3, centerV = 0.05, kd = {0.25, 0.02, 0.05}, ks = {0.6, 0.6, 0.6} },
  yarn { type = warp, umax = 40, kappa = 2, width = 1, length = 9, centerU = 0.5, centerV = 0.65, kd = {0.25, 0.02, 0.05}, ks = {0.6, 0.6, 0.6} },
  yarn { type = warp, umax = 40, kappa = 2, width = 1, length = 9, centerU = 0.5, centerV = -0.35, kd = {0.25, 0.02, 0.05}, ks = {0.6, 0.6, 0.6} },
  yarn { type = warp, umax = 40, kappa = 2, width = 1, length = 9, centerU = 0.7, centerV = 1.25, kd = {0.25, 0.02, 0.05}, ks = {0.6, 0.6, 0.6} },
  yarn { type = warp, umax = 40, kappa = 2, width = 1, length = 9, centerU = 0.7, centerV = 0.25, kd = {0.25, 0.02, 0.05}, ks = {0.6, 0.6, 0.6} },
  yarn { type = warp, umax = 40, kappa = 2, width = 1, length = 9, centerU = 0.9, centerV = 0.85, kd = {0.25, 0.02, 0.05}, ks = {0.6, 0.6, 0.6} },
  yarn { type = warp, umax = 40, kappa = 2, width = 1, length = 9, centerU = 0.9, centerV = -0.15, kd = {0.25, 0.02, 0.05}, ks = {0.6, 0.6, 0.6} },
  yarn { type = weft, umax = 60, kappa = 0, width = 1, length = 1, centerU = 0.1, centerV = 0.95, kd = {0.25, 0.02, 0.05}, ks = {0.3, 0.3, 0.3} },
  yarn { type = weft, umax = 60, kappa = 0, width = 1, length = 1, centerU = 0.3, centerV = 0.55, kd = {0.25, 0.02, 0.05}, ks = {0.3, 0.3, 0.3} },
  yarn { type = weft, umax = 60, kappa = 0, width = 1, length = 1, centerU = 0.5, centerV = 0.15, kd = {0.25, 0.02, 0.05}, ks = {0.3, 0.3, 0.3} },
  yarn { type = weft, umax = 60, kappa = 0, width = 1, length = 1, centerU = 0.7, centerV = 0.75, kd = {0.25, 0.02, 0.05}, ks = {0.3, 0.3, 0.3} },
  yarn { type = weft, umax = 60, kappa = 0, width = 1, length = 1, centerU = 0.9, centerV = 0.35, kd = {0.25, 0.02, 0.05}, ks = {0.3, 0.3, 0.3} }
})"},
    {"silk_shantung", R"(weave {
  name = "silk shantung", tileWidth = 6, tileHeight = 8,
  alpha = 0.02, beta = 1.5, ss = 0.5, hWidth = 0.5, warpArea = 8, weftArea = 16,
  dWarpUmaxOverDWarp = 20, dWarpUmaxOverDWeft = 20, dWeftUmaxOverDWarp = 10, dWeftUmaxOverDWeft = 10, period = 500,
  pattern { 3, 3, 3, 3, 2, 2,  3, 3, 3, 3, 2, 2,  3, 3, 3, 3, 2, 2,  3, 3, 3, 3, 2, 2,
            4, 1, 1, 5, 5, 5,  4, 1, 1, 5, 5, 5,  4, 1, 1, 5, 5, 5,  4, 1, 1, 5, 5, 5 },
  /* golden warp, copper weft: a "shot" silk (our colours) */
  yarn { type = warp, umax = 50, kappa = -0.5, width = 2, length = 4, centerU = 0.3333, centerV = 0.25, kd = {0.35, 0.25, 0.05}, ks = {0.5, 0.45, 0.3} },
  yarn { type = warp, umax = 50, kappa = -0.5, width = 2, length = 4, centerU = 0.8333, centerV = 0.75, kd = {0.35, 0.25, 0.05}, ks = {0.5, 0.45, 0.3} },
  yarn { type = weft, umax = 23, kappa = -0.3, width = 4, length = 4, centerU = 0.3333, centerV = 0.75, kd = {0.4, 0.1, 0.05}, ks = {0.4, 0.3, 0.2} },
  yarn { type = weft, umax = 23, kappa = -0.3, width = 4, length = 4, centerU = -0.1667, centerV = 0.25, kd = {0.4, 0.1, 0.05}, ks = {0.4, 0.3, 0.2} },
  yarn { type = weft, umax = 23, kappa = -0.3, width = 4, length = 4, centerU = 0.8333, centerV = 0.25, kd = {0.4, 0.1, 0.05}, ks = {0.4, 0.3, 0.2} }
})"},
    {"wool_gabardine", R"(weave {
  name = "wool gabardine", tileWidth = 6, tileHeight = 9,
  alpha = 0.01, beta = 4, ss = 0, hWidth = 0.5, warpArea = 12, weftArea = 6,
  pattern { 1, 1, 2, 2, 7, 7,  1, 1, 2, 2, 7, 7,  1, 1, 2, 2, 7, 7,
            1, 1, 6, 6, 4, 4,  1, 1, 6, 6, 4, 4,  1, 1, 6, 6, 4, 4,
            5, 5, 3, 3, 4, 4,  5, 5, 3, 3, 4, 4,  5, 5, 3, 3, 4, 4 },
  /* warm grey wool (our colours) */
  yarn { type = warp, psi = 30, umax = 30, kappa = 0, width = 2, length = 6, centerU = 0.167, centerV = 0.667, kd = {0.18, 0.16, 0.12}, ks = {0.06, 0.06, 0.06} },
  yarn { type = warp, psi = 30, umax = 30, kappa = 0, width = 2, length = 6, centerU = 0.5, centerV = 1.0, kd = {0.18, 0.16, 0.12}, ks = {0.06, 0.06, 0.06} },
  yarn { type = warp, psi = 30, umax = 30, kappa = 0, width = 2, length = 6, centerU = 0.5, centerV = 0.0, kd = {0.18, 0.16, 0.12}, ks = {0.06, 0.06, 0.06} },
  yarn { type = warp, psi = 30, umax = 30, kappa = 0, width = 2, length = 6, centerU = 0.833, centerV = 0.333, kd = {0.18, 0.16, 0.12}, ks = {0.06, 0.06, 0.06} },
  yarn { type = weft, psi = 30, umax = 30, kappa = 0, width = 3, length = 2, centerU = 0.167, centerV = 0.167, kd = {0.18, 0.16, 0.12}, ks = {0.06, 0.06, 0.06} },
  yarn { type = weft, psi = 30, umax = 30, kappa = 0, width = 3, length = 2, centerU = 0.5, centerV = 0.5, kd = {0.18, 0.16, 0.12}, ks = {0.06, 0.06, 0.06} },
  yarn { type = weft, psi = 30, umax = 30, kappa = 0, width = 3, length = 2, centerU = 0.833, centerV = 0.833, kd = {0.18, 0.16, 0.12}, ks = {0.06, 0.06, 0.06} }
})"},
    {"cotton_twill", R"(weave {
  name = "cotton twill", tileWidth = 4, tileHeight = 8,
  alpha = 0.01, beta = 4, ss = 0, hWidth = 0.5, warpArea = 6, weftArea = 2, fineness = 4,
  pattern { 7, 2, 4, 6,  7, 2, 4, 6,  1, 8, 4, 6,  1, 8, 4, 6,  1, 3, 9, 6,  1, 3, 9, 6,  1, 3, 5, 10,  1, 3, 5, 10 },
  /* khaki cotton (our colours); the weft is disabled by the w sin(umax) >= l guard */
  yarn { type = warp, psi = -30, umax = 24, kappa = 0, width = 1, length = 6, centerU = 0.125, centerV = 0.375, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} },
  yarn { type = warp, psi = -30, umax = 24, kappa = 0, width = 1, length = 6, centerU = 0.375, centerV = 1.125, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} },
  yarn { type = warp, psi = -30, umax = 24, kappa = 0, width = 1, length = 6, centerU = 0.375, centerV = 0.125, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} },
  yarn { type = warp, psi = -30, umax = 24, kappa = 0, width = 1, length = 6, centerU = 0.625, centerV = 0.875, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} },
  yarn { type = warp, psi = -30, umax = 24, kappa = 0, width = 1, length = 6, centerU = 0.625, centerV = -0.125, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} },
  yarn { type = warp, psi = -30, umax = 24, kappa = 0, width = 1, length = 6, centerU = 0.875, centerV = 0.625, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} },
  yarn { type = weft, psi = -30, umax = 36, kappa = 0, width = 2, length = 1, centerU = 0.125, centerV = 0.875, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} },
  yarn { type = weft, psi = -30, umax = 36, kappa = 0, width = 2, length = 1, centerU = 0.375, centerV = 0.625, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} },
  yarn { type = weft, psi = -30, umax = 36, kappa = 0, width = 2, length = 1, centerU = 0.625, centerV = 0.375, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} },
  yarn { type = weft, psi = -30, umax = 36, kappa = 0, width = 2, length = 1, centerU = 0.875, centerV = 0.125, kd = {0.45, 0.4, 0.3}, ks = {0.1, 0.1, 0.1} }
})"},
};

// Builds the layouts we chose for Sadeghi's supplement fabrics: each run of cells of one yarn
// becomes a segment; a run that wraps over the tile edge becomes two yarn entries (one centered
// outside the tile), exactly as the Mitsuba presets do.
class LayoutBuilder {
 public:
  LayoutBuilder(std::string name, int w, int h) {
    p_.name = std::move(name);
    p_.tile_width = w;
    p_.tile_height = h;
    p_.pattern.assign(static_cast<std::size_t>(w * h), 0);
  }
  WeavePattern& pattern() { return p_; }

  // Warp run in column `col` from row `row0` (0 = top) over `len` cells downwards.
  void Warp(int col, int row0, int len, WeaveYarn y) {
    y.type = WeaveYarn::Type::kWarp;
    y.width = 1;
    y.length = len;
    y.center_u = (col + 0.5) / p_.tile_width;
    y.center_v = 1.0 - (row0 + 0.5 * len) / p_.tile_height;
    const int a = Add(y);
    int b = -1;
    for (int i = 0; i < len; ++i) {
      const int r = row0 + i;
      int idx = a;
      if (r >= p_.tile_height) {
        if (b < 0) {
          y.center_v += 1.0;
          b = Add(y);
        }
        idx = b;
      }
      Set(col, r % p_.tile_height, idx);
    }
    p_.warp_area += len;
  }
  // Weft run in row `row` from column `col0` over `len` cells to the right.
  void Weft(int row, int col0, int len, WeaveYarn y) {
    y.type = WeaveYarn::Type::kWeft;
    y.width = 1;
    y.length = len;
    y.center_u = (col0 + 0.5 * len) / p_.tile_width;
    y.center_v = 1.0 - (row + 0.5) / p_.tile_height;
    const int a = Add(y);
    int b = -1;
    for (int i = 0; i < len; ++i) {
      const int c = col0 + i;
      int idx = a;
      if (c >= p_.tile_width) {
        if (b < 0) {
          y.center_u -= 1.0;
          b = Add(y);
        }
        idx = b;
      }
      Set(c % p_.tile_width, row, idx);
    }
    p_.weft_area += len;
  }

 private:
  int Add(const WeaveYarn& y) {
    p_.yarns.push_back(y);
    return static_cast<int>(p_.yarns.size());
  }
  void Set(int col, int row, int idx) { p_.pattern[static_cast<std::size_t>(row * p_.tile_width + col)] = idx; }
  WeavePattern p_;
};

WeaveYarn Thread(double psi_deg, double umax_deg, double kappa, Rgb kd, Rgb ks, double alpha, double beta, double ss) {
  WeaveYarn y;
  y.psi = DegToRad(psi_deg);
  y.umax = DegToRad(umax_deg);
  y.kappa = kappa;
  y.kd = kd;
  y.ks = ks;
  y.alpha = alpha;
  y.beta = beta;
  y.ss = ss;
  return y;
}
Rgb Scale(Rgb c, double s) { return {c[0] * s, c[1] * s, c[2] * s}; }

// Weave-level alpha/beta/ss are set from the first yarn; every yarn carries its own (Sadeghi's
// supplement gives them per thread). hWidth is not given there: 0.5 as in all Mitsuba presets.
void FinishSadeghi(WeavePattern& p) {
  p.alpha = p.yarns.front().alpha;
  p.beta = p.yarns.front().beta;
  p.ss = p.yarns.front().ss;
  p.h_width = 0.5;
}

// Plain weave, 2 x 2 cells, all segments 1 x 1 (linen, velvet).
WeavePattern PlainWeave(const std::string& name, const WeaveYarn& warp, const WeaveYarn& weft) {
  LayoutBuilder b(name, 2, 2);
  b.Warp(0, 1, 1, warp);
  b.Warp(1, 0, 1, warp);
  b.Weft(0, 0, 1, weft);
  b.Weft(1, 1, 1, weft);
  FinishSadeghi(b.pattern());
  return b.pattern();
}

// Warp floats of 2 cells over 1 weft cell, 2 x 3 tile (column 1 shifted by 1 row): crepe, shot silk.
WeavePattern TwoOverOne(const std::string& name, const WeaveYarn& warp, const WeaveYarn& weft) {
  LayoutBuilder b(name, 2, 3);
  b.Warp(0, 0, 2, warp);
  b.Weft(2, 0, 1, weft);
  b.Weft(0, 1, 1, weft);
  b.Warp(1, 1, 2, warp);
  FinishSadeghi(b.pattern());
  return b.pattern();
}

WeavePattern SadeghiPreset(const std::string& name) {
  if (name == "linen_plain") {
    const Rgb kd = Scale({0.2, 0.8, 1}, 0.09);
    const Rgb ks = Scale({1, 1, 1}, 0.7);
    const WeaveYarn t = Thread(20, 25, 0, kd, ks, 0.01, 6, 0);
    return PlainWeave("linen plain (Sadeghi 2013 supplement a)", t, t);
  }
  if (name == "silk_crepe_de_chine") {
    const Rgb kd = Scale({1, 0.95, 0.05}, 0.48);
    return TwoOverOne("silk crepe de Chine (Sadeghi 2013 supplement b)",
                      Thread(0, 45, -0.9, kd, {1.36, 1.312, 0.448}, 0.1, 10, 0.3),
                      Thread(30, 45, 1.0, kd, {1, 1, 1}, 0.1, 4, 0));
  }
  if (name == "polyester_satin_charmeuse_front" || name == "polyester_satin_charmeuse_back") {
    const Rgb kd_warp = Scale({1, 0.37, 0.3}, 0.0035);
    const Rgb ks_warp = Scale({1, 1, 1}, 0.9);
    const WeaveYarn weft = Thread(30, 25, 0, Scale({1, 0.37, 0.3}, 0.14), Scale({1, 1, 1}, 0.3), 0.01, 2, 0);
    if (name == "polyester_satin_charmeuse_front") {
      // 5-end warp-faced satin (move 2), warp floats of 4 cells; even ends carry the "inner
      // highlight" thread (c1), odd ends the "outer" one (c2). 10 ends so both alternate evenly.
      const WeaveYarn inner = Thread(0, 35, 2.0, kd_warp, ks_warp, 0.01, 8, 0.5);
      const WeaveYarn outer = Thread(0, 40, -0.85, kd_warp, ks_warp, 0.01, 8, 0.2);
      LayoutBuilder b("polyester satin charmeuse, front (Sadeghi 2013 supplement c1/c2)", 10, 5);
      for (int c = 0; c < 10; ++c) {
        const int weft_row = (2 * c) % 5;
        b.Weft(weft_row, c, 1, weft);
        b.Warp(c, (weft_row + 1) % 5, 4, c % 2 == 0 ? inner : outer);
      }
      FinishSadeghi(b.pattern());
      return b.pattern();
    }
    // Back: 3-end 2/1 twill (warp floats of 2 cells), ends alternating d1 (inner) / d2 (outer).
    const WeaveYarn inner = Thread(0, 9, -0.7, kd_warp, ks_warp, 0.01, 4, 0.6);
    const WeaveYarn outer = Thread(0, 35, -0.9, kd_warp, ks_warp, 0.01, 10, 0.2);
    LayoutBuilder b("polyester satin charmeuse, back (Sadeghi 2013 supplement d1/d2)", 6, 3);
    for (int c = 0; c < 6; ++c) {
      const int weft_row = c % 3;
      b.Weft(weft_row, c, 1, weft);
      b.Warp(c, (weft_row + 1) % 3, 2, c % 2 == 0 ? inner : outer);
    }
    FinishSadeghi(b.pattern());
    return b.pattern();
  }
  if (name == "silk_shot") {
    return TwoOverOne("silk shot (Sadeghi 2013 supplement e)",
                      Thread(0, 37, -0.7, Scale({0.1, 1, 0.4}, 0.04), {0.7, 2.5, 1.3}, 0.01, 40, 0.4),
                      Thread(0, 15, 1.0, Scale({1, 0, 0.1}, 0.12), {2.3, 0.3, 0.5}, 0.01, 40, 0.2));
  }
  if (name == "velvet") {
    // umax = 90 deg with w = l = 1: the guard zeroes the specular term of both yarns.
    const WeaveYarn t = Thread(0, 90, -0.99, Scale({0.05, 0.02, 0}, 0.03), Scale({1, 1, 1}, 0.9), 0, 10, 0.5);
    return PlainWeave("velvet (Sadeghi 2013 supplement f)", t, t);
  }
  return {};
}

const char* const kSadeghiNames[] = {"linen_plain", "silk_crepe_de_chine", "polyester_satin_charmeuse_front",
                                     "polyester_satin_charmeuse_back", "silk_shot", "velvet"};

}  // namespace

WeavePattern ParseWeavePattern(const std::string& text, const std::string& source, const nlohmann::json& variables) {
  Parser parser(text, source, variables);
  WeavePattern p = parser.Parse();
  ValidateWeavePattern(p, source);
  return p;
}

WeavePattern LoadWeavePattern(const std::filesystem::path& path, const nlohmann::json& variables) {
  return ParseWeavePattern(ReadFileBytes(path, "weave pattern file"), path.string(), variables);
}

std::string FormatWeavePattern(const WeavePattern& p) {
  std::string s = "weave {\n";
  s += fmt::format("  name = \"{}\",\n  tileWidth = {}, tileHeight = {},\n", p.name, p.tile_width, p.tile_height);
  s += fmt::format("  alpha = {}, beta = {}, ss = {}, hWidth = {},\n", Num(p.alpha), Num(p.beta), Num(p.ss), Num(p.h_width));
  s += fmt::format("  warpArea = {}, weftArea = {},\n", Num(p.warp_area), Num(p.weft_area));
  s += fmt::format("  dWarpUmaxOverDWarp = {}, dWarpUmaxOverDWeft = {},\n", Num(RadToDeg(p.d_warp_umax_over_d_warp)),
                   Num(RadToDeg(p.d_warp_umax_over_d_weft)));
  s += fmt::format("  dWeftUmaxOverDWarp = {}, dWeftUmaxOverDWeft = {},\n", Num(RadToDeg(p.d_weft_umax_over_d_warp)),
                   Num(RadToDeg(p.d_weft_umax_over_d_weft)));
  s += fmt::format("  fineness = {}, period = {},\n  pattern {{", Num(p.fineness), Num(p.period));
  for (std::size_t i = 0; i < p.pattern.size(); ++i) {
    if (i % static_cast<std::size_t>(std::max(p.tile_width, 1)) == 0) s += "\n   ";
    s += fmt::format(" {}{}", p.pattern[i], i + 1 < p.pattern.size() ? "," : "");
  }
  s += "\n  }";
  for (const auto& y : p.yarns) {
    s += fmt::format(",\n  yarn {{ type = {}, psi = {}, umax = {}, kappa = {}, width = {}, length = {},\n",
                     y.type == WeaveYarn::Type::kWarp ? "warp" : "weft", Num(RadToDeg(y.psi)), Num(RadToDeg(y.umax)),
                     Num(y.kappa), Num(y.width), Num(y.length));
    s += fmt::format("         centerU = {}, centerV = {}, kd = {}, ks = {}", Num(y.center_u), Num(y.center_v),
                     Col(y.kd), Col(y.ks));
    if (!std::isnan(y.alpha)) s += fmt::format(", alpha = {}", Num(y.alpha));
    if (!std::isnan(y.beta)) s += fmt::format(", beta = {}", Num(y.beta));
    if (!std::isnan(y.ss)) s += fmt::format(", ss = {}", Num(y.ss));
    s += " }";
  }
  s += "\n}\n";
  return s;
}

void ValidateWeavePattern(const WeavePattern& p, const std::string& source) {
  auto fail = [&](const std::string& what) {
    ThrowBadInput("weave pattern {} ('{}'): {}", source, p.name, what);
  };
  if (p.tile_width <= 0 || p.tile_height <= 0) fail("tileWidth and tileHeight must be given and >= 1");
  if (p.yarns.empty()) fail("no 'yarn { ... }' given");
  const std::size_t cells = static_cast<std::size_t>(p.tile_width) * static_cast<std::size_t>(p.tile_height);
  if (p.pattern.size() != cells)
    fail(fmt::format("'pattern' has {} entries, expected tileWidth x tileHeight = {}", p.pattern.size(), cells));
  auto finite = [](double v) { return std::isfinite(v); };
  if (!finite(p.alpha) || p.alpha < 0) fail("alpha must be finite and >= 0");
  if (!finite(p.beta)) fail("beta must be finite");
  if (!(p.ss >= 0 && p.ss < 1)) fail("ss must lie in [0, 1)");
  if (!(p.h_width > 0 && p.h_width <= 1)) fail("hWidth must lie in (0, 1]");
  if (!(p.warp_area >= 0) || !(p.weft_area >= 0) || !finite(p.warp_area) || !finite(p.weft_area))
    fail("warpArea and weftArea must be finite and >= 0");
  if (!(p.fineness >= 0) || !finite(p.fineness)) fail("fineness must be finite and >= 0 (0 = off)");
  if (!(p.period >= 0) || !finite(p.period)) fail("period must be finite and >= 0 (0 = off)");
  for (double d : {p.d_warp_umax_over_d_warp, p.d_warp_umax_over_d_weft, p.d_weft_umax_over_d_warp, p.d_weft_umax_over_d_weft})
    if (!finite(d)) fail("the dUmax noise amplitudes must be finite");
  bool has_warp = false, has_weft = false;
  for (std::size_t i = 0; i < p.yarns.size(); ++i) {
    const WeaveYarn& y = p.yarns[i];
    const std::string id = fmt::format("yarn {} ({})", i + 1, y.type == WeaveYarn::Type::kWarp ? "warp" : "weft");
    for (double v : {y.psi, y.umax, y.kappa, y.width, y.length, y.center_u, y.center_v})
      if (!finite(v)) fail(id + ": all values must be finite");
    for (double v : {y.kd[0], y.kd[1], y.kd[2], y.ks[0], y.ks[1], y.ks[2]})
      if (!finite(v) || v < 0) fail(id + ": kd and ks must be finite and >= 0");
    if (!(y.width > 0) || !(y.length > 0)) fail(id + ": width and length must be > 0 cells");
    if (!(y.umax >= 0 && y.umax <= kPi / 2 + 1e-12)) fail(id + ": umax must lie in [0, 90] degrees");
    // kappa = -1 makes the spine radius 0/0 (the reference only rejects kappa < -1 and returns NaN).
    if (!(y.kappa > -1)) fail(id + fmt::format(": kappa = {} must be > -1 (kappa <= -1 has no valid spine radius)", y.kappa));
    // Staple yarns divide by tan(umax): umax ~ 0 gives cot(umax) = inf and NaN in the reference.
    if (y.psi != 0 && y.umax < 1e-6)
      fail(id + ": a staple yarn (psi != 0) needs umax > 0 (umax ~ 0 makes its spine curvature undefined)");
    const double ss = p.SsOf(y), beta = p.BetaOf(y), alpha = p.AlphaOf(y);
    if (!(ss >= 0 && ss < 1)) fail(id + ": ss must lie in [0, 1)");
    if (!finite(beta)) fail(id + ": beta must be finite");
    if (!(alpha >= 0) || !finite(alpha)) fail(id + ": alpha must be finite and >= 0");
  }
  for (std::size_t c = 0; c < cells; ++c) {
    const int idx = p.pattern[c];
    const int cx = static_cast<int>(c) % p.tile_width, cy = static_cast<int>(c) / p.tile_width;
    if (idx < 1 || idx > static_cast<int>(p.yarns.size()))
      fail(fmt::format("pattern cell (column {}, row {} from the top) refers to yarn {}, but only yarns 1..{} exist",
                       cx, cy, idx, p.yarns.size()));
    const WeaveYarn& y = p.yarns[static_cast<std::size_t>(idx - 1)];
    (y.type == WeaveYarn::Type::kWarp ? has_warp : has_weft) = true;
    // The cell must lie inside its segment rectangle: otherwise the yarn coordinate u leaves
    // [-umax, umax] and the curvature formula is used outside its domain.
    double xl = cx + 0.5 - y.center_u * p.tile_width;
    double yl = -(cy + 0.5 - (1 - y.center_v) * p.tile_height);
    if (y.type == WeaveYarn::Type::kWeft) {
      const double t = xl;
      xl = -yl;
      yl = t;
    }
    constexpr double kTol = 0.02;  // cells; preset centers are rounded to 3-4 decimals
    if (std::abs(xl) + 0.5 > 0.5 * y.width + kTol || std::abs(yl) + 0.5 > 0.5 * y.length + kTol)
      fail(fmt::format("pattern cell (column {}, row {} from the top) lies outside the segment of yarn {} "
                       "(centre ({}, {}), width {}, length {}): check centerU/centerV/width/length",
                       cx, cy, idx, y.center_u, y.center_v, y.width, y.length));
  }
  if (has_warp && p.warp_area <= 0) fail("warpArea must be > 0 when the pattern uses warp yarns");
  if (has_weft && p.weft_area <= 0) fail("weftArea must be > 0 when the pattern uses weft yarns");
}

std::vector<std::string> WeavePresetNames() {
  std::vector<std::string> names;
  for (const auto& t : kTextPresets) names.emplace_back(t.name);
  for (const char* n : kSadeghiNames) names.emplace_back(n);
  return names;
}

WeavePattern WeavePreset(const std::string& name) {
  for (const auto& t : kTextPresets)
    if (name == t.name) return ParseWeavePattern(t.text, "preset:" + name);
  for (const char* n : kSadeghiNames) {
    if (name == n) {
      WeavePattern p = SadeghiPreset(name);
      ValidateWeavePattern(p, "preset:" + name);
      return p;
    }
  }
  std::string list;
  for (const auto& n : WeavePresetNames()) list += (list.empty() ? "" : ", ") + n;
  ThrowUsage("unknown irawan2012 preset '{}' (known: {}; or a path to a Mitsuba .wv file)", name, list);
}

}  // namespace btf
