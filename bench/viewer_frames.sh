#!/bin/bash
# Frame time of the WebGL2 viewer (docs/viewer.md, "Frame time"): renders a 16 x 16 bonn81 twill,
# exports it as LPCA (schneider-2004, k = 4, c = 4) and per-view PCA (sattler-2003, c = 4), and
# times FRAMES frames of each at 1280 x 720 in headless Chromium (SwiftShader: software WebGL2,
# so the CPU's speed, not a GPU's) with `btf-eval render-web --frames`; prints median and min ms.
#
#   bench/viewer_frames.sh [BUILD_DIR] [OUT_DIR]        environment: FRAMES (default 10)
set -euo pipefail
build=${1:-build}
out=${2:-bench-viewer}
bin=$(cd "$build/bin" && pwd)
frames=${FRAMES:-10}
mkdir -p "$out"
[ -f "$out/tw16.h5" ] || "$bin/btf-synth" btf --model irawan2006 --preset twill --directions bonn81 --resolution 16 \
  --samples 1 --quiet -o "$out/tw16.h5"
"$bin/btf-compress" "$out/tw16.h5" --method lpca --clusters 4 --components 4 --quiet -o "$out/lpca.h5"
"$bin/btf-compress" "$out/tw16.h5" --method pca-view --components 4 --quiet -o "$out/pv.h5"
printf '%-34s %12s %10s\n' export "median ms" "min ms"
for codec in lpca pv; do
  "$bin/btf-compress" export "$out/$codec.h5" --quiet -o "$out/$codec-export" >/dev/null
  "$bin/btf-eval" render-web "$out/$codec-export" -o "$out/$codec.png" --scene patch-point --size 1280x720 \
    --frames "$frames" --json --quiet >"$out/$codec.json"
  python3 - "$out/$codec.json" "$codec" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
f = j["benchmark"]
layout = {"lpca": "schneider-2004 (lpca k=4 c=4)", "pv": "sattler-2003 (pca-view c=4)"}[sys.argv[2]]
print(f"{layout:<34} {f['median_ms']:12.1f} {f['min_ms']:10.1f}")
PY
done
