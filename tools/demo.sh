#!/usr/bin/env bash
# The main job on the bundled sample data; called by `./run demo` as: demo.sh BIN SAMPLE_DATA OUT.
# Part 1, measurement: 12 photos -> btf-register -> dataset, compared with its ground truth.
# Part 2, compression: a full Bonn-81 ground-truth BTF (81 views x 81 lights) -> btf-compress and
# btf-eval sweep (four codecs, the neural one among them: ratio, error, time, rendered comparison,
# HTML report) -> export.
# About 1.5 minutes on an idle 2-core machine before the neural codec joined the sweep, 5 minutes
# with it at load average 5-8 (docs/btf-eval.md, "The demo"; docs/performance.md).
set -euo pipefail
bin=$1 data=$2 out=$3
photos=$data/photos
start=$SECONDS
step() { printf '\n==> %s\n' "$*" >&2; }

step "1/7 btf-register: 12 photos (4 views x 3 lights) -> rectified, radiometrically normalised BTF dataset"
"$bin/btf-register" run "$photos/manifest.json" -o "$out/registered.h5" --resolution 32 \
  --report "$out/registration.json" --contact-sheet "$out/contact_sheet.png" --truth "$photos/truth.json" --quiet
"$bin/btf-info" "$out/registered.h5" --no-stats | head -8

step "2/7 btf-synth: the ground truth for the same directions and texel grid"
"$bin/btf-synth" btf --model irawan2006 --preset twill --directions bonn81 --views 0,1,7,19 --lights 0,3,9 \
  --resolution 32 --tiles 10 --irregularity 0.01 -o "$out/ground_truth.h5" --quiet

step "3/7 btf-eval compare: registered dataset against the ground truth"
# No --fail threshold: this step reports; tests/register guards the accuracy.
"$bin/btf-eval" compare "$out/ground_truth.h5" "$out/registered.h5" --json --quiet >"$out/registered_vs_truth.json"
"$bin/btf-eval" compare "$out/ground_truth.h5" "$out/registered.h5" --quiet | head -7

# With 3 lights a view slot has at most 2 centred components, so the registered dataset cannot
# show compression; a full Bonn-81 BTF can: per-view PCA stores about 81 / (c + 1) times less,
# LPCA about texels / (k (c + 1)) (docs/btf-compress.md).
step "4/7 btf-synth: full Bonn-81 ground truth, Irawan 2006 twill, 81 views x 81 lights x 64x64 texels (322 MB as float32)"
"$bin/btf-synth" btf --model irawan2006 --preset twill --directions bonn81 --resolution 64 -o "$out/twill81.h5" --quiet

step "5/7 btf-compress: per-view PCA, 8 components per view"
"$bin/btf-compress" "$out/twill81.h5" --method pca-view --components 8 -o "$out/codec_pca_view.h5" --quiet

step "6/7 btf-eval sweep: per-view PCA c = 8, LPCA and lpca-tensor k = 8, c = 8, neural latent 8: error, size, time, renders, report"
# The neural codec with a short training (2^20 samples, 4 epochs: 1024 steps), to keep the demo fast.
"$bin/btf-eval" sweep "$out/twill81.h5" -o "$out/sweep" --components 8 --clusters 8 --runs 1 --no-ssim \
  --neural-samples 1048576 --neural-epochs 4 --quiet >"$out/sweep_table.txt"

step "7/7 btf-compress export: the LPCA k = 8, c = 8 codec in the Schneider 2004 3D-texture layout"
"$bin/btf-compress" export "$out/sweep/codecs/lpca_k8_c8.h5" --format schneider -o "$out/export" --quiet

cat <<MSG

Demo outputs are in $out:
  registered.h5            BTF dataset from the photos (btf-register)
  registration.json        per-photo markers, reprojection RMS, homography, errors against truth.json
  contact_sheet.png        rectified views, for a person to look at
  ground_truth.h5          btf-synth ground truth; registered_vs_truth.json = btf-eval compare
  twill81.h5               full Bonn-81 twill BTF (btf-synth); codec_pca_view.h5 = btf-compress
  sweep/                   btf-eval sweep: results.json, plots (SVG), renders (PNG), codecs/
  export/                  renderer export of sweep/codecs/lpca_k8_c8.h5

Compression of twill81.h5 (btf-eval sweep; ratio = float32 size / stored bytes, rel = relative
L2 error, times in seconds on this machine):
$(cat "$out/sweep_table.txt")

Open the report (plots, results, grazing-light and environment renders) in a browser.
Demo time: $((SECONDS - start)) s.
MSG
