#!/usr/bin/env python3
"""The neural codec's training step against PyTorch's on the CPU, in one run.

Usage: bench/neural_vs_torch.py [BUILD_DIR]

The question it answers: would training with a library (Debian's libtorch / python3-torch 1.13,
CPU only) be faster than libbtf's own Eigen trainer (libbtf/compress/neural_net.h)?

Ours: bench_neural's BM_NeuralStep/threads (BUILD_DIR/bin/bench_neural), one training step at
batch 4096 of the 14-32-32-3 SiLU decoder (8 latents + the 6-value direction encoding), 256
texels: forward, backward, the reduction over 16 blocks of 256 samples, dense Adam on the decoder
and lazy Adam on the latent rows the batch touched.
Theirs: the same step written plainly in PyTorch: an nn.Embedding(256, 8, sparse=True) for the
latents (torch.optim.SparseAdam: Adam on the rows the batch touched, as ours), an nn.Sequential
of Linear/SiLU layers (torch.optim.Adam), the mean squared error, on random samples of the same
shapes; timed over STEPS steps after WARMUP, with torch.set_num_threads(1) and (2).

Both print milliseconds per step (wall); the ratio is torch's time over ours. Torch's BLAS and
threading and the BLAS loaded are printed with the table; OPENBLAS_CORETYPE / OPENBLAS_L2_SIZE are
unset for the whole run (bench/peer_env.py). Needs python3-torch (`./run bench`
installs it).
"""
import json
import os
import subprocess
import sys
import time

from peer_env import blas_kernel, fair_environment  # bench/peer_env.py

UNSET = fair_environment()  # before torch loads its BLAS

BATCH, TEXELS, LATENT, DIRS, HIDDEN, OUT = 4096, 256, 8, 6, 32, 3
WARMUP, STEPS = 20, 300


def ours(build):
    """ms per step of BM_NeuralStep/1 and /2, from one bench_neural run."""
    exe = os.path.join(build, "bin", "bench_neural")
    out = subprocess.run([exe, "--benchmark_filter=BM_NeuralStep", "--benchmark_format=json"],
                         check=True, capture_output=True, text=True).stdout
    ms = {}
    for b in json.loads(out)["benchmarks"]:
        threads = int(b["name"].split("/")[1])
        ms[threads] = b["real_time"] * {"ms": 1, "us": 1e-3, "ns": 1e-6}[b["time_unit"]]
    return ms


def theirs(threads):
    import torch
    torch.set_num_threads(threads)
    torch.manual_seed(1)
    latents = torch.nn.Embedding(TEXELS, LATENT, sparse=True)
    torch.nn.init.uniform_(latents.weight, -0.1, 0.1)
    net = torch.nn.Sequential(torch.nn.Linear(LATENT + DIRS, HIDDEN), torch.nn.SiLU(),
                              torch.nn.Linear(HIDDEN, HIDDEN), torch.nn.SiLU(), torch.nn.Linear(HIDDEN, OUT))
    opt_net = torch.optim.Adam(net.parameters(), lr=1e-2)
    opt_lat = torch.optim.SparseAdam(list(latents.parameters()), lr=1e-2)
    n = BATCH * 64
    texel = torch.randint(0, TEXELS, (n,))
    dirs = torch.rand(n, DIRS) * 2 - 1
    target = torch.randn(n, OUT)

    def step(k):
        sl = slice((k % 64) * BATCH, (k % 64 + 1) * BATCH)
        opt_net.zero_grad(set_to_none=True)
        opt_lat.zero_grad(set_to_none=True)
        x = torch.cat([latents(texel[sl]), dirs[sl]], dim=1)
        loss = torch.nn.functional.mse_loss(net(x), target[sl])
        loss.backward()
        opt_net.step()
        opt_lat.step()

    for k in range(WARMUP):
        step(k)
    t0 = time.perf_counter()
    for k in range(STEPS):
        step(k)
    return (time.perf_counter() - t0) / STEPS * 1e3


def main():
    build = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else "build")
    try:
        import torch
    except ImportError:
        sys.exit("neural_vs_torch.py: PyTorch is not installed (Debian python3-torch; ./run bench installs it)")
    mine = ours(build)
    print(f"torch {torch.__version__}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} at the start")
    import re
    config = torch.__config__.show()
    keys = ("BLAS_INFO", "USE_MKLDNN", "USE_OPENMP", "PERF_WITH_AVX2")
    found = {k: m.group(1) for k in keys if (m := re.search(rf"{k}=([^,\s]+)", config))}
    print("torch build: " + ", ".join(f"{k}={v}" for k, v in found.items()))
    kernel, optimised = blas_kernel()
    print(f"BLAS loaded: {kernel}{f' (unset for the peer: {UNSET})' if UNSET else ''}")
    if not optimised:
        print("WARNING: torch runs an unoptimised BLAS, so the ratios below flatter ours")
    print(f"training step, batch {BATCH}, {LATENT + DIRS}-{HIDDEN}-{HIDDEN}-{OUT} SiLU, Adam "
          f"(latents: lazy / SparseAdam), {TEXELS} texels; ms per step (wall)")
    print(f"{'threads':>7} {'libbtf':>9} {'torch':>9} {'torch / libbtf':>15}")
    for threads in (1, 2):
        t = theirs(threads)
        print(f"{threads:>7} {mine[threads]:9.3f} {t:9.3f} {t / mine[threads]:15.2f}")
    print(f"load average at the end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
