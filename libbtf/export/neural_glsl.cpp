// The GLSL function file of a neural export (btf_neural.glsl): the decoder of
// NeuralReferenceDecoder::Value in GLSL ES 3.00 (WebGL2), float32, with the export's constants.
#include <algorithm>
#include <string>

#include "libbtf/core/error.h"
#include "libbtf/export/neural.h"

namespace btf {

namespace {

std::string FloatList(const std::vector<float>& v, std::size_t n) {
  std::string s;
  for (std::size_t i = 0; i < n; ++i) s += fmt::format("{}{:.9g}", i ? ", " : "", i < v.size() ? v[i] : 0.0f);
  return s;
}

// `const vec4 NAME[layers]` of the per-latent scales or biases (zero-padded to whole vec4s).
std::string LatentConstant(const std::string& name, const std::vector<float>& v, int layers) {
  std::string items;
  for (int g = 0; g < layers; ++g) {
    std::vector<float> four;
    for (int k = 0; k < 4; ++k) four.push_back(std::size_t(4 * g + k) < v.size() ? v[std::size_t(4 * g + k)] : 0.0f);
    items += fmt::format("{}\n  vec4({})", g ? "," : "", FloatList(four, 4));
  }
  return fmt::format("const vec4 {}[{}] = vec4[{}]({});\n", name, layers, layers, items);
}

std::string ActivationGlsl(const std::string& name) {
  if (name == "silu") return "z / (1.0 + exp(-z))";
  if (name == "relu") return "max(z, 0.0)";
  if (name == "leaky_relu") return "z > 0.0 ? z : 0.01 * z";
  if (name == "softplus") return "max(z, 0.0) + log(1.0 + exp(-abs(z)))";
  ThrowBadInput("neural export: unknown activation '{}'", name);
}

// The code of one layer: from `in` (inputs + a 1 at index inputs) into `out`, rows first_row.. of
// btf_decoder; hidden layers end with the 1 of the next layer's bias.
std::string LayerGlsl(const nlohmann::json& layer, int n, int outputs_used, const std::string& in,
                      const std::string& out) {
  const int inputs = layer.at("inputs"), outputs = layer.at("outputs"), row = layer.at("first_row");
  const std::string act = layer.at("activation");
  const bool hidden = act != "linear";
  const int used = hidden ? outputs : outputs_used;
  return fmt::format(R"(  // layer {n}: {inputs} -> {outputs}{act_note}
  for (int i = 0; i < BTF_MAX4; ++i) {out}[i] = vec4(0.0);
  for (int o = 0; o < {used}; ++o) {{
    vec4 s = vec4(0.0);
    for (int j = 0; j < {in4}; ++j) s += texelFetch(btf_decoder, ivec2(j, {row} + o), 0) * {in}[j];
    float z = (s.x + s.y) + (s.z + s.w);
    {out}[o / 4][o % 4] = {value};
  }}
{bias_one})",
                     fmt::arg("n", n), fmt::arg("inputs", inputs), fmt::arg("outputs", outputs),
                     fmt::arg("act_note", hidden ? ", " + act : fmt::format(", linear (the first {} outputs)", used)),
                     fmt::arg("out", out), fmt::arg("in", in), fmt::arg("used", used), fmt::arg("in4", (inputs + 4) / 4),
                     fmt::arg("row", row), fmt::arg("value", hidden ? "btf_act(z)" : "z"),
                     fmt::arg("bias_one", hidden ? fmt::format("  {}[{}][{}] = 1.0;\n", out, outputs / 4, outputs % 4) : ""));
}

}  // namespace

std::string NeuralGlsl(const nlohmann::json& j) {
  const auto& lat = j.at("latents");
  const auto& dec = j.at("decoder");
  const auto& enc = j.at("encoding");
  const int W = j.at("texture").at("width"), H = j.at("texture").at("height"), C = j.at("texture").at("channels");
  const int c = lat.at("count"), layers = lat.at("layers"), fourier = enc.at("fourier");
  const bool half_vector = enc.at("half_vector"), u8 = lat.at("storage") == "u8";
  const bool log = j.at("output").at("transform") == "log";
  int max4 = 0;
  std::string activation = "linear", body;
  const auto& ls = dec.at("layers");
  const int outputs_used = std::min(C, 3);
  for (std::size_t n = 0; n < ls.size(); ++n) {
    max4 = std::max({max4, (ls[n].at("inputs").get<int>() + 4) / 4, (ls[n].at("outputs").get<int>() + 4) / 4});
    if (n + 1 < ls.size()) activation = ls[n].at("activation");
    body += LayerGlsl(ls[n], int(n), outputs_used, n % 2 ? "btf_b" : "btf_a", n % 2 ? "btf_a" : "btf_b");
  }
  const std::string last = ls.size() % 2 ? "btf_b" : "btf_a";
  const std::string constants =
      u8 ? LatentConstant("BTF_LATENT_SCALE", lat.at("scale").get<std::vector<float>>(), layers) +
               LatentConstant("BTF_LATENT_BIAS", lat.at("bias").get<std::vector<float>>(), layers)
         : std::string();
  const std::string fetch = u8 ? "BTF_LATENT_BIAS[g] + BTF_LATENT_SCALE[g] * round(255.0 * t)" : "t";
  // The direction encoding after the latents (overwriting the padding of the last latent layer),
  // at constant indices.
  const auto set = [](int i, const std::string& v) { return fmt::format("  btf_a[{}].{} = {};\n", i / 4, "xyzw"[i % 4], v); };
  std::string encode = set(c, "wi.x") + set(c + 1, "wi.y") + set(c + 2, "wo.x") + set(c + 3, "wo.y");
  int k = c + 4;
  if (half_vector) {
    encode += "  vec3 h = wi + wo;\n  float h2 = dot(h, h);\n  h *= h2 > 1e-24 ? inversesqrt(h2) : 0.0;\n";
    encode += set(k, "h.x") + set(k + 1, "h.y");
    k += 2;
  }
  if (fourier > 0) encode += "  vec4 base = vec4(wi.xy, wo.xy);\n  vec2 sc;\n";
  for (int f = 0; f < fourier; ++f)
    for (int b = 0; b < 4; ++b) {
      encode += fmt::format("  sc = btf_sincos_pi({:.1f} * base.{});\n", double(1 << f), "xyzw"[b]);
      encode += set(k, "sc.x") + set(k + 1, "sc.y");
      k += 2;
    }
  encode += set(k, "1.0");  // the bias input
  const std::string result = C == 1 ? "vec3(v.x)" : C == 2 ? "vec3(v.xy, 0.0)" : "v";
  return fmt::format(R"(// btf_neural.glsl: generated by libbtf for one export ({format} {version}, layout neural-mlp;
// docs/viewer.md). vec3 btf_eval(vec2 uv, vec3 wi, vec3 wo) evaluates the codec's decoder as the C++
// reference decoder (libbtf/export/neural_reference_decoder.h) does, in float32: nearest texel for
// uv (period 1, v up) and its latents, the direction encoding of wi (light) and wo (view) in the
// local frame (z = normal, x = texture u, y = texture v; normalised here), the MLP, then
// {value_formula}. Returns the value in the export's units ({units}); for 1 channel the value is
// replicated.
// Bind (all from the export folder, rows uploaded in file order, no flip):
//   btf_latents  2D texture array {W} x {H} x {layers} of {latents_file} ({webgl}), NEAREST
//   btf_decoder  2D RGBA32F texture {TW} x {TH}: texel (j, first_row_n + o) = decoder.f32 layer n's row o,
//                values 4j .. 4j + 3, zero-padded (manifest decoder.layers), NEAREST
precision highp float;
precision highp int;

const int BTF_WIDTH = {W};
const int BTF_HEIGHT = {H};
const int BTF_LATENT = {c};
const int BTF_LATENT_LAYERS = {layers};
const int BTF_MAX4 = {max4};  // vec4s of the widest layer's values, its bias input 1 included
const float BTF_EPSILON = {epsilon:.9g};
const float BTF_PI = 3.14159265358979;
{constants}
uniform highp sampler2DArray btf_latents;
uniform highp sampler2D btf_decoder;

float btf_act(float z) {{ return {act}; }}  // {act_name}

// (sin, cos) of pi m without GLSL's sin and cos, whose precision ES 3.00 leaves open (SwiftShader's
// moved the decoder outputs by 4e-4): m = q / 2 + t with q an integer and t in [-1/4, 1/4] (exact
// in float32), Taylor polynomials of sin and cos of pi t (truncation below 2e-9), then the
// quarter turns q mod 4.
vec2 btf_sincos_pi(float m) {{
  float q = floor(2.0 * m + 0.5);
  float x = BTF_PI * (m - 0.5 * q), x2 = x * x;
  float s = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362880.0)))));
  float c = 1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40320.0 + x2 * (-1.0 / 3628800.0)))));
  int k = int(q - 4.0 * floor(0.25 * q));
  return k == 0 ? vec2(s, c) : k == 1 ? vec2(c, -s) : k == 2 ? vec2(-s, -c) : vec2(-c, s);
}}

vec3 btf_eval(vec2 uv, vec3 wi, vec3 wo) {{
  vec2 f = uv - floor(uv);
  int x = min(int(f.x * float(BTF_WIDTH)), BTF_WIDTH - 1);
  int y = min(int((1.0 - f.y) * float(BTF_HEIGHT)), BTF_HEIGHT - 1);
  wi = normalize(wi);
  wo = normalize(wo);
  vec4 btf_a[BTF_MAX4], btf_b[BTF_MAX4];
  for (int i = 0; i < BTF_MAX4; ++i) btf_a[i] = vec4(0.0);
  for (int g = 0; g < BTF_LATENT_LAYERS; ++g) {{
    vec4 t = texelFetch(btf_latents, ivec3(x, y, g), 0);
    btf_a[g] = {fetch};
  }}
  // The direction encoding, then the 1 that multiplies the biases.
{encode}{body}  vec3 v = {last}[0].xyz;
  v = {transform};
  return {result};
}}
)",
                     fmt::arg("format", j.at("format").get<std::string>()),
                     fmt::arg("version", j.at("format_version").get<std::string>()),
                     fmt::arg("value_formula", log ? "exp(y) - epsilon" : "y (no output transform)"),
                     fmt::arg("units", j.at("values").at("units").get<std::string>()), fmt::arg("W", W), fmt::arg("H", H),
                     fmt::arg("layers", layers), fmt::arg("latents_file", lat.at("file").get<std::string>()),
                     fmt::arg("webgl", lat.at("webgl_format").get<std::string>()),
                     fmt::arg("TW", dec.at("texture").at("width").get<int>()),
                     fmt::arg("TH", dec.at("texture").at("height").get<int>()), fmt::arg("c", c), fmt::arg("max4", max4),
                     fmt::arg("epsilon", j.at("output").at("epsilon").get<double>()), fmt::arg("constants", constants),
                     fmt::arg("act", ActivationGlsl(activation == "linear" ? "relu" : activation)),
                     fmt::arg("act_name", activation == "linear" ? "unused: no hidden layer" : activation),
                     fmt::arg("fetch", fetch), fmt::arg("encode", encode),
                     fmt::arg("body", body), fmt::arg("last", last),
                     fmt::arg("transform", log ? "exp(v) - BTF_EPSILON" : "v"), fmt::arg("result", result));
}

}  // namespace btf
