#!/bin/bash
# The neural codec against the linear codecs (docs/btf-compress.md "Neural codec", docs/performance.md
# "Neural codec against the linear codecs"), one run, the same files for every codec:
#   1. quality per byte: btf-synth twill and denim at RESOLUTION² (bonn81); lpca-tensor at
#      --bytes TENSOR_BYTES (its relative error and bytes), then the neural codec at the smallest
#      latent width of NEURAL_LATENTS whose relative error is at most lpca-tensor's (its bytes and
#      the ratio);
#   2. directions never trained on: every codec trained on the even bonn81 views x even lights
#      (41 x 41) at about the neural codec's bytes (the linear ones with --bytes), then compared
#      with btf-synth's truth at the odd views x odd lights (40 x 40, held out) and at RANDOM x
#      RANDOM random directions (a file of theta/phi, fixed seed; theta up to 75 deg), decoded there
#      by btf-eval compare (Codec::Value: the neural decoder at those directions, the linear
#      codecs' barycentric blend of the sampled ones);
#   3. speed: each neural training's seconds (btf-compress --json, "train") with the load average
#      when it ran; bench_neural's training step (GFLOP/s as a fraction of the 1024^3 float GEMM
#      rate measured in the same run, one thread) and decode rate (values/s per core).
# Slow (tens of minutes at 128²); not part of `./run test`.
#
#   bench/neural_vs_linear.sh [BUILD_DIR] [OUT_DIR]
#
# Environment: RESOLUTION (128), MATERIALS ("twill denim"), SYNTH_SAMPLES (btf-synth --samples, 2),
# TENSOR_BYTES (3000000), NEURAL_LATENTS ("4 8 16 32", tried in this order), NEURAL_FLAGS (extra
# btf-compress flags for the neural codec, e.g. "--neural-epochs 8"), HELD_OUT_METHODS
# ("pca-view lpca lpca-tensor"; a method that does not fit the bytes is said so, then measured at
# its smallest setting: pca-view -c 1, lpca -k 8 -c 1, lpca-tensor -k 8 -c 4 --quant-bits 8 with the
# bytes), RANDOM_DIRECTIONS (24), PARTS ("quality held-out speed"), REUSE (1: keep codecs already
# in OUT_DIR). The synthesised BTFs in OUT_DIR are always reused. Prints the tables and writes them
# to OUT_DIR/neural_vs_linear.txt.
set -euo pipefail
build=${1:-build}
out=${2:-bench-neural}
bin=$(cd "$build/bin" && pwd)
res=${RESOLUTION:-128}
materials=${MATERIALS:-"twill denim"}
synth_samples=${SYNTH_SAMPLES:-2}
tensor_bytes=${TENSOR_BYTES:-3000000}
latents=${NEURAL_LATENTS:-"4 8 16 32"}
neural_flags=${NEURAL_FLAGS:-}
held_methods=${HELD_OUT_METHODS:-"pca-view lpca lpca-tensor"}
random_count=${RANDOM_DIRECTIONS:-24}
parts=" ${PARTS:-quality held-out speed} "
want() { [[ $parts == *" $1 "* ]]; }
mkdir -p "$out"
report="$out/neural_vs_linear.txt"
: >"$report"
say() { printf '%s\n' "$*" | tee -a "$report"; }
load() { cut -d' ' -f1 /proc/loadavg; }
# json FILE KEY.KEY...: one value of a JSON file (python3).
json() {
  python3 - "$@" <<'EOF'
import json, sys
v = json.load(open(sys.argv[1]))
for k in sys.argv[2].split("."):
    v = v[int(k)] if isinstance(v, list) else v[k]
print(v)
EOF
}

model_flags() {
  case $1 in
    twill) echo "--model irawan2006 --preset twill" ;;
    denim) echo "--model irawan2012 --preset cotton_denim" ;;
    *) echo "unknown material $1 (twill or denim)" >&2; exit 2 ;;
  esac
}
# synth MATERIAL FILE [btf-synth flags]: renders FILE unless it exists.
synth() {
  local m=$1 f=$2
  shift 2
  [ -f "$f" ] && return 0
  # shellcheck disable=SC2046
  "$bin/btf-synth" btf $(model_flags "$m") --resolution "$res" --samples "$synth_samples" "$@" -o "$f" --quiet >/dev/null
}
# compress IN OUT.h5 FLAGS...: btf-compress --json into OUT.json; returns non-zero if refused.
compress() {
  local in=$1 codec=$2
  shift 2
  [ "${REUSE:-0}" = 1 ] && [ -f "$codec" ] && [ -f "${codec%.h5}.json" ] && return 0
  load >"${codec%.h5}.load"  # the load average when it started, for the tables
  "$bin/btf-compress" "$in" "$@" -o "$codec" --json --quiet >"${codec%.h5}.json" 2>"${codec%.h5}.err"
}
# rel REFERENCE CODEC: btf-eval compare's relative L2 error (decoded at REFERENCE's directions).
rel() {
  "$bin/btf-eval" compare "$1" "$2" --no-ssim --json --quiet >"${2%.h5}_vs_$(basename "${1%.h5}").json"
  json "${2%.h5}_vs_$(basename "${1%.h5}").json" rel_l2
}

say "neural_vs_linear.sh: ${res}² bonn81 (btf-synth --samples $synth_samples), $(nproc) cores, $(date -u +%Y-%m-%d)"
declare -A neural_latent neural_bytes
if want quality; then
  say ""
  say "Quality per byte: lpca-tensor --bytes $tensor_bytes against the smallest neural codec at its error"
  say "$(printf '%-8s %-34s %12s %10s %9s %9s %6s' material codec bytes rel_l2 train_s total_s load)"
  for m in $materials; do
    gt="$out/$m.h5"
    synth "$m" "$gt"
    t0=$SECONDS
    compress "$gt" "$out/${m}_tensor.h5" --method lpca-tensor --bytes "$tensor_bytes"
    l0=$(cat "$out/${m}_tensor.load" 2>/dev/null || echo -)
    tb=$(json "$out/${m}_tensor.json" codec_bytes) te=$(json "$out/${m}_tensor.json" relative_error)
    say "$(printf '%-8s %-34s %12s %10.6f %9s %9d %6s' "$m" "lpca-tensor --bytes $tensor_bytes" "$tb" "$te" - $((SECONDS - t0)) "$l0")"
    for c in $latents; do
      t0=$SECONDS
      # shellcheck disable=SC2086
      compress "$gt" "$out/${m}_neural_c$c.h5" --method neural --neural-latent "$c" $neural_flags
      l0=$(cat "$out/${m}_neural_c$c.load" 2>/dev/null || echo -)
      nb=$(json "$out/${m}_neural_c$c.json" codec_bytes) ne=$(json "$out/${m}_neural_c$c.json" relative_error)
      ts=$(json "$out/${m}_neural_c$c.json" seconds.train)
      say "$(printf '%-8s %-34s %12s %10.6f %9.1f %9d %6s' "$m" "neural --neural-latent $c" "$nb" "$ne" "$ts" $((SECONDS - t0)) "$l0")"
      neural_latent[$m]=$c neural_bytes[$m]=$nb
      if python3 -c "import sys; sys.exit(0 if $ne <= $te else 1)"; then
        say "$(printf '%-8s neural c = %s reaches lpca-tensor'"'"'s error with %s bytes: %.2fx fewer' "$m" "$c" "$nb" \
          "$(python3 -c "print($tb / $nb)")")"
        break
      fi
    done
  done
fi

if want held-out; then
  say ""
  say "Directions never trained on: trained on bonn81 even views x even lights (41 x 41), measured at"
  say "the odd views x odd lights (40 x 40) and at $random_count x $random_count random directions (relative L2)"
  # Random directions: theta uniform in cos theta over [0, 75 deg], phi uniform, seed 1.
  python3 - "$out/random_dirs.txt" "$random_count" <<'EOF'
import math, random, sys
rng = random.Random(1)
with open(sys.argv[1], "w") as f:
    for _ in range(int(sys.argv[2])):
        ct = 1 - rng.random() * (1 - math.cos(math.radians(75)))
        f.write(f"{math.degrees(math.acos(ct)):.6f} {rng.random() * 360:.6f}\n")
EOF
  even=$(seq -s, 0 2 80) odd=$(seq -s, 1 2 79)
  say "$(printf '%-8s %-42s %10s %10s %10s %10s %9s %6s' material codec bytes trained held_out random train_s load)"
  for m in $materials; do
    synth "$m" "$out/${m}_train.h5" --directions bonn81 --views "$even" --lights "$even"
    synth "$m" "$out/${m}_held.h5" --directions bonn81 --views "$odd" --lights "$odd"
    synth "$m" "$out/${m}_random.h5" --directions "$out/random_dirs.txt"
    c=${neural_latent[$m]:-${HELD_OUT_LATENT:-8}}
    # shellcheck disable=SC2086
    compress "$out/${m}_train.h5" "$out/${m}_sub_neural.h5" --method neural --neural-latent "$c" $neural_flags
    l0=$(cat "$out/${m}_sub_neural.load" 2>/dev/null || echo -)
    nb=$(json "$out/${m}_sub_neural.json" codec_bytes)
    say "$(printf '%-8s %-42s %10s %10.6f %10.6f %10.6f %9.1f %6s' "$m" "neural --neural-latent $c" "$nb" \
      "$(json "$out/${m}_sub_neural.json" relative_error)" "$(rel "$out/${m}_held.h5" "$out/${m}_sub_neural.h5")" \
      "$(rel "$out/${m}_random.h5" "$out/${m}_sub_neural.h5")" "$(json "$out/${m}_sub_neural.json" seconds.train)" "$l0")"
    for method in $held_methods; do
      f="$out/${m}_sub_$method.h5"
      label="$method --bytes $nb"
      if ! compress "$out/${m}_train.h5" "$f" --method "$method" --bytes "$nb"; then
        say "$(printf '%-8s %-42s %s' "$m" "$label" "does not fit ($(grep -o 'below [^(;]*' "${f%.h5}.err" | head -1))")"
        case $method in
          pca-view) small=(-c 1) ;;
          lpca) small=(-k 8 -c 1) ;;
          lpca-tensor) small=(-k 8 -c 4 --quant-bits 8 --bytes "$nb") ;;
          *) continue ;;
        esac
        f="$out/${m}_sub_${method}_small.h5" label="$method ${small[*]}"
        compress "$out/${m}_train.h5" "$f" --method "$method" "${small[@]}" || continue
      fi
      say "$(printf '%-8s %-42s %10s %10.6f %10.6f %10.6f %9s %6s' "$m" "$label" \
        "$(json "${f%.h5}.json" codec_bytes)" "$(json "${f%.h5}.json" relative_error)" \
        "$(rel "$out/${m}_held.h5" "$f")" "$(rel "$out/${m}_random.h5" "$f")" - -)"
    done
  done
fi

if want speed; then
  say ""
  say "Speed: bench_neural (one thread unless /2; load $(load) when it started)"
  "$bin/bench_neural" --benchmark_filter='BM_NeuralEigenGemm|BM_NeuralGemmShapes|BM_NeuralStep|BM_NeuralDecode' \
    --benchmark_format=json --benchmark_out="$out/bench_neural.json" >/dev/null 2>"$out/bench_neural.err"
  python3 - "$out/bench_neural.json" <<'EOF' | tee -a "$report"
import json, sys
for b in json.load(open(sys.argv[1]))["benchmarks"]:
    keys = [k for k in ("GFLOPs", "of_eigen_1024", "of_same_shapes", "samples_per_s", "values_per_s",
                        "values_per_s_per_core") if k in b]
    print(f"{b['name']:32s} " + "  ".join(f"{k} {b[k]:.4g}" for k in keys))
EOF
fi
say ""
say "load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
