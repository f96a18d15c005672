#pragma once
// Weave patterns for the Irawan 2012 cloth model: the data of Mitsuba 0.6's `.wv` text format
// (parser and writer) and the built-in fabric presets (docs/btf-synth.md, "Irawan 2012 and
// Sadeghi 2013 models").
//
// Units as stored here: angles in RADIANS (the .wv text uses degrees), lengths in pattern cells,
// segment centers in tile units ((0,0) = lower-left corner of the tile, may lie outside [0,1]).
#include <array>
#include <cmath>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace btf {

using Rgb = std::array<double, 3>;

struct WeaveYarn {
  enum class Type { kWarp, kWeft };
  Type type = Type::kWarp;
  double psi = 0;    // fibre twist angle (rad); 0 = filament yarn, otherwise staple
  double umax = 0;   // maximum inclination angle (rad)
  double kappa = 0;  // spine curvature, > -1
  double width = 0;  // segment width w (cells)
  double length = 0; // segment length l (cells)
  double center_u = 0, center_v = 0;  // segment center (tile units)
  Rgb kd{0, 0, 0};  // diffuse albedo (the BRDF adds kd / pi), linear RGB
  Rgb ks{0, 0, 0};  // specular albedo after normalization, linear RGB
  // libbtf extension (Sadeghi's supplement gives these per thread): NaN = use the weave's value.
  double alpha = std::numeric_limits<double>::quiet_NaN();
  double beta = std::numeric_limits<double>::quiet_NaN();
  double ss = std::numeric_limits<double>::quiet_NaN();
};

struct WeavePattern {
  std::string name;
  double alpha = 0;   // uniform part of the fibre phase function
  double beta = 0;    // von Mises concentration of the forward-scattering part
  double ss = 0;      // filament smoothing, [0, 1)
  double h_width = 0; // highlight band width (fraction of segment length / width), (0, 1]
  double warp_area = 0, weft_area = 0;
  int tile_width = 0, tile_height = 0;
  // umax noise amplitudes (rad): d(warp umax)/d(warp), d(warp umax)/d(weft), weft likewise.
  double d_warp_umax_over_d_warp = 0, d_warp_umax_over_d_weft = 0;
  double d_weft_umax_over_d_warp = 0, d_weft_umax_over_d_weft = 0;
  double fineness = 0;  // intensity-variation cells per cell (0 = off)
  double period = 0;    // umax noise period (0 = off)
  std::vector<int> pattern;  // 1-based yarn indices, row-major, first row = top of the tile
  std::vector<WeaveYarn> yarns;

  const WeaveYarn& YarnAt(int cell_x, int cell_y) const {
    return yarns[static_cast<std::size_t>(pattern[static_cast<std::size_t>(cell_y * tile_width + cell_x)] - 1)];
  }
  // The effective per-yarn value of alpha / beta / ss (yarn override or weave value).
  double AlphaOf(const WeaveYarn& y) const { return std::isnan(y.alpha) ? alpha : y.alpha; }
  double BetaOf(const WeaveYarn& y) const { return std::isnan(y.beta) ? beta : y.beta; }
  double SsOf(const WeaveYarn& y) const { return std::isnan(y.ss) ? ss : y.ss; }
};

// Parses the `.wv` grammar: `weave { item, item, ... }` with items `name = "..."`,
// `tileWidth = N`, `tileHeight = N`, `alpha|beta|ss|hWidth|warpArea|weftArea|fineness|period = F`,
// `dWarpUmaxOverDWarp|dWarpUmaxOverDWeft|dWeftUmaxOverDWarp|dWeftUmaxOverDWeft = F` (degrees),
// `pattern { N, N, ... }` and `yarn { type = warp|weft, psi|umax = F (degrees), kappa|width|
// length|centerU|centerV = F, kd|ks = {r, g, b} }`, separated by commas; `/* ... */` comments.
// A float or color may be a `$identifier`, resolved from `variables` (JSON number or [r,g,b]).
// libbtf extension: yarn items `alpha`, `beta`, `ss` (per-thread values, as in Sadeghi 2013).
// `source` names the file in error messages (bad input, with line number). Validates the result.
WeavePattern ParseWeavePattern(const std::string& text, const std::string& source,
                               const nlohmann::json& variables = nlohmann::json::object());
WeavePattern LoadWeavePattern(const std::filesystem::path& path,
                              const nlohmann::json& variables = nlohmann::json::object());
// Writes `.wv` text that ParseWeavePattern reads back to the same values (17 significant digits).
std::string FormatWeavePattern(const WeavePattern& p);

// Consistency checks (pattern size, yarn indices in range, every cell inside its yarn's segment
// rectangle, parameter ranges: kappa > -1, 0 <= ss < 1, 0 < hWidth <= 1, staple umax > 0, ...).
// Throws btf::Error (bad input) naming `source` and the offending item.
void ValidateWeavePattern(const WeavePattern& p, const std::string& source);

// Built-in presets (names in WeavePresetNames()); unknown names throw btf::Error (usage).
WeavePattern WeavePreset(const std::string& name);
std::vector<std::string> WeavePresetNames();

}  // namespace btf
