#!/usr/bin/python3
"""CPU time by symbol during per-view PCA's decomposition, from a `perf record` of it.

    BTF_BENCH_RES=256 perf record -F 499 -o P.data -- build-dev/bin/bench_compress \
        --benchmark_filter='BM_PcaView/0'          (or a btf-compress --method pca-view run)
    bench/pcaview_profile.py P.data 499 [TOP]

Counts the samples of every thread from the first to the last one in WidePca (the benchmark's
synthetic data is made before that, on the same threads); each is 1/F s of CPU (F: the perf -F
frequency). Prints the wall time of that window, its CPU time and the TOP (default 12) symbols.
Page faults and their zeroing (kernel: clear_page_erms) vary from run to run on a virtual machine.
"""
import collections
import sys

from perf_samples import perf_samples

data, freq = sys.argv[1], float(sys.argv[2])
top = int(sys.argv[3]) if len(sys.argv) > 3 else 12
rows = perf_samples(data)
inside = [t for t, s, _ in rows if "WidePca" in s]
t0, t1 = inside[0], inside[-1]
counts = collections.Counter(s for t, s, _ in rows if t0 <= t <= t1)
total = sum(counts.values())
print(f"window {t1 - t0:.2f} s wall, {total / freq:.2f} s CPU")
for sym, n in counts.most_common(top):
    print(f"{n / freq:7.2f} s  {100 * n / total:5.1f} %  {sym[:100]}")
