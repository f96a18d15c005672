#!/usr/bin/env bash
# The main job on the bundled sample data; called by `./run demo` as: demo.sh BIN SAMPLE_DATA OUT.
# photos -> btf-register -> dataset -> (vs ground truth) -> btf-compress -> export -> btf-eval sweep.
set -euo pipefail
bin=$1 data=$2 out=$3
photos=$data/photos
step() { printf '\n==> %s\n' "$*" >&2; }

step "1/6 btf-register: 12 photos -> rectified, radiometrically normalised BTF dataset"
"$bin/btf-register" run "$photos/manifest.json" -o "$out/registered.h5" --resolution 32 \
  --report "$out/registration.json" --contact-sheet "$out/contact_sheet.png" --truth "$photos/truth.json" --quiet
"$bin/btf-info" "$out/registered.h5" --no-stats | head -8

step "2/6 btf-synth: the ground truth for the same directions and texel grid"
"$bin/btf-synth" btf --model irawan2006 --preset twill --directions bonn81 --views 0,1,7,19 --lights 0,3,9 \
  --resolution 32 --tiles 10 --irregularity 0.01 -o "$out/ground_truth.h5" --quiet

step "3/6 btf-eval compare: registered dataset against the ground truth"
# No --fail threshold: this step reports; tests/register guards the accuracy.
"$bin/btf-eval" compare "$out/ground_truth.h5" "$out/registered.h5" --json --quiet >"$out/registered_vs_truth.json"
"$bin/btf-eval" compare "$out/ground_truth.h5" "$out/registered.h5" --quiet | head -7

step "4/6 btf-compress: per-view PCA and local PCA codecs"
"$bin/btf-compress" "$out/registered.h5" --method pca-view --components 4 -o "$out/codec_pca_view.h5" --quiet
"$bin/btf-compress" "$out/registered.h5" --method lpca --clusters 8 --components 4 -o "$out/codec_lpca.h5" --quiet
"$bin/btf-info" "$out/codec_lpca.h5" | head -12

step "5/6 btf-compress export: Schneider 2004 3D-texture layout for renderers"
"$bin/btf-compress" export "$out/codec_lpca.h5" --format schneider -o "$out/export" --quiet

step "6/6 btf-eval sweep: error against size and run time, rendered comparison, HTML report"
"$bin/btf-eval" sweep "$out/registered.h5" -o "$out/sweep" --components 1,2,4,8 --clusters 4,8 --runs 3 --quiet

cat <<MSG

Demo outputs are in $out:
  registered.h5            BTF dataset from the photos (btf-register)
  registration.json        per-photo markers, reprojection RMS, homography, errors against truth.json
  contact_sheet.png        rectified views, for a person to look at
  ground_truth.h5          btf-synth ground truth; registered_vs_truth.json = btf-eval compare
  codec_pca_view.h5, codec_lpca.h5   codecs (btf-compress); export/ = renderer export
  sweep/report.html        HTML report: error vs size and run time, Pareto fronts, rendered comparison
MSG
