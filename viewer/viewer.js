// libbtf WebGL2 viewer (docs/viewer.md): loads a renderer export (/export/manifest.json and its
// files, btf_schneider.glsl, btf_sattler.glsl or btf_neural.glsl included) and draws a plane or a cylinder under a point light or a
// sampled sky. The surface point of each pixel is the analytic intersection of the pixel's ray
// (camera -> rasterised proxy fragment) with the shape, as in the CPU renderer
// (libbtf/eval/render.cpp), so both draw the same (uv, wi, wo) per pixel: the ray is built from
// gl_FragCoord and the camera's basis exactly as the CPU's Camera::Ray, not from the rasterised
// position (whose interpolation differs by a fraction of a pixel).
// ?export=DIR/ loads the export from that folder below the page instead.
// Modes (?mode=): view (interactive), shot (one frame -> PNG data URL), eval (btf_eval at the
// queries in /job/queries.f32 -> float results), bench (ms per frame).
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const params = new URLSearchParams(location.search);
const mode = params.get('mode') || 'view';
const status = (window.btfStatus = { done: false, error: null, result: null });

async function fetchJson(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`cannot load ${url}: ${r.status}`);
  return r.json();
}
async function fetchBytes(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`cannot load ${url}: ${r.status}`);
  return r.arrayBuffer();
}
async function fetchText(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`cannot load ${url}: ${r.status}`);
  return r.text();
}

// The default scene: what btf-eval render-web --scene patch-point writes (libbtf/web/scene.cpp).
const defaultScene = {
  shape: 'patch', lighting: 'point', width: 960, height: 640, tiles: 3, cylinder_radius: 0.6,
  camera: { position: [0, -3.2, 2.6], target: [0, 0, 0], up: [0, 0, 1], fov_y_deg: 32 },
  light: { position: [1.2, -1.4, 2.6], intensity: 10.2 }, background: 0.02, exposure: 1,
  environment: { directions: [], radiance_solid_angle: [] }, max_taps: 4,
};

// Export textures (docs/viewer.md, "Binding the textures"): layout schneider-2004 (LPCA, a 3D
// atlas), sattler-2003 (pca-view, a 2D texture array of per-view images) or neural-mlp (neural:
// a 2D texture array of latents and a texture of decoder weights).
async function loadExport(base) {
  const m = await fetchJson(`${base}manifest.json`);
  if (m.format !== 'libbtf-schneider-export' || !String(m.format_version).startsWith('2.'))
    throw new Error(`unsupported export: ${m.format} ${m.format_version} (the viewer reads 2.x)`);
  const layout = m.layout || 'schneider-2004';
  if (layout === 'sattler-2003') return loadSattler(base, m);
  if (layout === 'neural-mlp') return loadNeural(base, m);
  if (layout !== 'schneider-2004') throw new Error(`unsupported export layout '${layout}'`);
  const a = m.atlas, W = m.texture.width, H = m.texture.height, C = m.texture.channels;
  const F = m.functions.count_per_cluster, NT = F + 1, NT4 = Math.ceil(NT / 4);
  const perPage = a.depth * a.height * a.width;
  const src = await loadValues(base, a.file, a.storage, a.pages * perPage * C);
  const pages = [];
  for (let p = 0; p < a.pages; ++p) {
    const t = new THREE.Data3DTexture(rgba(src, p * perPage, perPage, C, a.storage), a.width, a.height, a.depth);
    t.minFilter = t.magFilter = THREE.LinearFilter;
    t.wrapR = THREE.ClampToEdgeWrapping;
    pages.push(valueTexture(t, a.storage));
  }
  const termsTex = termsTexture(await fetchBytes(base + m.terms.file), m.terms.file, W * H, NT, W, H);
  const idx = new Uint16Array(await fetchBytes(base + m.cluster_index.file));
  const clusterTex = dataTexture(Float32Array.from(idx), W, H, THREE.RedFormat);
  const glsl = await fetchText(base + m.glsl.file);
  const uniforms = { btf_terms: { value: termsTex }, btf_cluster: { value: clusterTex } };
  pages.forEach((t, p) => (uniforms[p === 0 ? 'btf_atlas' : `btf_atlas${p}`] = { value: t }));
  const info = `${m.scale_bias.shape[0]} clusters x ${F} functions, atlas ${a.width}x${a.height}x${a.depth} ${a.storage}`;
  return { manifest: m, glsl, uniforms, info };
}

async function loadSattler(base, m) {
  const im = m.images, C = m.texture.channels, F = m.functions.count_per_view, NT = F + 1;
  const n = im.layers * im.height * im.width;
  const src = await loadValues(base, im.file, im.storage, n * C);
  const t = new THREE.DataArrayTexture(rgba(src, 0, n, C, im.storage), im.width, im.height, im.layers);
  t.minFilter = t.magFilter = THREE.NearestFilter;
  const V = m.views.count, L = m.lights.count;
  const termsTex = termsTexture(await fetchBytes(base + m.terms.file), m.terms.file, V * L, NT, L, V);
  const glsl = await fetchText(base + m.glsl.file);
  const info = `${V} views x ${F} images, ${L} lights, texture array ${im.width}x${im.height}x${im.layers} ${im.storage}`;
  return { manifest: m, glsl, uniforms: { btf_images: { value: valueTexture(t, im.storage) }, btf_terms: { value: termsTex } }, info };
}

// neural-mlp: latents.u8 / latents.f16 ([layers][H][W][4], already RGBA) as a 2D texture array,
// decoder.f32 as an RGBA32F texture with one row per neuron (its weights, then its bias).
async function loadNeural(base, m) {
  const lt = m.latents, W = m.texture.width, H = m.texture.height, dec = m.decoder;
  const src = await loadValues(base, lt.file, lt.storage, lt.layers * H * W * 4);
  const t = new THREE.DataArrayTexture(src, W, H, lt.layers);
  t.minFilter = t.magFilter = THREE.NearestFilter;
  const weights = new Float32Array(await fetchBytes(base + dec.file));
  if (weights.length !== dec.parameters) throw new Error(`${dec.file}: ${weights.length} values, expected ${dec.parameters}`);
  const TW = dec.texture.width, TH = dec.texture.height, data = new Float32Array(TW * TH * 4);
  for (const l of dec.layers)
    for (let o = 0; o < l.outputs; ++o)
      data.set(weights.subarray(l.offset + o * (l.inputs + 1), l.offset + (o + 1) * (l.inputs + 1)), (l.first_row + o) * TW * 4);
  const glsl = await fetchText(base + m.glsl.file);
  const hidden = dec.layers.slice(0, -1).map((l) => l.outputs).join(',') || '-';
  const info = `${lt.count} latents (${lt.storage}), decoder ${dec.inputs} -> ${hidden} -> ${m.texture.channels} (${dec.parameters} parameters)`;
  return { manifest: m, glsl, info,
           uniforms: { btf_latents: { value: valueTexture(t, lt.storage) }, btf_decoder: { value: dataTexture(data, TW, TH, THREE.RGBAFormat) } } };
}

async function loadValues(base, file, storage, count) {
  const raw = await fetchBytes(base + file);
  const src = storage === 'f16' ? new Uint16Array(raw) : new Uint8Array(raw);
  if (src.length !== count) throw new Error(`${file}: ${src.length} values, expected ${count}`);
  return src;
}

// n texels of C channels from `first` as RGBA (alpha unused): three.js uploads RGBA8 / RGBA16F;
// the values are those of the file (1 channel replicated).
function rgba(src, first, n, C, storage) {
  const half = storage === 'f16';
  const data = half ? new Uint16Array(n * 4) : new Uint8Array(n * 4);
  for (let i = 0; i < n; ++i)
    for (let c = 0; c < 4; ++c) data[i * 4 + c] = c < C ? src[(first + i) * C + c] : (c === 3 ? (half ? 0x3c00 : 255) : src[(first + i) * C]);
  return data;
}

function valueTexture(t, storage) {
  t.format = THREE.RGBAFormat;
  t.type = storage === 'f16' ? THREE.HalfFloatType : THREE.UnsignedByteType;
  t.wrapS = t.wrapT = THREE.ClampToEdgeWrapping;
  t.generateMipmaps = false;
  t.unpackAlignment = 1;
  t.colorSpace = THREE.NoColorSpace;
  t.needsUpdate = true;
  return t;
}

// terms.f32 ([rows][cols][NT] floats) as an RGBA32F texture (cols * ceil(NT / 4)) x rows, zero-padded.
function termsTexture(raw, file, count, NT, cols, rows) {
  const terms = new Float32Array(raw), NT4 = Math.ceil(NT / 4);
  if (terms.length !== count * NT) throw new Error(`${file}: ${terms.length} values, expected ${count * NT}`);
  const data = new Float32Array(cols * NT4 * 4 * rows);
  for (let t = 0; t < count; ++t) for (let j = 0; j < NT; ++j) data[t * NT4 * 4 + j] = terms[t * NT + j];
  return dataTexture(data, cols * NT4, rows, THREE.RGBAFormat);
}

function dataTexture(data, w, h, format) {
  const t = new THREE.DataTexture(data, w, h, format, THREE.FloatType);
  t.minFilter = t.magFilter = THREE.NearestFilter;
  t.generateMipmaps = false;
  t.colorSpace = THREE.NoColorSpace;
  t.needsUpdate = true;
  return t;
}

const vertexShader = `
precision highp float;
in vec3 position, normal, tangent;
in vec2 uv;
uniform mat4 modelMatrix, viewMatrix, projectionMatrix;
out vec3 vWorld, vNormal, vTangent;
out vec2 vUv;
void main() {
  vec4 w = modelMatrix * vec4(position, 1.0);
  vWorld = w.xyz;
  vNormal = mat3(modelMatrix) * normal;
  vTangent = mat3(modelMatrix) * tangent;
  vUv = uv;
  gl_Position = projectionMatrix * viewMatrix * w;
}`;

function sceneFragmentShader(glsl) {
  return `${glsl}
in vec3 vWorld, vNormal, vTangent;
in vec2 vUv;
uniform vec3 camPos, camForward, camRight, camUp;
uniform float tanHalf;
uniform vec2 viewport;
uniform int shape;         // 0 = patch, 1 = cylinder (both analytic), 2 = draped cloth (the mesh itself)
uniform int lighting;      // 0 = point, 1 = environment
uniform float tiles, radius, lightIntensity, exposure, background;
uniform vec2 texSize;      // the export's texels per tile (W, H)
uniform int maxTaps;       // the footprint filter's largest tap count per axis (1 = nearest texel only)
uniform vec3 lightPos;
uniform bool cosIncluded;
uniform highp sampler2D envTex;  // row 0: directions, row 1: radiance * solid angle
uniform int envCount;
out vec4 fragColor;

bool hitShape(vec3 o, vec3 d, out vec3 p, out vec3 n, out vec3 tu, out vec3 tv, out vec2 uv) {
  if (shape == 0) {
    if (abs(d.z) < 1e-12) return false;
    float t = -o.z / d.z;
    if (t <= 0.0) return false;
    p = o + t * d;
    if (abs(p.x) > 1.0 || abs(p.y) > 1.0) return false;
    n = vec3(0, 0, 1); tu = vec3(1, 0, 0); tv = vec3(0, 1, 0);
    uv = vec2((p.x + 1.0) / 2.0 * tiles, (p.y + 1.0) / 2.0 * tiles);
    return true;
  }
  float a = d.y * d.y + d.z * d.z, b = 2.0 * (o.y * d.y + o.z * d.z), c = o.y * o.y + o.z * o.z - radius * radius;
  float disc = b * b - 4.0 * a * c;
  if (a < 1e-12 || disc < 0.0) return false;
  float q = sqrt(disc);
  for (int i = 0; i < 2; ++i) {
    float t = i == 0 ? (-b - q) / (2.0 * a) : (-b + q) / (2.0 * a);
    if (t <= 0.0) continue;
    p = o + t * d;
    if (abs(p.x) > 1.0) continue;
    float phi = atan(p.y, p.z);
    n = vec3(0, sin(phi), cos(phi)); tu = vec3(1, 0, 0); tv = vec3(0, cos(phi), -sin(phi));
    float around = tiles * (2.0 * BTF_PI * radius) / 2.0;
    uv = vec2((p.x + 1.0) / 2.0 * tiles, (phi / (2.0 * BTF_PI) + 0.5) * around);
    return true;
  }
  return false;
}

// Radiance towards the camera at texture position uv: the point light or the sky's samples.
vec3 shade(vec2 uv, vec3 p, vec3 tu, vec3 tv, vec3 n, vec3 wo) {
  vec3 L = vec3(0.0);
  if (lighting == 0) {
    vec3 tl = lightPos - p;
    float r2 = dot(tl, tl);
    vec3 l = tl / sqrt(r2);
    vec3 wi = vec3(dot(l, tu), dot(l, tv), dot(l, n));
    if (wi.z > 0.0 && wo.z > 0.0) L += btf_eval(uv, wi, wo) * (cosIncluded ? 1.0 : wi.z) * lightIntensity / r2;
  } else {
    for (int i = 0; i < envCount; ++i) {
      vec3 e = texelFetch(envTex, ivec2(i, 0), 0).xyz;
      vec3 wi = vec3(dot(e, tu), dot(e, tv), dot(e, n));
      if (wi.z <= 0.0 || wo.z <= 0.0) continue;
      L += btf_eval(uv, wi, wo) * (cosIncluded ? 1.0 : wi.z) * texelFetch(envTex, ivec2(i, 1), 0).rgb;
    }
  }
  return L;
}

// uv at the surface point seen through the pixel offset by (dx, dy) pixels: the offset ray meets
// the tangent plane at p (a ray differential); the texture scale is tiles / 2 per unit of length
// on the plane, along the cylinder and around it.
vec2 uvOffset(vec3 o, vec3 p, vec3 n, vec3 tu, vec3 tv, vec2 s, vec2 ds) {
  vec3 d = normalize(camForward + (s.x + ds.x) * camRight + (s.y + ds.y) * camUp);
  float dn = dot(d, n);
  if (abs(dn) < 1e-6) return vec2(1e6);
  vec3 q = o + dot(p - o, n) / dn * d;
  return 0.5 * tiles * vec2(dot(q - p, tu), dot(q - p, tv));
}

float srgb(float v) {
  v = clamp(v, 0.0, 1.0);
  return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}

void main() {
  vec2 s = (2.0 * gl_FragCoord.xy / viewport - 1.0) * tanHalf * vec2(viewport.x / viewport.y, 1.0);
  vec3 o = camPos, d = normalize(camForward + s.x * camRight + s.y * camUp);
  vec3 p, n, tu, tv; vec2 uv, duvx, duvy;
  vec3 L = vec3(background);
  bool hit;
  if (shape == 2) {
    // The cloth mesh: its interpolated position, normal and u tangent (Gram-Schmidt), uv as meshed.
    p = vWorld;
    n = normalize(vNormal);
    if (!gl_FrontFacing) n = -n;
    tu = normalize(vTangent - n * dot(n, vTangent));
    tv = cross(n, tu);
    uv = vUv * tiles;
    hit = true;
    duvx = dFdx(uv);
    duvy = dFdy(uv);
  } else {
    hit = hitShape(o, d, p, n, tu, tv, uv);
    if (hit) {
      float px = 2.0 * tanHalf / viewport.y;  // one pixel in s
      duvx = uvOffset(o, p, n, tu, tv, s, vec2(px, 0.0));
      duvy = uvOffset(o, p, n, tu, tv, s, vec2(0.0, px));
    }
  }
  if (hit) {
    L = vec3(0.0);
    vec3 toCam = normalize(camPos - p);
    vec3 wo = vec3(dot(toCam, tu), dot(toCam, tv), dot(toCam, n));
    // The pixel's footprint in texels (the larger of its two edges): up to one texel, the nearest
    // texel at the pixel's uv, as the CPU renderer; beyond, the mean of N x N taps spread evenly
    // over the footprint parallelogram, N = ceil(footprint) up to maxTaps (the export's texels are
    // decoded one by one, so no mipmaps: docs/viewer.md, "Tiling and filtering").
    float footprint = max(length(duvx * texSize), length(duvy * texSize));
    int N = footprint <= 1.0 ? 1 : min(int(ceil(footprint)), maxTaps);
    if (N == 1) {
      L = shade(uv, p, tu, tv, n, wo);
    } else {
      for (int j = 0; j < N; ++j)
        for (int i = 0; i < N; ++i)
          L += shade(uv + ((float(i) + 0.5) / float(N) - 0.5) * duvx + ((float(j) + 0.5) / float(N) - 0.5) * duvy, p, tu, tv, n, wo);
      L /= float(N * N);
    }
  }
  L *= exposure;
  fragColor = vec4(srgb(L.r), srgb(L.g), srgb(L.b), 1.0);
}`;
}

function evalFragmentShader(glsl) {
  return `${glsl}
uniform highp sampler2D qUv, qWi, qWo;
out vec4 fragColor;
void main() {
  ivec2 c = ivec2(gl_FragCoord.xy);
  fragColor = vec4(btf_eval(texelFetch(qUv, c, 0).xy, texelFetch(qWi, c, 0).xyz, texelFetch(qWo, c, 0).xyz), 1.0);
}`;
}

function envTexture(env) {
  const N = Math.max(1, env.directions.length);
  const data = new Float32Array(N * 2 * 4);
  env.directions.forEach((dir, i) => data.set([...dir, 0], i * 4));
  env.radiance_solid_angle.forEach((rad, i) => data.set([...rad, 0], (N + i) * 4));
  return dataTexture(data, N, 2, THREE.RGBAFormat);
}

function srgbEncode(v) {
  v = Math.min(1, Math.max(0, v));
  return v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055;
}

function buildScene(exp, sc) {
  const uniforms = {
    ...exp.uniforms,
    camPos: { value: new THREE.Vector3() }, camForward: { value: new THREE.Vector3() }, camRight: { value: new THREE.Vector3() },
    camUp: { value: new THREE.Vector3() }, tanHalf: { value: 0 }, viewport: { value: new THREE.Vector2() }, shape: { value: sc.shape === 'cylinder' ? 1 : 0 },
    lighting: { value: sc.lighting === 'environment' ? 1 : 0 }, tiles: { value: sc.tiles },
    texSize: { value: new THREE.Vector2(exp.manifest.texture.width, exp.manifest.texture.height) },
    maxTaps: { value: sc.max_taps },
    radius: { value: sc.cylinder_radius }, lightIntensity: { value: sc.light.intensity },
    exposure: { value: sc.exposure }, background: { value: sc.background },
    lightPos: { value: new THREE.Vector3(...sc.light.position) },
    cosIncluded: { value: !!exp.manifest.values.cos_theta_i_included },
    envTex: { value: envTexture(sc.environment) }, envCount: { value: sc.environment.directions.length },
  };
  const material = new THREE.RawShaderMaterial({
    glslVersion: THREE.GLSL3, vertexShader, fragmentShader: sceneFragmentShader(exp.glsl), uniforms, side: THREE.DoubleSide,
  });
  // Proxies slightly larger than the analytic shapes: every pixel of the shape gets a fragment.
  const meshes = {
    cloth: new THREE.Mesh(clothGeometry(), material),
    patch: new THREE.Mesh(new THREE.PlaneGeometry(2.02, 2.02), material),
    cylinder: new THREE.Mesh(
      new THREE.CylinderGeometry(sc.cylinder_radius * 1.01, sc.cylinder_radius * 1.01, 2.02, 256, 1, true).rotateZ(-Math.PI / 2),
      material),
  };
  const scene = new THREE.Scene();
  scene.add(meshes.patch, meshes.cylinder, meshes.cloth);
  const setShape = (name) => {
    uniforms.shape.value = { patch: 0, cylinder: 1, cloth: 2 }[name] ?? 0;
    for (const [k, m] of Object.entries(meshes)) m.visible = k === (name in meshes ? name : 'patch');
  };
  setShape(sc.shape);
  return { scene, uniforms, setShape };
}

// A cloth draped over a ball: a 2.4 x 2.4 sheet (161 x 161 vertices) whose height falls off from
// the ball's top with radial folds; uv spans the sheet at the plane's texel size (1.2 repeats of
// `tiles` per 2.4 units), tangents along u from central differences of the positions.
function clothGeometry() {
  const n = 160, g = new THREE.PlaneGeometry(2.4, 2.4, n, n);
  const pos = g.attributes.position, uv = g.attributes.uv;
  for (let i = 0; i < pos.count; ++i) {
    const x = pos.getX(i), y = pos.getY(i), r = Math.hypot(x, y), phi = Math.atan2(y, x);
    const fold = 1 + 0.12 * Math.sin(7 * phi) * Math.min(1, Math.max(0, (r - 0.35) / 0.5));
    pos.setZ(i, 0.75 * Math.exp(-(r * r) / 0.45) * fold);
    uv.setXY(i, uv.getX(i) * 1.2, uv.getY(i) * 1.2);
  }
  g.computeVertexNormals();
  const tangent = new Float32Array(pos.count * 3);
  for (let row = 0; row <= n; ++row)
    for (let col = 0; col <= n; ++col) {
      const i = row * (n + 1) + col, a = row * (n + 1) + Math.max(0, col - 1), b = row * (n + 1) + Math.min(n, col + 1);
      const t = new THREE.Vector3(pos.getX(b) - pos.getX(a), pos.getY(b) - pos.getY(a), pos.getZ(b) - pos.getZ(a)).normalize();
      tangent.set([t.x, t.y, t.z], i * 3);
    }
  g.setAttribute('tangent', new THREE.BufferAttribute(tangent, 3));
  return g;
}

function makeCamera(sc) {
  const cam = new THREE.PerspectiveCamera(sc.camera.fov_y_deg, sc.width / sc.height, 0.05, 100);
  cam.up.set(...sc.camera.up);
  cam.position.set(...sc.camera.position);
  cam.lookAt(new THREE.Vector3(...sc.camera.target));
  cam.updateMatrixWorld();
  return cam;
}

function makeRenderer(canvas, w, h) {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true, alpha: false });
  renderer.setPixelRatio(1);
  renderer.setSize(w, h, false);
  renderer.autoClear = false;
  return renderer;
}

function draw(renderer, view, cam, sc) {
  const gl = renderer.getContext();
  renderer.setRenderTarget(null);
  const bg = srgbEncode(sc.background * view.uniforms.exposure.value);
  // The background radiance, tone-mapped like the shape (three.js's clear colour would be colour-managed).
  gl.clearColor(bg, bg, bg, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  // The camera basis as the CPU renderer builds it: forward, right = forward x world up, up = right x forward.
  cam.updateMatrixWorld();
  const u = view.uniforms, fwd = new THREE.Vector3();
  cam.getWorldDirection(fwd);
  u.camPos.value.copy(cam.position);
  u.camForward.value.copy(fwd);
  u.camRight.value.crossVectors(fwd, cam.up).normalize();
  u.camUp.value.crossVectors(u.camRight.value, fwd);
  u.tanHalf.value = Math.tan((cam.fov * Math.PI) / 360);
  const size = new THREE.Vector2();
  renderer.getDrawingBufferSize(size);
  u.viewport.value.copy(size);
  renderer.render(view.scene, cam);
}

// Waits until the GPU has finished: a 1-pixel read back.
function finish(renderer) {
  const gl = renderer.getContext();
  const px = new Uint8Array(4);
  gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
}

async function main() {
  if (mode !== 'view') document.body.classList.add('headless');
  // ?export=DIR/ (a relative folder below the page, as btf-eval sweep --viewer links it), else /export/.
  const dir = params.get('export') || 'export/';
  if (!/^[A-Za-z0-9_.=,+-]+(\/[A-Za-z0-9_.=,+-]+)*\/$/.test(dir) || dir.split('/').includes('..'))
    throw new Error(`export=${dir}: give a relative folder below the page, ending in /`);
  const exp = await loadExport(`./${dir}`);
  const sc = params.get('job') || mode !== 'view' ? { ...defaultScene, ...(await fetchJson('./job/scene.json')) } : { ...defaultScene };
  if (mode === 'view') sc.width = innerWidth, sc.height = innerHeight;
  const canvas = document.getElementById('view');
  canvas.width = sc.width;
  canvas.height = sc.height;
  const renderer = makeRenderer(canvas, sc.width, sc.height);
  if (!renderer.capabilities.isWebGL2) throw new Error('WebGL2 is needed');
  if (mode === 'eval') return evalQueries(renderer, exp);
  const view = buildScene(exp, sc);
  const cam = makeCamera(sc);
  if (mode === 'shot') {
    draw(renderer, view, cam, sc);
    finish(renderer);
    status.result = { png: canvas.toDataURL('image/png'), width: sc.width, height: sc.height, renderer: glRendererName(renderer) };
    return;
  }
  if (mode === 'bench') {
    const frames = Number(params.get('frames') || 10);
    draw(renderer, view, cam, sc);  // compile and upload outside the timing
    finish(renderer);
    const ms = [];
    for (let i = 0; i < frames; ++i) {
      const t0 = performance.now();
      draw(renderer, view, cam, sc);
      finish(renderer);
      ms.push(performance.now() - t0);
    }
    ms.sort((a, b) => a - b);
    status.result = { frames, median_ms: ms[Math.floor(frames / 2)], min_ms: ms[0], max_ms: ms[frames - 1],
                      renderer: glRendererName(renderer) };
    return;
  }
  interactive(renderer, view, cam, sc, exp);
}

// The light's and the camera's directions at the object's reference point (the plane's centre, the
// cylinder's and the cloth's top, where the normal is z and the frame's u and v are x and y), as
// polar angle theta from the normal and azimuth phi from u, in degrees.
export function anglesText(shape, lighting, light, camera, radius) {
  const top = { patch: 0, cylinder: radius, cloth: 0.75 }[shape] ?? 0;
  const polar = (q) => {
    const v = new THREE.Vector3(q.x, q.y, q.z - top).normalize();
    const theta = (Math.acos(Math.min(1, Math.max(-1, v.z))) * 180) / Math.PI, phi = (Math.atan2(v.y, v.x) * 180) / Math.PI;
    return `theta ${theta.toFixed(1)}\u00b0 phi ${phi.toFixed(1)}\u00b0`;
  };
  const where = { patch: "the plane's centre", cylinder: "the cylinder's top", cloth: "the cloth's top" }[shape] ?? 'the centre';
  return `light ${lighting === 'environment' ? 'sky' : polar(light)}; camera ${polar(camera)} (at ${where})`;
}

function glRendererName(renderer) {
  const gl = renderer.getContext();
  const ext = gl.getExtension('WEBGL_debug_renderer_info');
  return ext ? gl.getParameter(ext.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
}

function evalQueries(renderer, exp) {
  return (async () => {
    const q = new Float32Array(await fetchBytes('./job/queries.f32'));  // [N][8]: u v wi(3) wo(3)
    const N = q.length / 8, QW = Math.min(N, 256), QH = Math.ceil(N / QW);
    const uv = new Float32Array(QW * QH * 4), wi = new Float32Array(QW * QH * 4), wo = new Float32Array(QW * QH * 4);
    for (let i = 0; i < N; ++i) {
      uv.set([q[i * 8], q[i * 8 + 1], 0, 0], i * 4);
      wi.set([q[i * 8 + 2], q[i * 8 + 3], q[i * 8 + 4], 0], i * 4);
      wo.set([q[i * 8 + 5], q[i * 8 + 6], q[i * 8 + 7], 0], i * 4);
    }
    const target = new THREE.WebGLRenderTarget(QW, QH, { type: THREE.FloatType, format: THREE.RGBAFormat,
                                                         minFilter: THREE.NearestFilter, magFilter: THREE.NearestFilter, depthBuffer: false });
    const material = new THREE.RawShaderMaterial({
      glslVersion: THREE.GLSL3,
      vertexShader: 'in vec3 position; void main() { gl_Position = vec4(position.xy, 0.0, 1.0); }',
      fragmentShader: evalFragmentShader(exp.glsl),
      uniforms: { ...exp.uniforms, qUv: { value: dataTexture(uv, QW, QH, THREE.RGBAFormat) },
                  qWi: { value: dataTexture(wi, QW, QH, THREE.RGBAFormat) }, qWo: { value: dataTexture(wo, QW, QH, THREE.RGBAFormat) } },
    });
    const quad = new THREE.Mesh(new THREE.PlaneGeometry(2, 2), material);
    quad.frustumCulled = false;
    const scene = new THREE.Scene();
    scene.add(quad);
    renderer.setRenderTarget(target);
    renderer.render(scene, new THREE.Camera());
    const out = new Float32Array(QW * QH * 4);
    renderer.readRenderTargetPixels(target, 0, 0, QW, QH, out);
    renderer.setRenderTarget(null);
    const values = new Array(N * 3);
    for (let i = 0; i < N; ++i) for (let c = 0; c < 3; ++c) values[i * 3 + c] = out[i * 4 + c];
    status.result = { count: N, values, renderer: glRendererName(renderer) };
  })();
}

function interactive(renderer, view, cam, sc, exp) {
  let dirty = true, avg = null;
  const controls = new OrbitControls(cam, renderer.domElement);
  controls.target.set(...sc.camera.target);
  controls.update();
  const light = new THREE.Vector3(...sc.light.position);
  let dragging = null;
  renderer.domElement.addEventListener('contextmenu', (e) => e.preventDefault());
  renderer.domElement.addEventListener('pointerdown', (e) => {
    if (e.shiftKey || e.button === 2) { dragging = { x: e.clientX, y: e.clientY }; controls.enabled = false; }
  });
  addEventListener('pointerup', () => { dragging = null; controls.enabled = true; });
  addEventListener('pointermove', (e) => {
    if (!dragging) return;
    // Light on a sphere around the origin: horizontal drag = azimuth, vertical = elevation (z up).
    const dx = e.clientX - dragging.x, dy = e.clientY - dragging.y;
    dragging = { x: e.clientX, y: e.clientY };
    const r = light.length(), az = Math.atan2(light.y, light.x) - dx * 0.01;
    const el = Math.min(Math.PI / 2 - 0.01, Math.max(0.02, Math.asin(light.z / r) + dy * 0.01));
    light.set(r * Math.cos(el) * Math.cos(az), r * Math.cos(el) * Math.sin(az), r * Math.sin(el));
    view.uniforms.lightPos.value.copy(light);
    dirty = true;
  });
  controls.addEventListener('change', () => (dirty = true));
  const sceneSel = document.getElementById('scene'), lightSel = document.getElementById('lighting');
  sceneSel.value = sc.shape;
  lightSel.value = sc.lighting;
  sceneSel.onchange = () => { view.setShape(sceneSel.value); dirty = true; };
  lightSel.onchange = () => { view.uniforms.lighting.value = lightSel.value === 'environment' ? 1 : 0; dirty = true; };
  const u = view.uniforms, m = exp.manifest, W = m.texture.width, H = m.texture.height;
  const on = (el, f) => { el.addEventListener('input', f); el.addEventListener('change', f); f(); };
  // Exposure: a slider in stops (log2) around the start exposure (--exposure).
  const e0 = sc.exposure, expIn = document.getElementById('exposure');
  on(expIn, () => {
    const stops = Number(expIn.value);
    u.exposure.value = e0 * 2 ** stops;
    document.getElementById('exposure-value').textContent =
      `x${u.exposure.value.toPrecision(3)} (${stops >= 0 ? '+' : ''}${stops.toFixed(1)} stops from ${e0.toPrecision(3)})`;
    dirty = true;
  });
  // Tiling: texture repeats along each side of the plane (the CPU renderer's `tiles`); the cylinder
  // and the cloth at the same texel size.
  const tilesIn = document.getElementById('tiles');
  tilesIn.value = String(sc.tiles);
  on(tilesIn, () => {
    const r = Number(tilesIn.value);
    if (!(Number.isFinite(r) && r > 0 && r <= 1000)) return;
    u.tiles.value = r;
    document.getElementById('tile-value').textContent =
      `tile ${W} x ${H} texels = 1/${r.toPrecision(3)} of the plane's side (${Math.round(r * W)} texels across the plane)`;
    dirty = true;
  });
  const tapsSel = document.getElementById('taps');
  if (![...tapsSel.options].some((o) => o.value === String(sc.max_taps))) tapsSel.add(new Option(`<= ${sc.max_taps}x${sc.max_taps}`, String(sc.max_taps)));
  tapsSel.value = String(sc.max_taps);
  on(tapsSel, () => { u.maxTaps.value = Number(tapsSel.value); dirty = true; });
  const anglesEl = document.getElementById('angles');
  addEventListener('resize', () => {
    renderer.setSize(innerWidth, innerHeight, false);
    cam.aspect = innerWidth / innerHeight;
    cam.updateProjectionMatrix();
    dirty = true;
  });
  document.getElementById('info').textContent =
    `${m.texture.width}x${m.texture.height} texels, ${exp.info}; ${glRendererName(renderer)}`;
  const msEl = document.getElementById('ms');
  const frame = () => {
    if (dirty) {
      dirty = false;
      const t0 = performance.now();
      draw(renderer, view, cam, sc);
      finish(renderer);
      const ms = performance.now() - t0;
      avg = avg === null ? ms : 0.8 * avg + 0.2 * ms;
      msEl.textContent = `${avg.toFixed(1)} ms/frame (${renderer.domElement.width}x${renderer.domElement.height})`;
      anglesEl.textContent = anglesText(sceneSel.value, lightSel.value, light, cam.position, sc.cylinder_radius);
      status.frames = (status.frames || 0) + 1;
    }
    status.pending = dirty;
    requestAnimationFrame(frame);
  };
  frame();
  status.result = { interactive: true, renderer: glRendererName(renderer) };
}

main().then(() => (status.done = true), (e) => { status.error = String(e && e.stack || e); status.done = true;
  const info = document.getElementById('info'); if (info) info.textContent = `error: ${e.message}`; });
