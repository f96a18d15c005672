#include "libbtf/synth/sadeghi2013.h"

#include <algorithm>
#include <atomic>
#include <cmath>

#include <Eigen/Geometry>

#include "libbtf/core/error.h"

namespace btf {
namespace sadeghi2013 {

double FresnelDielectric(double cos_i, double eta) {
  cos_i = std::clamp(cos_i, 0.0, 1.0);
  const double sin2_t = (1 - cos_i * cos_i) / (eta * eta);
  if (sin2_t >= 1) return 1;  // total internal reflection (only for eta < 1)
  const double cos_t = std::sqrt(1 - sin2_t);
  const double rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  const double rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  return 0.5 * (rs * rs + rp * rp);
}

double UnitGaussian(double width, double x) {
  return std::exp(-0.5 * (x * x) / (width * width)) / (width * std::sqrt(2 * kPi));
}

std::vector<TangentSample> SampleTangentCurve(const std::vector<double>& offsets, const std::vector<double>& lengths,
                                              double max_step) {
  std::vector<TangentSample> out;
  double total = 0;
  for (double l : lengths) total += l;
  if (offsets.size() == 1 || total <= 0) {  // a single tangent
    out.push_back({offsets.front(), 1.0});
    return out;
  }
  // Piecewise-linear tilt along the thread; midpoint rule per piece, fine enough that the
  // narrowest lobe (gamma_s = 2.5 deg in Table II) is resolved without banding.
  for (std::size_t k = 0; k + 1 < offsets.size(); ++k) {
    const double len = lengths[k];
    if (len <= 0) continue;  // a zero-length piece is a jump in the curve
    const double a0 = offsets[k], a1 = offsets[k + 1];
    const int m = std::max(1, static_cast<int>(std::ceil(std::abs(a1 - a0) / max_step)));
    for (int i = 0; i < m; ++i) {
      const double s = (i + 0.5) / m;
      out.push_back({a0 + s * (a1 - a0), len / (m * total)});
    }
  }
  return out;
}

}  // namespace sadeghi2013

namespace {
using sadeghi2013::FresnelDielectric;
using sadeghi2013::UnitGaussian;

std::atomic<unsigned long long> g_instance_counter{1};

// Unit-height Gaussian of Eqs. 9 and 13 (Ashikhmin et al. 2000).
double UnitHeight(double x, double sigma) { return std::exp(-0.5 * x * x / (sigma * sigma)); }

// Longitudinal angle psi of Eqs. 11-12: between the fabric normal and w projected onto the plane
// of the (untilted) thread direction and the normal (signed, positive towards the thread direction).
double Psi(const Vec3& w, bool along_v) {
  const double along = along_v ? w.y() : w.x();
  return std::atan2(along, w.z());
}

unsigned long long NextId() { return g_instance_counter.fetch_add(1); }

}  // namespace

Sadeghi2013Model::Sadeghi2013Model(std::string preset, SadeghiParams params)
    : preset_(std::move(preset)), params_(std::move(params)), id_(NextId()) {
  auto fail = [&](const std::string& what) { ThrowUsage("sadeghi2013 preset '{}': {}", preset_, what); };
  if (!(params_.eta > 1) || !std::isfinite(params_.eta)) fail("eta must be a finite refractive index > 1");
  if (!(params_.masking_sigma > 0) || !std::isfinite(params_.masking_sigma)) fail("masking_sigma_deg must be > 0");
  if (!(params_.tangent_step > 0) || !std::isfinite(params_.tangent_step)) fail("tangent_step_deg must be > 0");
  if (params_.threads.empty()) fail("needs at least one thread");
  double cover = 0;
  for (const auto& th : params_.threads) {
    const std::string id = "thread '" + th.label + "'";
    for (double a : th.albedo)
      if (!(a >= 0) || !std::isfinite(a)) fail(id + ": albedo A must be finite and >= 0");
    if (!(th.kd >= 0 && th.kd <= 1)) fail(id + ": kd must lie in [0, 1]");
    if (!(th.gamma_s > 0) || !(th.gamma_v > 0) || !std::isfinite(th.gamma_s) || !std::isfinite(th.gamma_v))
      fail(id + ": gamma_s and gamma_v must be > 0");
    if (!(th.coverage >= 0 && th.coverage <= 1)) fail(id + ": coverage a must lie in [0, 1]");
    if (th.offsets.empty() || th.lengths.size() + 1 != th.offsets.size())
      fail(id + ": needs K tangent offsets and K-1 lengths");
    for (double l : th.lengths)
      if (!(l >= 0) || !std::isfinite(l)) fail(id + ": tangent lengths must be finite and >= 0");
    for (double o : th.offsets)
      if (!(std::abs(o) <= kPi / 2 + 1e-12)) fail(id + ": tangent offsets must lie in [-90, 90] degrees");
    cover += th.coverage;
    Sampled c;
    for (const auto& smp : sadeghi2013::SampleTangentCurve(th.offsets, th.lengths, params_.tangent_step))
      c.frames.push_back(MakeFrame(th.along_v, smp.angle, smp.weight));
    curves_.push_back(std::move(c));
  }
  if (cover > 1 + 1e-9) fail("the thread coverages a must sum to <= 1");
}

Sadeghi2013Model::TangentFrame Sadeghi2013Model::MakeFrame(bool along_v, double tilt, double weight) {
  // Tilting the tangent by `tilt` tilts its local normal by the same angle (paper, Fig. 12).
  const double c = std::cos(tilt), s = std::sin(tilt);
  TangentFrame f;
  f.t = along_v ? Vec3(0, c, s) : Vec3(c, 0, s);
  f.n = along_v ? Vec3(0, -s, c) : Vec3(-s, 0, c);
  f.b = f.t.cross(f.n);
  f.weight = weight;
  return f;
}

void Sadeghi2013Model::Terms(const SadeghiThread& th, const TangentFrame& f, const Vec3& wi, const Vec3& wo,
                             double* surface, double* volume, double* masking) const {
  *surface = *volume = *masking = 0;
  // Longitudinal angles from the normal plane of t (sin theta = w . t) and azimuths about t from the
  // local normal n (Fig. 9), without inverse trigonometry where the cosines suffice.
  const double si = std::clamp(wi.dot(f.t), -1.0, 1.0), so = std::clamp(wo.dot(f.t), -1.0, 1.0);
  const double ci = std::sqrt(1 - si * si), co = std::sqrt(1 - so * so);
  // cos/sin of the azimuths; a direction along t has no azimuth: phi = 0 by convention.
  const double cpi = ci > 1e-12 ? wi.dot(f.n) / ci : 1.0, spi = ci > 1e-12 ? wi.dot(f.b) / ci : 0.0;
  const double cpo = co > 1e-12 ? wo.dot(f.n) / co : 1.0, spo = co > 1e-12 ? wo.dot(f.b) / co : 0.0;
  // Masking (Eqs. 7-9) with the unit-height Gaussian u of phi_d.
  const double m_i = std::max(cpi, 0.0), m_o = std::max(cpo, 0.0);
  if (m_i == 0 || m_o == 0) return;  // then M = 0: back-facing for light or viewer
  const double cos_phi_d = std::clamp(cpi * cpo + spi * spo, -1.0, 1.0);
  const double phi_d = std::acos(cos_phi_d);  // |phi_i - phi_o| wrapped to [0, pi]
  const double um = UnitHeight(phi_d, params_.masking_sigma);
  *masking = (1 - um) * m_i * m_o + um * std::min(m_i, m_o);
  const double theta_h = 0.5 * std::atan2(si * co + ci * so, ci * co - si * so);  // (theta_i + theta_o) / 2
  const double cos2_td_exact = 0.5 * (1 + ci * co + si * so);                    // cos^2((theta_i - theta_o) / 2)
  const double cos_half_phi = std::sqrt(0.5 * (1 + cos_phi_d));                  // cos(phi_d / 2) >= 0
  // Both directions grazing along +t and -t make cos(theta_d) -> 0: the 1/cos^2 solid-angle factor
  // of Eq. 4 is capped there (theta_d <= 89.9 deg) so values stay finite.
  const double cos2_td = std::max(cos2_td_exact, 3.0461741978670857e-6);
  // Eq. 2: Fresnel at the effective angle acos(cos theta_d cos(phi_d / 2)).
  const double cos_eff = std::clamp(std::sqrt(cos2_td_exact) * cos_half_phi, 0.0, 1.0);
  const double fr = FresnelDielectric(cos_eff, params_.eta);
  const double f_surface = fr * cos_half_phi * UnitGaussian(th.gamma_s, theta_h);
  // Eq. 3: transmission in and out, our choice: both at the same effective angle (reciprocal).
  const double ft = 1 - fr;
  const double cos_sum = std::max(ci + co, 1e-6);
  const double f_volume = ft * ft * ((1 - th.kd) * UnitGaussian(th.gamma_v, theta_h) + th.kd) / cos_sum;
  *surface = f_surface / cos2_td;
  *volume = f_volume / cos2_td;
}

void Sadeghi2013Model::EvalRgb(const Vec3& wi_in, const Vec3& wo_in, double out[3]) const {
  out[0] = out[1] = out[2] = 0;
  const double ni = wi_in.norm(), no = wo_in.norm();
  if (!(ni > 0) || !(no > 0) || !std::isfinite(ni) || !std::isfinite(no)) return;
  const Vec3 wi = wi_in / ni, wo = wo_in / no;
  if (wi.z() <= 0 || wo.z() <= 0) return;
  const double sigma = params_.masking_sigma;
  double num[3] = {0, 0, 0};
  double q = 0;
  double cover = 0;
  for (std::size_t j = 0; j < params_.threads.size(); ++j) {
    const SadeghiThread& th = params_.threads[j];
    cover += th.coverage;
    // Reweighting (Eqs. 11-13): the same for every tangent of this thread direction, because psi is
    // measured in the plane of the untilted thread direction and the fabric normal.
    const double psi_i = Psi(wi, th.along_v), psi_o = Psi(wo, th.along_v);
    const double p_i = std::max(std::cos(psi_i), 0.0), p_o = std::max(std::cos(psi_o), 0.0);
    const double up = UnitHeight(psi_i - psi_o, sigma);
    const double P = (1 - up) * p_i * p_o + up * std::min(p_i, p_o);
    q += th.coverage * P;  // Eq. 15: (a_j / N_j) sum_t P(t)
    if (P == 0 || th.coverage == 0) continue;
    double s_sum = 0, v_sum = 0;
    for (const TangentFrame& fr : curves_[j].frames) {
      double s, v, M;
      Terms(th, fr, wi, wo, &s, &v, &M);
      s_sum += fr.weight * s * M;
      v_sum += fr.weight * v * M;
    }
    for (int c = 0; c < 3; ++c) num[c] += th.coverage * P * (s_sum + v_sum * th.albedo[static_cast<std::size_t>(c)]);
  }
  q += std::max(0.0, 1 - cover) * wo.z();  // projected area of the gaps
  if (!(q > 1e-300)) return;
  for (int c = 0; c < 3; ++c) {
    const double v = num[c] / q;
    out[c] = std::isfinite(v) && v > 0 ? v : 0.0;
  }
}

void Sadeghi2013Model::EvalBrdf(const Vec3& wi, const Vec3& wo, float* out) const {
  double v[3];
  EvalRgb(wi, wo, v);
  for (int c = 0; c < 3; ++c) out[c] = static_cast<float>(v[c]);
}

void Sadeghi2013Model::EvalBatch(const Vec3& wi, const Vec3& wo, const Vec2* /*uv*/, int n, float* out) const {
  float v[3];
  EvalBrdf(wi, wo, v);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) out[static_cast<std::ptrdiff_t>(i) * 3 + c] = v[c];
}

void Sadeghi2013Model::Eval(const Vec2& /*uv: constant over the tile*/, const Vec3& wi, const Vec3& wo,
                            float* out) const {
  // Callers that loop over texels for one direction pair hit this per-thread cache.
  static thread_local unsigned long long last_id = 0;
  static thread_local Vec3 last_wi, last_wo;
  static thread_local float last[3];
  if (last_id != id_ || last_wi != wi || last_wo != wo) {
    EvalBrdf(wi, wo, last);
    last_id = id_;
    last_wi = wi;
    last_wo = wo;
  }
  out[0] = last[0];
  out[1] = last[1];
  out[2] = last[2];
}

nlohmann::json Sadeghi2013Model::Describe() const {
  nlohmann::json threads = nlohmann::json::array();
  for (std::size_t j = 0; j < params_.threads.size(); ++j) {
    const auto& th = params_.threads[j];
    std::vector<double> off;
    for (double o : th.offsets) off.push_back(RadToDeg(o));
    threads.push_back({{"label", th.label},
                       {"direction", th.along_v ? "warp (+y, texture v)" : "weft (+x, texture u)"},
                       {"albedo", th.albedo},
                       {"kd", th.kd},
                       {"gamma_s_deg", RadToDeg(th.gamma_s)},
                       {"gamma_v_deg", RadToDeg(th.gamma_v)},
                       {"coverage", th.coverage},
                       {"tangent_offsets_deg", off},
                       {"tangent_lengths", th.lengths},
                       {"tangent_samples", curves_[j].frames.size()}});
  }
  return {{"model", "sadeghi2013"},
          {"preset", preset_},
          {"fabric", params_.name},
          {"reference", "Sadeghi et al. 2013, Eqs. 2-15, Table II (our own code)"},
          {"units", "BRDF in 1/sr without cos(theta_i); constant over the tile"},
          {"eta", params_.eta},
          {"masking_sigma_deg", RadToDeg(params_.masking_sigma)},
          {"tangent_step_deg", RadToDeg(params_.tangent_step)},
          {"tile_mm", params_.tile_mm},
          {"threads", threads},
          {"choices",
           {"Eq. 14 read as a surface BRDF: f = sum_j a_j P_j sum_t w_t f_s M / Q, integrated against the fabric's "
            "cos(theta_i)",
            "transmission Fresnel F = (1 - Fr)^2 at the surface term's effective angle",
            "thread 1 runs along the warp (+y), thread 2 along the weft (+x)",
            "tangent curves piecewise linear between control points, midpoint samples at most tangent_step_deg apart",
            "psi of Eq. 11 measured in the plane of the untilted thread direction and the normal",
            "cos^2(theta_d) capped below at cos^2(89.9 deg); a direction along t has azimuth 0",
            "Eq. 15's gap term makes fabrics with a1 + a2 < 1 non-reciprocal"}}};
}

namespace {

SadeghiThread MakeThread(std::string label, bool along_v, std::array<double, 3> color, double scale, double kd,
                         double gs_deg, double gv_deg, double a, std::vector<double> offsets_deg,
                         std::vector<double> lengths) {
  SadeghiThread t;
  t.label = std::move(label);
  t.along_v = along_v;
  for (int c = 0; c < 3; ++c) t.albedo[static_cast<std::size_t>(c)] = color[static_cast<std::size_t>(c)] * scale;
  t.kd = kd;
  t.gamma_s = DegToRad(gs_deg);
  t.gamma_v = DegToRad(gv_deg);
  t.coverage = a;
  for (double o : offsets_deg) t.offsets.push_back(DegToRad(o));
  t.lengths = std::move(lengths);
  return t;
}

const char* const kPresetNames[] = {"linen_plain",     "crepe_de_chine", "charmeuse_front",
                                    "charmeuse_back",  "silk_shot",      "velvet"};

// Table II. Thread 1 (flat / dir 1) runs along the warp (+y), thread 2 along the weft (+x): our
// choice, the table does not say. "Both" (linen) = two identical threads, one per direction.
SadeghiParams Preset(const std::string& name) {
  SadeghiParams p;
  if (name == "linen_plain") {
    p.name = "linen plain (Table II a)";
    p.eta = 1.46;
    for (bool v : {true, false})
      p.threads.push_back(MakeThread(v ? "both (warp)" : "both (weft)", v, {0.2, 0.8, 1}, 0.3, 0.3, 12, 24, 0.33,
                                     {-25, 25}, {1}));
  } else if (name == "crepe_de_chine") {
    p.name = "silk crepe de Chine (Table II b)";
    p.eta = 1.345;
    p.threads.push_back(MakeThread("flat", true, {1, 0.95, 0.05}, 0.12, 0.2, 5, 10, 0.75, {-35, -35, 35, 35}, {1, 1, 1}));
    p.threads.push_back(MakeThread("twisted", false, {1, 0.95, 0.05}, 0.16, 0.3, 18, 32, 0.25, {0, 0}, {1}));
  } else if (name == "charmeuse_front") {
    p.name = "polyester satin charmeuse, front (Table II c)";
    p.eta = 1.539;
    p.threads.push_back(MakeThread("flat", true, {1, 0.37, 0.3}, 0.035, 0.1, 2.5, 5, 0.9,
                                   {-32, -32, -18, 0, 0, 18, 32, 32}, {1.33, 0.66, 2, 2, 2, 0.66, 1.33}));
    p.threads.push_back(MakeThread("twisted", false, {1, 0.37, 0.3}, 0.2, 0.7, 30, 60, 0.1, {0, 0}, {1}));
  } else if (name == "charmeuse_back") {
    p.name = "polyester satin charmeuse, back (Table II d)";
    p.eta = 1.539;
    p.threads.push_back(MakeThread("flat", true, {1, 0.37, 0.3}, 0.035, 0.1, 2.5, 5, 0.67,
                                   {-30, -30, 30, 30, -5, -5, 5, 5}, {1.33, 1.33, 1.33, 0, 0.67, 0.67, 0.67}));
    p.threads.push_back(MakeThread("twisted", false, {1, 0.37, 0.3}, 0.2, 0.7, 30, 60, 0.33, {0, 0}, {3}));
  } else if (name == "silk_shot") {
    p.name = "silk shot (Table II e)";
    p.eta = 1.345;
    p.threads.push_back(MakeThread("dir 1", true, {0.1, 1, 0.4}, 0.2, 0.1, 4, 8, 0.86, {-25, -25, 25, 25},
                                   {1.33, 2.67, 1.33}));
    p.threads.push_back(MakeThread("dir 2", false, {1, 0, 0.1}, 0.6, 0.1, 5, 10, 0.14, {0, 0}, {1}));
  } else if (name == "velvet") {
    p.name = "velvet (Table II f)";
    p.eta = 1.46;
    p.threads.push_back(MakeThread("dir 1", true, {0.05, 0.02, 0}, 0.3, 0.1, 6, 12, 0.5, {-90, -50}, {1}));
    p.threads.push_back(
        MakeThread("dir 2", false, {0.05, 0.02, 0}, 0.3, 0.1, 6, 12, 0.5, {-90, -55, 55, 90}, {0.5, 0, 0.5}));
  } else {
    std::string list;
    for (const char* n : kPresetNames) list += (list.empty() ? "" : ", ") + std::string(n);
    ThrowUsage("unknown sadeghi2013 preset '{}' (known: {})", name, list);
  }
  return p;
}

double Positive(const nlohmann::json& v, const char* field) {
  if (!v.is_number() || !std::isfinite(v.get<double>()) || v.get<double>() <= 0)
    ThrowUsage("sadeghi2013 parameter '{}' must be a number > 0, got {}", field, v.dump());
  return v.get<double>();
}

}  // namespace

std::vector<std::string> Sadeghi2013PresetNames() { return {std::begin(kPresetNames), std::end(kPresetNames)}; }

std::unique_ptr<Sadeghi2013Model> MakeSadeghi2013(const std::string& preset, const nlohmann::json& params_in) {
  const nlohmann::json params = params_in.is_null() ? nlohmann::json::object() : params_in;
  if (!params.is_object()) ThrowUsage("sadeghi2013 parameters must be a JSON object, got {}", params.dump());
  SadeghiParams p = Preset(preset);
  for (const auto& [key, value] : params.items()) {
    if (key == "eta") {
      p.eta = Positive(value, "eta");
    } else if (key == "masking_sigma_deg") {
      p.masking_sigma = DegToRad(Positive(value, "masking_sigma_deg"));
    } else if (key == "tangent_step_deg") {
      p.tangent_step = DegToRad(Positive(value, "tangent_step_deg"));
    } else if (key == "tile_mm") {
      p.tile_mm = Positive(value, "tile_mm");
    } else {
      ThrowUsage("unknown sadeghi2013 parameter '{}' (known: eta, masking_sigma_deg, tangent_step_deg, tile_mm)", key);
    }
  }
  return std::make_unique<Sadeghi2013Model>(preset, std::move(p));
}

std::unique_ptr<SvbrdfModel> MakeSadeghi2013Model(const std::string& preset, const nlohmann::json& params) {
  return MakeSadeghi2013(preset, params);
}

}  // namespace btf
