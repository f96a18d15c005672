#!/usr/bin/python3
"""CPU time of each LPCA phase, by symbol, from a `perf record` of btf-compress and its summary.

    perf record -F 499 -o P.data -- build-dev/bin/btf-compress FILE --method lpca -k 32 -c 8 \
        -o /tmp/l.h5 --json -q > S.json
    bench/lpca_phase_profile.py P.data S.json 499 [TOP]

The phases are the summary's `seconds` (read, kmeans, sample_rounds, first_fit, iterate,
evaluate, in that order), laid end to end from the first sample in the read phase's fill or chunk
reader; a sample counts in the phase whose interval holds its time. Each sample is 1/F s of CPU
(F: the perf -F frequency), of any thread. Eigen's GEMM kernels and packing are one group per
scalar type; kernel symbols are prefixed "kernel:". Prints, per phase, its wall time (from the
summary), its CPU time and the TOP (default 8) groups. Under perf every phase runs a few percent
slower; page faults and their zeroing (kernel: clear_page_erms) vary from run to run on a
virtual machine (first touches of guest memory).
"""
import collections
import json
import re
import sys

from perf_samples import perf_samples

data, summary, freq = sys.argv[1], sys.argv[2], float(sys.argv[3])
top = int(sys.argv[4]) if len(sys.argv) > 4 else 8
seconds = json.load(open(summary))["seconds"]
phases = [p for p in ("read", "kmeans", "sample_rounds", "first_fit", "iterate", "evaluate") if p in seconds]
rows = perf_samples(data)
start = next(t for t, s, _ in rows if re.search(r"ReadRows|ReadRawChunks", s))
bounds = [start]
for p in phases:
    bounds.append(bounds[-1] + seconds[p])


def group(sym, dso):
    if re.search(r"gebp_kernel|gemm_pack|lhs_process", sym):
        return "Eigen GEMM (" + ("double" if "<double" in sym else "float") + ")"
    if "kernel" in dso:
        return "kernel:" + sym
    if "libgomp" in dso:
        return "OpenMP (libgomp)"
    if "libdeflate" in dso:
        return "inflate (libdeflate)"
    sym = re.sub(r"\(anonymous namespace\)::", "", sym)
    return re.sub(r"[<(].*", "", sym) or dso


per = [collections.Counter() for _ in phases]
for t, s, d in rows:
    for i in range(len(phases)):
        if bounds[i] <= t < bounds[i + 1]:
            per[i][group(s, d)] += 1
            break
for i, p in enumerate(phases):
    total = sum(per[i].values())
    print(f"{p}: {seconds[p]:.2f} s wall, {total / freq:.2f} s CPU")
    for g, n in per[i].most_common(top):
        print(f"  {n / freq:6.2f} s  {g}")
