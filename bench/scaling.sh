#!/bin/bash
# Distributed scaling benchmark (docs/scaling.md, "Measured scaling"): wall time and peak memory
# per rank of btf-synth btf, btf-compress --method pca-view, lpca, fmf and dfmf, and btf-eval
# compare on a bonn81 BTF, for 1, 2 and 4 local MPI ranks. Slow (minutes); not part of `./run test`.
#
#   bench/scaling.sh [BUILD_DIR] [OUT_DIR]
#
# Environment: RESOLUTION (default 128), RANKS (default "1 2 4"), SYNTH_VIEWS (views rendered by
# the timed btf-synth runs, default 0-80: all; the full-size input used by the other commands is
# rendered once, with the largest rank count), OMP_NUM_THREADS (default 1 per rank),
# LPCA_FLAGS (default "--clusters 8 --components 8"), PCA_FLAGS (default "--components 8"),
# FMF_FLAGS (fmf and dfmf, default "--components 16"), GT (an existing full-size input to
# compress and compare instead of the rendered one), COMMANDS (default
# "synth pca-view lpca fmf dfmf compare"; compare measures the lpca codec, so it needs lpca).
# Prints one line per (command, ranks) with each rank's seconds and peak RSS (from --json's
# per_rank), and writes them to OUT_DIR/scaling.tsv.
set -euo pipefail
build=${1:-build}
out=${2:-bench-scaling}
bin=$(cd "$build/bin" && pwd)
res=${RESOLUTION:-128}
ranks_list=${RANKS:-"1 2 4"}
synth_views=${SYNTH_VIEWS:-0-80}
lpca_flags=${LPCA_FLAGS:-"--clusters 8 --components 8"}
pca_flags=${PCA_FLAGS:-"--components 8"}
fmf_flags=${FMF_FLAGS:-"--components 16"}
commands=" ${COMMANDS:-synth pca-view lpca fmf dfmf compare} "
want() { [[ $commands == *" $1 "* ]]; }
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
mkdir -p "$out"
root=""
[ "$(id -u)" = 0 ] && root="--allow-run-as-root"
mpi() { mpirun $root --oversubscribe -x OMP_NUM_THREADS -np "$1" "${@:2}"; }
max_ranks=0
for r in $ranks_list; do [ "$r" -gt "$max_ranks" ] && max_ranks=$r; done

tsv="$out/scaling.tsv"
printf 'command\tranks\twall_s\trank\tseconds\tpeak_rss_mib\n' >"$tsv"
# run NAME RANKS CMD...: times the job and records each rank's figures from its --json.
run() {
  local name=$1 ranks=$2
  shift 2
  local t0 t1
  t0=$(date +%s.%N)
  mpi "$ranks" "$@" --json --quiet >"$out/$name-$ranks.json"
  t1=$(date +%s.%N)
  python3 - "$out/$name-$ranks.json" "$name" "$ranks" "$(echo "$t1 - $t0" | bc)" "$tsv" <<'EOF'
import json, sys
doc = json.load(open(sys.argv[1]))
name, ranks, wall, tsv = sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
assert doc["ranks"] == ranks, (doc["ranks"], ranks)
cells = []
with open(tsv, "a") as f:
    for r in doc["per_rank"]:
        mib = r["peak_rss_bytes"] / 2**20
        f.write(f"{name}\t{ranks}\t{wall:.1f}\t{r['rank']}\t{r['seconds']:.1f}\t{mib:.0f}\n")
        cells.append(f"r{r['rank']} {r['seconds']:.1f} s {mib:.0f} MiB")
print(f"{name:10s} {ranks} ranks  wall {wall:6.1f} s  " + ", ".join(cells))
EOF
}

echo "load before: $(uptime)"
gt=${GT:-$out/gt.h5}
synth=(btf --preset twill --directions bonn81 --resolution "$res" --samples 1)
for r in $ranks_list; do
  want synth || break
  run synth "$r" "$bin/btf-synth" "${synth[@]}" --views "$synth_views" -o "$out/synth-$r.h5"
  if [ -z "${GT:-}" ] && [ "$synth_views" = 0-80 ] && [ "$r" = "$max_ranks" ]; then mv "$out/synth-$r.h5" "$gt"; fi
  rm -f "$out/synth-$r.h5"
done
[ -f "$gt" ] || mpi "$max_ranks" "$bin/btf-synth" "${synth[@]}" --quiet -o "$gt" >/dev/null
for r in $ranks_list; do
  # shellcheck disable=SC2086
  want pca-view && run pca-view "$r" "$bin/btf-compress" "$gt" --method pca-view $pca_flags -o "$out/pca-$r.h5"
  # shellcheck disable=SC2086
  want lpca && run lpca "$r" "$bin/btf-compress" "$gt" --method lpca $lpca_flags -o "$out/lpca-$r.h5"
  for m in fmf dfmf; do
    # shellcheck disable=SC2086
    want $m && run $m "$r" "$bin/btf-compress" "$gt" --method $m $fmf_flags -o "$out/$m-$r.h5"
  done
  want compare && run compare "$r" "$bin/btf-eval" compare "$gt" "$out/lpca-$r.h5"
done
echo "load after: $(uptime)"
echo "figures: $tsv"
