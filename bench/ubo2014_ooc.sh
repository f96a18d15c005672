#!/bin/bash
# Out-of-core benchmark (docs/btf-compress.md "Out-of-core LPCA" and "Neural codec"): writes the
# benchmarks' synthetic BTF (bench/synthetic_btf.h; synthetic, not a material model) slot by slot
# with bench_synthetic_input, then runs btf-compress --method lpca -k 32 -c 8 --lpca-memory
# out-of-core (METHOD=neural: --method neural, default options but the log epsilon; the training set is drawn in one
# streaming pass) under /usr/bin/time -v and prints its wall time, peak memory, passes and
# per-phase seconds.
# Slow: the default is the UBO2014 size (ubo151 directions, 400^2 texels, RGB: 43.8 GB of input,
# hours); set RESOLUTION / DIRECTIONS for a reduced run, and BTF_MAX_BYTES to force streaming.
#
#   bench/ubo2014_ooc.sh BUILD_DIR OUT_DIR
#
# Environment: DIRECTIONS (default ubo151), RESOLUTION (default 400), METHOD (lpca, the default, or
# neural), LPCA_FLAGS (default "-k 32 -c 8"), NEURAL_FLAGS (default "--log-epsilon 1": the
# synthetic values dip slightly below 0, outside the neural codec's log domain at the default
# epsilon), BTF_MAX_BYTES (the memory limit LPCA streams within; default: the library's).
set -euo pipefail
build=${1:?usage: bench/ubo2014_ooc.sh BUILD_DIR OUT_DIR}
out=${2:?usage: bench/ubo2014_ooc.sh BUILD_DIR OUT_DIR}
bin=$(cd "$build/bin" && pwd)
dirs=${DIRECTIONS:-ubo151}
res=${RESOLUTION:-400}
lpca_flags=${LPCA_FLAGS:-"-k 32 -c 8"}
neural_flags=${NEURAL_FLAGS:-"--log-epsilon 1"}
mkdir -p "$out"
input="$out/synthetic_${dirs}_${res}.h5"
if [[ ! -f $input ]]; then
  start=$(date +%s.%N)
  "$bin/bench_synthetic_input" "$dirs" "$res" "$input"
  echo "input: $input ($(du -h "$input" | cut -f1)) written in $(echo "$(date +%s.%N) - $start" | bc) s"
fi
method=${METHOD:-lpca}
case $method in
  lpca) flags=(--method lpca $lpca_flags --lpca-memory out-of-core) ;;
  neural) flags=(--method neural $neural_flags) ;;
  *) echo "METHOD must be lpca or neural" >&2; exit 2 ;;
esac
/usr/bin/time -v "$bin/btf-compress" "$input" "${flags[@]}" -o "$out/$method.h5" --json > "$out/summary.json" 2> "$out/time.txt"
wall=$(grep "Elapsed (wall clock)" "$out/time.txt" | awk '{print $NF}')
rss_kib=$(grep "Maximum resident set size" "$out/time.txt" | awk '{print $NF}')
python3 - "$out/summary.json" "$wall" "$rss_kib" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
sh = s["shape"]
floats = sh["views"] * sh["lights"] * sh["height"] * sh["width"] * sh["channels"]
rss = int(sys.argv[3]) * 1024
print(f"shape {sh['views']} x {sh['lights']} x {sh['height']}^2 x {sh['channels']}: float32 dataset {floats * 4 / 2**30:.3f} GiB")
print(f"wall {sys.argv[2]}, peak RSS {rss / 2**30:.3f} GiB ({rss / (floats * 4):.3f} x the float dataset)")
if "lpca_memory" in s:
    m = s["lpca_memory"]
    print(f"mode {m['mode']}, {m['input_passes']} passes over the input, relative error {s['relative_error']:.5f}")
else:
    print(f"{s['method']}: relative error {s['relative_error']:.5f}, {s.get('codec_bytes', 0):,} codec bytes")
print("seconds " + " ".join(f"{k} {v:.1f}" for k, v in s["seconds"].items()))
PY
