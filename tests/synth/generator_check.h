#pragma once
// Shared by the fast and slow generator tests: the texel mean of a generated Irawan 2006 BTF
// against the analytic BRDF over all bonn81 pairs, with the stratified-sampling error bound.
#include <gtest/gtest.h>

#include <cmath>

#include "libbtf/synth/btf_generator.h"
#include "tests/synth_util.h"
#include "libbtf/synth/irawan2006.h"

namespace btf::test {

// Upper bound on the number of strata (cells of the N*S x N*S sample grid over the image) that
// the highlight boundaries of one tile cross, times the number of tiles. Each segment's lit
// region is ellipse ∩ window, convex with a bounding box no larger than the ellipse's; a convex
// curve of extent (ex, ey) crosses at most 2 (ex/dx + ey/dy) + 8 cells. Window edges are not
// counted: the caller makes them coincide with stratum edges.
inline double BoundaryStrata(const Irawan2006Params& p, double dx_units, double dy_units) {
  double n = 0;
  for (const auto& s : p.segments) {
    const double beta = s.alpha * std::sqrt(1 - s.eta * s.eta);
    const double c = std::cos(s.phi), sn = std::sin(s.phi);
    const double ex = 2 * std::sqrt(s.alpha * s.alpha * c * c + beta * beta * sn * sn);
    const double ey = 2 * std::sqrt(s.alpha * s.alpha * sn * sn + beta * beta * c * c);
    n += 2 * (std::min(ex, s.sx) / dx_units + std::min(ey, s.sy) / dy_units) + 8;
  }
  return n;
}

// Generates preset at N^2 texels x S^2 samples over bonn81 x bonn81 and asserts the texel mean
// equals the analytic BRDF within 6 SD of the stratified estimate (stratum edges must fall on
// unit boundaries: checked). Returns the worst error in SDs.
inline double ExpectTexelMeanConverges(const std::string& preset, int resolution, int samples) {
  const Irawan2006Params params = Irawan2006Preset(preset);
  const Irawan2006Model model(params);
  BtfOptions o;  // bonn81 x bonn81
  o.resolution = resolution;
  o.samples = samples;
  o.tiles = 1;
  const Dataset ds = test::GenerateDataset(model, o);
  const int grid = o.resolution * o.samples;  // strata per tile side
  // Stratum edges fall on unit boundaries, so only the ellipse arcs leave strata partly lit.
  // Each such stratum's jittered sample is an independent Bernoulli error of variance
  // <= 1/4 stratum^2: SD of the lit fraction <= sqrt(Nb) / (2 M^2), M = strata per side.
  EXPECT_EQ(grid % params.tile_w, 0);
  EXPECT_EQ(grid % params.tile_h, 0);
  const double nb = BoundaryStrata(params, double(params.tile_w) / grid, double(params.tile_h) / grid);
  const double sd = std::sqrt(nb) / (2.0 * grid * grid);
  const double tol_fraction = 6 * sd;  // 6 SD; the seed is fixed, so the test is deterministic
  double worst_sigma = 0;
  int lit_pairs = 0;
  for (int v = 0; v < ds.num_views(); ++v)
    for (int l = 0; l < ds.num_lights(); ++l) {
      const auto img = ds.image(v, l);
      float f[3];
      model.EvalBrdf(ds.lights()[l], ds.views()[v], f);
      const double spec = model.SpecularFactor(ds.lights()[l], ds.views()[v]);
      if (model.HighlightFraction(ds.lights()[l], ds.views()[v]) > 0) ++lit_pairs;
      for (int c = 0; c < 3; ++c) {
        double mean = 0;
        for (std::size_t i = c; i < img.size(); i += 3) mean += img[i];
        mean /= ds.num_texels();
        // Float storage of the texel values and the analytic value: 1e-6 relative.
        const double tol = params.ks[c] * spec * tol_fraction + 1e-6 * f[c];
        EXPECT_NEAR(mean, f[c], tol) << preset << " view " << v << " light " << l << " channel " << c;
        if (std::abs(mean - f[c]) > tol) return worst_sigma;  // one report is enough
        if (spec > 0) worst_sigma = std::max(worst_sigma, std::abs(mean - f[c]) / (params.ks[c] * spec * sd));
      }
    }
  EXPECT_GT(lit_pairs, 1000) << preset;  // the comparison is not vacuous: highlights are present
  return worst_sigma;
}

}  // namespace btf::test
