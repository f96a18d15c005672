#!/usr/bin/env bash
# The main job on the bundled sample data; called by `./run demo BIN SAMPLE_DATA OUT`.
# Each stage runs only if its tool exists in this build.
set -euo pipefail
bin=$1 data=$2 out=$3
step() { printf '\n==> %s\n' "$*" >&2; }

if [ -x "$bin/btf-synth" ]; then
  step "btf-synth: ground-truth BTF (Irawan 2006 twill) -> $out/gt.h5"
  "$bin/btf-synth" btf --model irawan2006 --preset twill --directions bonn81 --views 0,1,7,19 --lights 0,3,9 \
    --resolution 32 -o "$out/gt.h5" --quiet
  "$bin/btf-info" "$out/gt.h5" --no-stats
fi
echo
echo "Demo outputs are in $out"
