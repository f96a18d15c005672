"""Tests of the Python module libbtf (docs/python.md) on btf-synth data.

Run by ctest as `python` (tests/CMakeLists.txt) with PYTHONPATH=<build>/python and
BTF_TOOLS_DIR=<build>/bin. The C++ side every binding is checked against is the tools: btf-synth
makes the ground truth, btf-compress / btf-compress decode / btf-eval compare / btf-info / btf-convert
run the same library code from the command line.
"""
import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

import libbtf

TOOLS = os.environ.get("BTF_TOOLS_DIR", "")
# A small twill BTF: 4 bonn81 views x 5 lights x 8 x 8 texels x RGB.
VIEWS, LIGHTS, N = [0, 1, 7, 19], [0, 3, 9, 20, 40], 8


def tool(name, *args, check=True):
    r = subprocess.run([os.path.join(TOOLS, name), *map(str, args)], capture_output=True, text=True)
    if check and r.returncode != 0:
        raise AssertionError(f"{name} {' '.join(map(str, args))} exited {r.returncode}: {r.stderr}")
    return r


def tool_json(name, *args):
    return json.loads(tool(name, *args, "--json", "-q").stdout)


@pytest.fixture(scope="session")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("libbtf")
    gt = d / "gt.h5"
    tool("btf-synth", "btf", "--model", "irawan2006", "--preset", "twill", "--directions", "bonn81",
         "--views", ",".join(map(str, VIEWS)), "--lights", ",".join(map(str, LIGHTS)), "--resolution", N,
         "--samples", 2, "-q", "-o", gt)
    # pca-view with lights - 1 components keeps every component of each view slot: lossless up to
    # float rounding. lpca with few components is lossy, so decoders are tested on a real codec.
    pca, lpca = d / "pca.h5", d / "lpca.h5"
    libbtf.compress(gt, pca, method="pca-view", components=len(LIGHTS) - 1)
    lpca_summary = libbtf.compress(gt, lpca, method="lpca", clusters=2, components=3)
    decoded = d / "lpca_decoded.h5"
    tool("btf-compress", "decode", lpca, "-o", decoded, "-q")  # the C++ decoder, into a dataset file
    return dict(dir=d, gt=gt, pca=pca, lpca=lpca, lpca_summary=lpca_summary, decoded=decoded)


def test_version_matches_the_tools():
    assert tool("btf-info", "--version").stdout.split() == ["btf-info", libbtf.__version__]


def test_shape_samplings_and_conventions(data):
    for key in ("gt", "pca", "lpca"):
        src = libbtf.open(data[key])
        assert src.shape == (len(VIEWS), len(LIGHTS), N, N, 3)
        assert src.format == ("libbtf-dataset" if key == "gt" else "libbtf-codec")
        assert src.is_codec == (key != "gt")
        for sampling, idx in ((src.views, VIEWS), (src.lights, LIGHTS)):
            dirs, ang = sampling["directions"], sampling["angles"]
            assert "bonn81" in sampling["name"]
            assert dirs.shape == (len(idx), 3) and ang.shape == (len(idx), 2)
            np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1, atol=1e-12)
            # docs/conventions.md: direction = (sin t cos p, sin t sin p, cos t).
            np.testing.assert_allclose(np.cos(ang[:, 0]), dirs[:, 2], atol=1e-12)
        # btf-synth's conventions (docs/btf-synth.md): BRDF in 1/sr without cos, linear sRGB, a 4 mm tile over N texels.
        c = src.conventions
        assert c["units"] == "brdf_per_sr" and c["color_space"] == "linear_srgb"
        assert c["cos_theta_i_included"] is False and c["channel_names"] == ["R", "G", "B"]
        assert c["texel_size_mm"] == pytest.approx(4.0 / N)
        assert isinstance(c["provenance"], dict)
    # The views sampled are bonn81 entries 0, 1, 7, 19: the first is the pole.
    np.testing.assert_allclose(libbtf.open(data["gt"]).views["directions"][0], [0, 0, 1], atol=1e-12)


def test_describe_is_btf_info(data):
    for key in ("gt", "lpca"):
        info = tool_json("btf-info", data[key], "--no-stats")
        got = libbtf.open(data[key]).describe()
        for k in ("tool", "version", "schema_version", "options", "ranks", "per_rank"):  # the tools' --json envelope
            info.pop(k, None)
            got.pop(k, None)
        assert got == info
    stats = tool_json("btf-info", data["gt"])
    assert libbtf.open(data["gt"]).describe(stats=True)["values"] == stats["values"]


def test_reads_agree_with_each_other_and_with_btf_info_stats(data):
    src = libbtf.open(data["gt"])
    allv = src.read_all()
    assert allv.dtype == np.float32 and allv.flags.c_contiguous and allv.shape == src.shape
    # btf-info's value scan (C++ DatasetReader) over the same file: min and max are exact floats.
    stats = tool_json("btf-info", data["gt"])["values"]
    assert float(allv.min()) == stats["min"]
    assert float(allv.max()) == stats["max"]
    # The mean is accumulated in double in both; 1e-6 relative covers summation order.
    assert float(allv.astype(np.float64).mean()) == pytest.approx(stats["mean"], rel=1e-6)
    for v in range(src.shape[0]):
        np.testing.assert_array_equal(src.view_slot(v), allv[v])
        for l in range(src.shape[1]):
            np.testing.assert_array_equal(src.image(v, l), allv[v, l])
    for y, x in ((0, 0), (3, 5), (N - 1, N - 1)):
        np.testing.assert_array_equal(src.abrdf(y, x), allv[:, :, y, x, :])


# Decoded values of one codec in two processes: Eigen's multi-threaded kernels may differ in the
# last bits between runs (docs/architecture.md, "Threads"), so 1e-6 of the peak (about 13 float32
# ulps at the peak) rather than bit equality.
def close_to_decoded(got, want, peak):
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * peak)


def test_codec_reads_equal_the_cpp_decoder(data):
    codec, ref = libbtf.open(data["lpca"]), libbtf.open(data["decoded"]).read_all()
    peak = float(np.abs(ref).max())
    # `decoded` was written by btf-compress decode (Codec::DecodeViewSlot).
    allv = codec.read_all()
    assert allv.shape == ref.shape and allv.dtype == np.float32
    close_to_decoded(allv, ref, peak)
    close_to_decoded(codec.view_slot(2), ref[2], peak)
    close_to_decoded(codec.image(1, 3), ref[1, 3], peak)
    # Codec::DecodeAbrdf evaluates one texel in another loop order: float rounding only (1e-5 of the peak).
    np.testing.assert_allclose(codec.abrdf(4, 2), ref[:, :, 4, 2, :], rtol=0, atol=1e-5 * peak)


def test_decode_at_uv_wi_wo(data):
    codec, ref = libbtf.open(data["lpca"]), libbtf.open(data["decoded"]).read_all()
    views, lights = codec.views["directions"], codec.lights["directions"]
    peak = float(np.abs(ref).max())
    tol = 1e-5 * peak  # float rounding: Value sums in double, DecodeImage in float
    # At texel centres (u = (x + 0.5) / N, v = 1 - (y + 0.5) / N) and sampled directions the
    # decoded value is exact for both filters.
    vv, ll, yy, xx = np.meshgrid(range(len(VIEWS)), range(len(LIGHTS)), range(N), range(N), indexing="ij")
    vv, ll, yy, xx = (a.ravel() for a in (vv, ll, yy, xx))
    uv = np.stack([(xx + 0.5) / N, 1 - (yy + 0.5) / N], axis=1)
    for f in ("nearest", "bilinear"):
        got = codec.decode(uv, lights[ll], views[vv], filter=f)
        assert got.shape == (len(vv), 3) and got.dtype == np.float32
        np.testing.assert_allclose(got, ref[vv, ll, yy, xx], rtol=0, atol=tol)
    # Halfway between two texel centres bilinear is their mean; one row broadcasts.
    mid = codec.decode([[3.0 / N, 1 - 0.5 / N]], lights[1], views[2])
    np.testing.assert_allclose(mid[0], (ref[2, 1, 0, 2] + ref[2, 1, 0, 3]) / 2, rtol=0, atol=tol)
    # The tile repeats: uv + 1 gives the same value.
    np.testing.assert_allclose(codec.decode(uv[:50] + 1, lights[ll[:50]], views[vv[:50]]),
                               codec.decode(uv[:50], lights[ll[:50]], views[vv[:50]]), rtol=0, atol=tol)
    # Between sampled directions the value is a convex combination of sampled values at that texel.
    rng = np.random.default_rng(1)
    wi = rng.normal(size=(20, 3))
    wi[:, 2] = np.abs(wi[:, 2]) + 0.5
    wo = rng.normal(size=(20, 3))
    wo[:, 2] = np.abs(wo[:, 2]) + 0.5
    got = codec.decode([0.5 / N, 1 - 0.5 / N], wi, wo, filter="nearest")
    texel = ref[:, :, 0, 0, :].reshape(-1, 3)
    assert np.all(got >= texel.min(axis=0) - tol) and np.all(got <= texel.max(axis=0) + tol)


def test_coefficients_are_views_that_rebuild_the_decoded_values(data):
    # The formulas of libbtf/compress/codec.h, evaluated in NumPy on the stored coefficients, give
    # the C++ decoders' values (float32 rounding in both: 1e-5 of the peak).
    lpca = libbtf.open(data["lpca"])
    co = lpca.coefficients()
    assert co["method"] == "lpca" and co["transform"] == "none"
    assert co["means"].shape == (2, len(VIEWS), len(LIGHTS), 3) and co["cluster_of"].shape == (N, N)
    assert co["basis"].shape[:2] == (2, 3) and co["weights"].shape == (N, N, 3)
    # No copy: read-only views of the codec's memory, the same buffer on every call.
    assert not co["means"].flags.writeable and co["means"].base is not None
    assert np.shares_memory(co["basis"], lpca.coefficients()["basis"])
    ref = libbtf.open(data["decoded"]).read_all()
    peak = float(np.abs(ref).max())
    for y, x in ((0, 0), (5, 2), (N - 1, 3)):
        k = co["cluster_of"][y, x]
        value = co["means"][k] + np.tensordot(co["weights"][y, x], co["basis"][k], axes=1)
        np.testing.assert_allclose(value, ref[:, :, y, x, :], rtol=0, atol=1e-5 * peak)
    pca = libbtf.open(data["pca"])
    slots = pca.coefficients()["slots"]
    assert len(slots) == len(VIEWS)
    for v, slot in enumerate(slots):
        value = slot["mean"] + np.tensordot(slot["weights"], slot["basis"], axes=1)
        np.testing.assert_allclose(value, pca.view_slot(v), rtol=0, atol=1e-5 * peak)
    # The arrays keep the codec alive after the Source is gone.
    basis = libbtf.open(data["lpca"]).coefficients()["basis"]
    np.testing.assert_array_equal(basis, co["basis"])
    expect_error("usage", 2, "not a codec", libbtf.open(data["gt"]).coefficients)


def test_lossless_codec_reproduces_the_ground_truth(data):
    gt, pca = libbtf.open(data["gt"]).read_all(), libbtf.open(data["pca"]).read_all()
    # All lights - 1 components of each view slot: exact up to float32 rounding of the PCA.
    np.testing.assert_allclose(pca, gt, rtol=0, atol=1e-5 * float(np.abs(gt).max()))


def test_compress_matches_btf_compress(data):
    d = data["dir"]
    tool_summary = tool_json("btf-compress", data["gt"], "--method", "lpca", "-k", 2, "-c", 3, "-o", d / "tool.h5")
    py_summary = data["lpca_summary"]
    assert py_summary["output"] == str(data["lpca"])
    # Deterministic for a seed: the same sizes and clustering as the tool; the error figures equal
    # to 1e-6 relative (Eigen's last bits, as above), and a codec that decodes the same.
    for k in ("method", "shape", "components", "cluster_components", "clusters", "codec_bytes", "raw_float32_bytes"):
        assert py_summary[k] == tool_summary[k], k
    for k in ("rmse", "relative_error", "max_abs_error", "psnr_db"):
        assert py_summary[k] == pytest.approx(tool_summary[k], rel=1e-6), k
    assert py_summary["iteration_relative_errors"] == pytest.approx(tool_summary["iteration_relative_errors"], rel=1e-6)
    tool_values = libbtf.open(d / "tool.h5").read_all()
    close_to_decoded(libbtf.open(data["lpca"]).read_all(), tool_values, float(np.abs(tool_values).max()))
    # Every tool option is a keyword with the tool's default (docs/btf-compress.md).
    s = libbtf.compress(data["gt"], d / "energy.h5", method="pca-view", energy=0.9, seed=3, log=True,
                        log_epsilon=1e-2, max_iterations=5, min_improvement=1e-2, error=0, components=4, clusters=8)
    assert s["method"] == "pca-view" and max(s["slot_components"]) <= 4
    assert libbtf.open(d / "energy.h5").describe()["transform"] != "none"
    # The rate-distortion and lpca-tensor keywords reach the library as the tool's flags do: the
    # same codec bytes as btf-compress with the same flags.
    flags = dict(method="lpca-tensor", clusters=2, components=3, quant_bits=8, tensor_growth=0.5)
    s = libbtf.compress(data["gt"], d / "tensor.h5", **flags)
    t = tool_json("btf-compress", data["gt"], "--method", "lpca-tensor", "-k", 2, "-c", 3, "--quant-bits", 8,
                  "--tensor-growth", 0.5, "-o", d / "tensor_tool.h5")
    assert s["codec_bytes"] == t["codec_bytes"] and s["storage"] == t["storage"]
    # LPCA's memory mode, k-means sample and texel matrix: a 40-texel sample (fewer than the texels, so the
    # sample rounds run) out of core gives the tool's codec with the same flags, value for value.
    s = libbtf.compress(data["gt"], d / "ooc.h5", method="lpca", clusters=2, components=3, lpca_memory="out-of-core",
                        lpca_sample=40, lpca_matrix="float")
    t = tool_json("btf-compress", data["gt"], "--method", "lpca", "-k", 2, "-c", 3, "--lpca-memory", "out-of-core",
                  "--lpca-sample", 40, "--lpca-matrix", "float", "-o", d / "ooc_tool.h5")
    assert s["lpca_memory"]["mode"] == t["lpca_memory"]["mode"] == "out-of-core" and s["codec_bytes"] == t["codec_bytes"]
    assert s["lpca_memory"]["matrix"] == t["lpca_memory"]["matrix"] == "float"
    np.testing.assert_array_equal(libbtf.open(d / "ooc.h5").read_all(), libbtf.open(d / "ooc_tool.h5").read_all())
    half = libbtf.compress(data["gt"], d / "half.h5", method="pca-view", components=4, storage="half")
    s = libbtf.compress(data["gt"], d / "budget.h5", method="pca-view", components=4, storage="half",
                        bytes=half["codec_bytes"] - 1)
    assert half["storage"] == "half" and 0 < s["codec_bytes"] < half["codec_bytes"]


# The neural codec's options: keyword -> the btf-compress flag with the same value.
NEURAL = dict(neural_latent=4, neural_hidden=[16, 8], neural_fourier=1, neural_latent_storage="half",
              neural_samples=3000, neural_steps=60, neural_epochs=3, neural_batch=512, neural_lr=0.02,
              neural_linear_loss=0.25)


def neural_flags(**kw):
    out = []
    for k, v in kw.items():
        out += ["--" + k.replace("_", "-"), ",".join(map(str, v)) if isinstance(v, list) else v]
    return out


def silu(z):
    return z / (1 + np.exp(-z))


def test_neural_compress_decode_and_coefficients(data):
    d = data["dir"]
    s = libbtf.compress(data["gt"], d / "neural.h5", method="neural", seed=3, **NEURAL)
    t = tool_json("btf-compress", data["gt"], "--method", "neural", "--seed", 3, *neural_flags(**NEURAL),
                  "-o", d / "neural_tool.h5")
    # Every keyword reached the library as the tool's flag does: the same training and the same codec.
    assert s["method"] == "neural" and s["storage"] == "half" and s["latent_components"] == [4]
    assert s["neural"]["samples"] == 3000 and s["neural"]["steps"] == 60 and s["neural"]["hidden"] == [16, 8]
    for k in ("neural", "codec_bytes", "rmse", "relative_error"):
        assert s[k] == t[k], k
    assert s["neural"]["last_loss"] < s["neural"]["first_loss"]
    codec = libbtf.open(d / "neural.h5")
    values = codec.read_all()  # Codec::DecodeViewSlot
    np.testing.assert_array_equal(values, libbtf.open(d / "neural_tool.h5").read_all())
    tool("btf-compress", "decode", d / "neural.h5", "-o", d / "neural_decoded.h5", "-q")
    np.testing.assert_array_equal(values, libbtf.open(d / "neural_decoded.h5").read_all())
    # decode() at texel centres and sampled directions, nearest texel: the decoder evaluated at the
    # same inputs in batches of other sizes (float rounding, 1e-4 relative).
    views, lights = codec.views["directions"], codec.lights["directions"]
    vv, ll, yy, xx = np.meshgrid(range(len(VIEWS)), range(len(LIGHTS)), range(N), range(N), indexing="ij")
    vv, ll, yy, xx = (a.ravel() for a in (vv, ll, yy, xx))
    uv = np.stack([(xx + 0.5) / N, 1 - (yy + 0.5) / N], axis=1)
    got = codec.decode(uv, lights[ll], views[vv], filter="nearest")
    np.testing.assert_allclose(got, values[vv, ll, yy, xx], rtol=1e-4, atol=1e-6)
    # Anywhere on the hemisphere, bilinear: finite values above -epsilon.
    rng = np.random.default_rng(2)
    wi, wo = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]) + 0.2, np.abs(wo[:, 2]) + 0.2
    between = codec.decode(rng.uniform(size=(50, 2)), wi, wo)
    assert np.all(np.isfinite(between)) and np.all(between > -1.0001e-3)
    # coefficients(): the decoder of docs/format.md ("Neural") evaluated in NumPy gives the decoded
    # values (float32 arithmetic in C++, float64 here: 1e-4 relative).
    co = codec.coefficients()
    assert co["method"] == "neural" and co["transform"] == "log" and co["activation"] == "silu"
    assert co["latents"].shape == (N, N, 4) and not co["latents"].flags.writeable
    assert [w.shape for w in co["weights"]] == [(16, 4 + 6 + 8), (8, 16), (3, 8)]
    wi, wo = lights[ll], views[vv]
    wi, wo = wi / np.linalg.norm(wi, axis=1)[:, None], wo / np.linalg.norm(wo, axis=1)[:, None]
    h = wi + wo
    h /= np.linalg.norm(h, axis=1)[:, None]
    base = np.stack([wi[:, 0], wi[:, 1], wo[:, 0], wo[:, 1]], axis=1)
    fourier = np.stack([f(np.pi * base) for f in (np.sin, np.cos)], axis=2).reshape(len(vv), 8)
    a = np.concatenate([co["latents"][yy, xx], base, h[:, :2], fourier], axis=1).astype(np.float64)
    for n, (w, b) in enumerate(zip(co["weights"], co["biases"])):
        a = a @ w.T.astype(np.float64) + b
        if n + 1 < len(co["weights"]):
            a = silu(a)
    np.testing.assert_allclose(np.exp(a) - co["log_epsilon"], values[vv, ll, yy, xx], rtol=1e-4, atol=1e-6)
    expect_error("usage", 2, "invalid option 'neural_hidden'", libbtf.compress, data["gt"], d / "x.h5",
                 method="neural", neural_hidden=[8, 0])
    expect_error("usage", 2, "not fmf", libbtf.open(libbtf.compress(data["gt"], d / "fmf.h5", method="fmf",
                                                                    components=2)["output"]).coefficients)


def test_compare_matches_btf_eval(data):
    tool_summary = tool_json("btf-eval", "compare", data["gt"], data["lpca"])
    by_path = libbtf.compare(data["gt"], data["lpca"])
    by_source = libbtf.compare(libbtf.open(data["gt"]), libbtf.open(data["lpca"]), ssim=False)
    assert by_path["values"] == tool_summary["values"] and by_path["shape"] == tool_summary["shape"]
    for k in ("rmse", "psnr_db", "max_abs", "mean_ssim"):  # 1e-6 relative: the codec decoded in two processes
        assert by_path[k] == pytest.approx(tool_summary[k], rel=1e-6), k
    assert by_source["rmse"] == by_path["rmse"] and by_source.get("mean_ssim") is None
    # Against the numbers computed here from the arrays (double sums; 1e-9 relative).
    gt, lp = libbtf.open(data["gt"]).read_all().astype(np.float64), libbtf.open(data["lpca"]).read_all()
    assert by_path["rmse"] == pytest.approx(np.sqrt(np.mean((lp - gt) ** 2)), rel=1e-9)
    assert libbtf.compare(data["gt"], data["gt"])["rmse"] == 0
    maps = data["dir"] / "maps"
    s = libbtf.compare(data["gt"], data["lpca"], ssim=False, error_maps=maps, maps=2, worst_images=3)
    assert len(s["worst_images"]) == 3 and len(s["error_maps"]) == 2
    assert all(os.path.getsize(f) > 0 for f in s["error_maps"]) and maps.is_dir()


def test_bonn_btf_file(data):
    btf_file = data["dir"] / "gt.btf"
    tool("btf-convert", data["gt"], "-o", btf_file, "-q")  # Bonn BDI, half-float texels
    src = libbtf.open(btf_file)
    assert src.format == "bonn-bdi" and src.shape == (len(VIEWS), len(LIGHTS), N, N, 3)
    gt = libbtf.open(data["gt"]).read_all()
    # Half precision: 2^-11 relative (plus the smallest normal half for values near 0).
    np.testing.assert_allclose(src.read_all(), gt, rtol=2.0 ** -11, atol=6.2e-5)
    np.testing.assert_array_equal(src.abrdf(1, 2), src.read_all()[:, :, 1, 2, :])
    assert src.describe()["format"] == "bonn-bdi"
    s = libbtf.compress(btf_file, data["dir"] / "from_bonn.h5", components=2)
    assert s["shape"]["views"] == len(VIEWS) and s["input"] == str(btf_file)


def test_progress_callback_and_cancelling(data):
    seen = []
    libbtf.compress(data["gt"], data["dir"] / "p.h5", progress=lambda done, total, stage: seen.append((done, total)))
    assert seen and seen[-1][0] == seen[-1][1]
    out = data["dir"] / "cancelled.h5"
    with pytest.raises(libbtf.Error) as e:
        libbtf.compress(data["gt"], out, progress=lambda *a: False)
    assert e.value.category == "interrupted" and e.value.exit_code == 130
    assert not out.exists()

    def boom(*a):
        raise ValueError("from the callback")

    with pytest.raises(ValueError, match="from the callback"):
        libbtf.compare(data["gt"], data["lpca"], progress=boom)

    # Ctrl-C (SIGINT, Python's default handler) during the work: KeyboardInterrupt, nothing written.
    def interrupt(*a):
        os.kill(os.getpid(), signal.SIGINT)
        return True

    with pytest.raises(KeyboardInterrupt):
        libbtf.compress(data["gt"], out, progress=interrupt)
    assert not out.exists()


def expect_error(category, code, fragment, fn, *args, **kw):
    with pytest.raises(libbtf.Error) as e:
        fn(*args, **kw)
    assert isinstance(e.value, RuntimeError)
    assert (e.value.category, e.value.exit_code) == (category, code), str(e.value)
    assert fragment in str(e.value), str(e.value)
    return str(e.value)


def test_errors_carry_the_tools_message_and_exit_code(data, tmp_path):
    d = data["dir"]
    missing = tmp_path / "missing.h5"
    msg = expect_error("io", 4, str(missing), libbtf.open, missing)
    assert tool("btf-info", missing, check=False).stderr.strip() == f"btf-info: error: {msg}"
    text = tmp_path / "notes.h5"
    text.write_text("not a BTF\n")
    expect_error("bad_input", 3, str(text), libbtf.open, text)
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(data["gt"].read_bytes()[:3000])
    expect_error("bad_input", 3, str(truncated), libbtf.open, truncated)

    gt, lpca = data["gt"], data["lpca"]
    src = libbtf.open(gt)
    expect_error("usage", 2, "view index 9", src.view_slot, 9)
    expect_error("usage", 2, "light index -1", src.image, 0, -1)
    expect_error("usage", 2, "y index", src.abrdf, N, 0)
    expect_error("usage", 2, "not a codec", src.decode, [0.5, 0.5], [0, 0, 1], [0, 0, 1])
    codec = libbtf.open(lpca)
    expect_error("usage", 2, "'wi' has 2 rows", codec.decode, np.zeros((3, 2)), np.ones((2, 3)), [0, 0, 1])
    expect_error("usage", 2, "shape (N, 3)", codec.decode, [0.5, 0.5], [0, 1], [0, 0, 1])
    expect_error("usage", 2, "'filter'", codec.decode, [0.5, 0.5], [0, 0, 1], [0, 0, 1], filter="cubic")
    expect_error("usage", 2, "non-zero finite", codec.decode, [0.5, 0.5], [0, 0, 0], [0, 0, 1])

    # compress: the tool's option checks, input checks and output folder check, nothing written.
    expect_error("usage", 2, "invalid option 'components'", libbtf.compress, gt, d / "x.h5", components=0)
    expect_error("usage", 2, "unknown compression method 'wavelet'", libbtf.compress, gt, d / "x.h5", method="wavelet")
    expect_error("io", 4, "does not exist", libbtf.compress, gt, tmp_path / "no" / "x.h5")
    expect_error("bad_input", 3, "libbtf-codec", libbtf.compress, lpca, d / "x.h5")
    assert not (d / "x.h5").exists()
    r = tool("btf-compress", gt, "-c", 0, "-o", d / "x.h5", check=False)
    assert r.returncode == 2 and "invalid option 'components'" in r.stderr

    # compare: incompatible inputs and bad options.
    other = tmp_path / "other.h5"
    tool("btf-synth", "btf", "--views", "0,1", "--lights", "0,3", "--resolution", 4, "--samples", 1, "-q", "-o", other)
    expect_error("bad_input", 3, str(other), libbtf.compare, gt, other)
    expect_error("usage", 2, "invalid option 'ssim_sigma'", libbtf.compare, gt, lpca, ssim_sigma=-1)


def test_import_without_numpy_names_numpy():
    # An interpreter where NumPy cannot be imported: libbtf fails at import, naming NumPy.
    code = ("import sys\n"
            "class Block:\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            "        if name == 'numpy' or name.startswith('numpy.'):\n"
            "            raise ImportError('No module named numpy (blocked)')\n"
            "sys.meta_path.insert(0, Block())\n"
            "try:\n"
            "    import libbtf\n"
            "except ImportError as e:\n"
            "    print('ImportError:', e)\n"
            "    sys.exit(0)\n"
            "sys.exit(1)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=os.environ.copy())
    assert r.returncode == 0, r.stdout + r.stderr
    assert "NumPy" in r.stdout and "python3-numpy" in r.stdout, r.stdout
