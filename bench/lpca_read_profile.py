#!/usr/bin/python3
"""CPU time of LPCA's read phase, split by what it does, from a `perf record` of btf-compress.

    perf record -F 1000 -o P.data -- build-dev/bin/btf-compress FILE --method lpca -k 2 -c 1 \
        --max-iterations 1 -o /tmp/l.h5 --json -q
    bench/lpca_read_profile.py P.data 1000

The read phase is taken as the samples (of every thread) from the first one in the fill or the
chunk reader to the first one in k-means, whose symbols only the next phase runs; each sample is
one 1/F s of CPU (F: the perf -F frequency). Symbols are grouped by regular expression; the
rest is "other". Page faults and their zeroing are kernel time that varies from run to run on a
virtual machine (first touches of guest memory), so compare the user-space groups across builds.
"""
import collections
import re
import sys

from perf_samples import perf_samples

data, freq = sys.argv[1], float(sys.argv[2])
rows = [(t, f"{sym} ({dso})") for t, sym, dso in perf_samples(data)]
start = next(t for t, s in rows if re.search(r"ReadRows|ReadRawChunks|Fletcher32|ToHalves", s))
end = next(t for t, s in rows if t > start and re.search(r"SeedCenters|NearestCenters|UpdateMeans", s))
groups = collections.OrderedDict([
    ("fill: convert, check, transpose (ReadRows, ToHalves, HalvesToFloats)", r"ReadRows|ToHalves|HalvesToFloats"),
    ("inflate (libdeflate)", r"libdeflate"),
    ("Fletcher-32", r"Fletcher32"),
    ("unshuffle (ReadRawChunks)", r"ReadRawChunks|DecodeChunk"),
    ("memcpy / memmove", r"memmove|memcpy|memset"),
    ("kernel: copy from the page cache", r"copy_to_iter|filemap|copy_page_to_iter"),
    ("kernel: page faults, zeroing", r"clear_page|page_fault|handle_mm|anonymous_page|alloc_pages|get_page_from_freelist"
                                     r"|folio|page_reporting|lruvec|mem_cgroup"),
    ("OpenMP waits (libgomp)", r"libgomp"),
])
count = collections.Counter()
total = 0
for t, s in rows:
    if start <= t <= end:
        total += 1
        count[next((g for g, rx in groups.items() if re.search(rx, s)), "other")] += 1
print(f"{data}: read phase {end - start:.2f} s wall (under perf), {total / freq:.2f} s CPU")
for g in list(groups) + ["other"]:
    print(f"  {g:<72} {count[g] / freq:6.2f} s  {100 * count[g] / max(total, 1):5.1f} %")
