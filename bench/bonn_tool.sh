#!/bin/bash
# Bonn-size compression through the tool (docs/performance.md, "Compression at the Bonn size"): writes the benchmarks' synthetic BTF (bench/synthetic_btf.h; synthetic, not a material
# model; 81 x 81 directions, 256^2 texels, RGB, 5.16 GB as float) once with bench_synthetic_input
# (deflate 4 + shuffle, as libbtf writes datasets) and once uncompressed (btf-convert
# --deflate-level 0), then runs btf-compress from each file under /usr/bin/time -v:
#   pca-view -c 16 (float and half storage) and lpca -k 32 -c 8,
# and prints wall, CPU, peak memory (and as a multiple of the float dataset), the summary's phases
# and error. Two yardsticks of this machine, measured in the same run: writing 1 GiB to OUT_DIR
# (dd; every codec is written there) and reading each input file once from the page cache (cat).
# Needs about 10 GB of disk in OUT_DIR and 12 GB of memory (LPCA in core); run it on an idle machine.
#
#   bench/bonn_tool.sh BUILD_DIR OUT_DIR
#
# Environment: RESOLUTION (default 256), METHODS (default "pca-view pca-view-half lpca").
set -euo pipefail
build=${1:?usage: bench/bonn_tool.sh BUILD_DIR OUT_DIR}
out=${2:?usage: bench/bonn_tool.sh BUILD_DIR OUT_DIR}
bin=$(cd "$build/bin" && pwd)
res=${RESOLUTION:-256}
methods=${METHODS:-"pca-view pca-view-half lpca"}
mkdir -p "$out"
deflated="$out/synthetic_bonn81_${res}.h5"
plain="$out/synthetic_bonn81_${res}_uncompressed.h5"
[[ -f $deflated ]] || "$bin/bench_synthetic_input" bonn81 "$res" "$deflated"
[[ -f $plain ]] || "$bin/btf-convert" "$deflated" -o "$plain" --deflate-level 0 -q

echo "load average at the start: $(cut -d' ' -f1-3 /proc/loadavg)"
start=$(date +%s.%N)
dd if=/dev/zero of="$out/dd.tmp" bs=8M count=128 conv=fsync status=none
echo "yardstick: writing 1 GiB to $out (dd, with fsync): $(echo "$(date +%s.%N) - $start" | bc) s"
rm -f "$out/dd.tmp"
for input in "$deflated" "$plain"; do
  cat "$input" > /dev/null  # into the page cache
  start=$(date +%s.%N)
  cat "$input" > /dev/null
  echo "yardstick: reading $(basename "$input") ($(du -h "$input" | cut -f1)) from the page cache: $(echo "$(date +%s.%N) - $start" | bc) s"
done

run() {  # run NAME INPUT FLAGS...
  local name=$1 input=$2
  shift 2
  /usr/bin/time -v "$bin/btf-compress" "$input" "$@" -o "$out/$name.h5" --json -q > "$out/$name.json" 2> "$out/$name.time"
  python3 - "$name" "$input" "$out/$name.json" "$out/$name.time" <<'PY'
import json, os, sys
name, path, summary, timing = sys.argv[1:]
s = json.load(open(summary))
t = {}
for line in open(timing):
    k, _, v = line.strip().rpartition(": ")
    t[k] = v
sh = s["shape"]
floats = sh["views"] * sh["lights"] * sh["height"] * sh["width"] * sh["channels"]
rss = int(t["Maximum resident set size (kbytes)"]) * 1024
phases = " ".join(f"{k} {v:.2f}" for k, v in s["seconds"].items())
print(f"{name:<19} {os.path.basename(path):<36} wall {t['Elapsed (wall clock) time (h:mm:ss or m:ss)']:>8}  "
      f"user {float(t['User time (seconds)']):6.1f} s  sys {float(t['System time (seconds)']):5.1f} s  "
      f"peak RSS {rss / 2**30:5.2f} GiB ({rss / (floats * 4):.2f}x float)  error {s['relative_error']:.6f}  "
      f"codec {s['codec_bytes'] / 2**20:.0f} MiB  [{phases}]")
PY
}
for input in "$deflated" "$plain"; do
  tag=$([[ $input == "$plain" ]] && echo "-plain" || echo "")
  for m in $methods; do
    case $m in
      pca-view) run "pca-view$tag" "$input" --method pca-view -c 16 ;;
      pca-view-half) run "pca-view-half$tag" "$input" --method pca-view -c 16 --storage half ;;
      lpca) run "lpca$tag" "$input" --method lpca -k 32 -c 8 ;;
    esac
    rm -f "$out/$m$tag.h5"
  done
done
echo "load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
