#!/usr/bin/env python3
"""Per-view PCA and LPCA against straightforward NumPy / scikit-learn implementations, in one run.

Usage: bench/vs_numpy.py [BUILD_DIR] [INPUT.h5]
  BUILD_DIR  the build with the Python module and the tools (default: build)
  INPUT.h5   a dataset; default: a 64 x 64 bonn81 twill rendered into BUILD_DIR/bench-twill64.h5
             with `btf-synth btf --preset twill --directions bonn81 --resolution 64` (once)

Ours: libbtf.compress (what btf-compress runs), wall time of the call, which includes reading the
dataset file and writing the codec. Theirs: the same decompositions written plainly on the array
already in memory (the read is not counted for them):
  per-view PCA, c = 16: per view slot numpy.linalg.svd of the centred (lights x texel values)
    matrix, first 16 components;
  LPCA, k = 32, c = 8: sklearn.cluster.KMeans (k-means++, Lloyd to convergence, one init) on the
    texel-major matrix, then Kambhatla-Leen local PCA: sklearn.decomposition.PCA per cluster,
    each texel reassigned to the cluster that reconstructs it best, `ROUNDS` rounds, final fit.
Per-view PCA takes a second or so on each side, where the machine's noise is a large share: each side
is timed REPS times (default 3) and its fastest run counts. LPCA (tens of seconds for theirs) is
timed once. Errors are relative L2 over the whole BTF, ||X - X'||_F / ||X||_F, the definition our
summary uses.
Both sides use both cores (OpenMP for ours, OpenBLAS threads for NumPy). Prints one table.

A fair peer (bench/peer_env.py): the script re-executes itself without OPENBLAS_CORETYPE and
OPENBLAS_L2_SIZE before NumPy loads, prints the BLAS NumPy runs (threadpoolctl: library, version,
kernel architecture, threads) with the table, and warns when it is Debian's reference BLAS
(install libopenblas0-pthread; ./run bench does). It also prints NumPy's and Eigen's float32 GEMM
rates, measured in the same run.
"""
import json
import os
import subprocess
import sys
import tempfile
import time

from peer_env import blas_kernel, fair_environment  # bench/peer_env.py

UNSET = fair_environment()  # before NumPy loads its BLAS: a peer slowed by these variables is no peer
import numpy as np  # noqa: E402

ROUNDS = 2
REPS = int(os.environ.get("REPS", "3"))  # per-view PCA: the fastest of this many runs on each side


def numpy_gemm_rate(n=1024, seconds=2.0):
    """NumPy's float32 n x n x n GEMM rate in GFLOP/s (its BLAS, all its threads), best of the reps."""
    a = np.random.default_rng(1).standard_normal((n, n), dtype=np.float32)
    b = np.random.default_rng(2).standard_normal((n, n), dtype=np.float32)
    a @ b  # warm-up: thread pool start, page faults
    best, start = float("inf"), time.perf_counter()
    while time.perf_counter() - start < seconds:
        t = time.perf_counter()
        a @ b
        best = min(best, time.perf_counter() - t)
    return 2.0 * n ** 3 / best / 1e9


def our_gemm_rate(build):
    """Eigen's float32 1024^3 GEMM rate in GFLOP/s on both threads (bench_compress BM_EigenGemm), or None."""
    exe = os.path.join(build, "bin", "bench_compress")
    if not os.path.exists(exe):
        return None
    out = subprocess.run([exe, "--benchmark_filter=BM_EigenGemm<float>", "--benchmark_format=json"],
                         capture_output=True, text=True, check=True).stdout
    rates = [b["GFLOPs"] for b in json.loads(out)["benchmarks"] if "GFLOPs" in b]
    return rates[0] if rates else None


def main():
    build = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else "build")
    sys.path.insert(0, os.path.join(build, "python"))
    import libbtf  # noqa: E402  (from this build)
    try:
        from sklearn.cluster import KMeans
        from sklearn.decomposition import PCA
    except ImportError:
        sys.exit("vs_numpy.py: scikit-learn is missing (Debian: python3-sklearn; ./run bench installs it)")

    path = sys.argv[2] if len(sys.argv) > 2 else os.path.join(build, "bench-twill64.h5")
    if not os.path.exists(path):
        print(f"rendering {path} (once)", file=sys.stderr)
        subprocess.run([os.path.join(build, "bin", "btf-synth"), "btf", "--preset", "twill", "--directions",
                        "bonn81", "--resolution", "64", "--quiet", "-o", path], check=True)
    src = libbtf.open(path)
    V, L, H, W, C = src.shape
    data = src.read_all()  # (V, L, H, W, C) float32
    total = float(np.sum(data.astype(np.float64) ** 2))
    rows = []

    with tempfile.TemporaryDirectory() as tmp:
        # All of ours first: OpenBLAS's threads spin for a while after NumPy's calls and would take
        # the cores from ours.
        ours_s = theirs_s = float("inf")
        for _ in range(REPS):
            t = time.perf_counter()
            ours = libbtf.compress(path, os.path.join(tmp, "pv.h5"), method="pca-view", components=16)
            ours_s = min(ours_s, time.perf_counter() - t)
        for _ in range(REPS):
            t = time.perf_counter()
            err = 0.0
            for v in range(V):
                X = data[v].reshape(L, -1)
                Xc = X - X.mean(axis=0, keepdims=True)
                U, S, Vt = np.linalg.svd(Xc, full_matrices=False)
                R = Xc - (U[:, :16] * S[:16]) @ Vt[:16]
                err += float(np.sum(R.astype(np.float64) ** 2))
            theirs_s = min(theirs_s, time.perf_counter() - t)
        rows.append(("per-view PCA c=16", f"numpy.linalg.svd per view, best of {REPS}", ours_s,
                     ours["relative_error"], theirs_s, np.sqrt(err / total)))

        t = time.perf_counter()
        ours = libbtf.compress(path, os.path.join(tmp, "lpca.h5"), method="lpca", clusters=32, components=8)
        ours_s = time.perf_counter() - t

    t = time.perf_counter()
    T = np.ascontiguousarray(data.transpose(2, 3, 0, 1, 4).reshape(H * W, V * L * C))
    labels = KMeans(n_clusters=32, n_init=1, random_state=1).fit_predict(T)
    for r in range(ROUNDS + 1):
        models = []
        for k in range(32):
            members = T[labels == k]
            models.append(PCA(n_components=min(8, len(members) - 1)).fit(members) if len(members) > 1 else None)
        res = np.full((H * W, 32), np.inf)
        for k, m in enumerate(models):
            if m is None:
                continue
            Xc = T - m.mean_
            P = Xc @ m.components_.T
            res[:, k] = np.sum(Xc.astype(np.float64) ** 2, axis=1) - np.sum(P.astype(np.float64) ** 2, axis=1)
        if r < ROUNDS:
            labels = np.argmin(res, axis=1)
        else:  # error of the final fit, each texel under its own cluster
            err = float(np.sum(np.maximum(res[np.arange(H * W), labels], 0.0)))
    theirs_s = time.perf_counter() - t
    rows.append(("LPCA k=32 c=8", f"sklearn KMeans + {ROUNDS} local-PCA rounds", ours_s, ours["relative_error"],
                 theirs_s, np.sqrt(err / total)))

    kernel, optimised = blas_kernel()
    print(f"numpy {np.__version__}, BLAS: {kernel}{f' (unset for the peer: {UNSET})' if UNSET else ''}")
    if not optimised:
        print("WARNING: the peer runs an unoptimised BLAS, so the ratios below flatter ours")
    ours_gemm = our_gemm_rate(build)
    print(f"float32 GEMM 1024^3, both cores: NumPy {numpy_gemm_rate():.1f} GFLOP/s"
          f"{f', ours (Eigen, bench_compress BM_EigenGemm) {ours_gemm:.1f} GFLOP/s' if ours_gemm else ''}; "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"input {path}: {V} x {L} directions, {H} x {W} texels, {C} channels")
    print(f"{'codec':<20} {'theirs':<36} {'ours s':>8} {'ours err':>9} {'theirs s':>9} {'their err':>9} {'speed-up':>8}")
    for name, how, os_, oe, ts, te in rows:
        print(f"{name:<20} {how:<36} {os_:8.2f} {oe:9.5f} {ts:9.2f} {te:9.5f} {ts / os_:7.1f}x")


if __name__ == "__main__":
    main()
