#!/usr/bin/env bash
# Tool start-up and the tools' own overhead, one plain-text table (docs/performance.md, "Tool
# start-up"):
#   1. every tool's `--version`: median wall time and median peak resident memory of RUNS runs;
#   2. per-view PCA with 16 components on a 64 x 64 bonn81 twill, through the tool
#      (`btf-compress IN --method pca-view -c 16 -o OUT`, the whole process) and through the
#      library (`libbtf.compress(...)` of the Python module, the call alone, after the import; the
#      first call in a fresh process, as the tool's, and a second one in the same process):
#      median of PCA_RUNS runs of each, alternated, and the tool / first call ratio.
# A benchmark, not a test: it asserts nothing (timings depend on the machine and its load, printed
# with them).
# Usage: bench/startup.sh [BUILD_DIR] [INPUT.h5]
#   BUILD_DIR  the build with the tools and the Python module (default: build)
#   INPUT.h5   default: BUILD_DIR/bench-twill64.h5, rendered with
#              `btf-synth btf --preset twill --directions bonn81 --resolution 64` when missing
#              (the file bench/vs_numpy.py uses)
# Environment: RUNS (default 10), PCA_RUNS (default 5).
set -euo pipefail
build=$(cd "${1:-build}" && pwd)
input=${2:-$build/bench-twill64.h5}
runs=${RUNS:-10} pca_runs=${PCA_RUNS:-5}
python=${PYTHON:-/usr/bin/python3}
[ -x /usr/bin/time ] || { echo "startup.sh: needs /usr/bin/time (Debian: time)" >&2; exit 2; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Median of the numbers on stdin.
median() { sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
# Runs "$@" once: prints "wall_seconds peak_rss_kib" (wall from bash's clock, RSS from time(1)).
measure() {
  local t0 t1
  t0=$EPOCHREALTIME
  /usr/bin/time -f '%M' -o "$work/rss" "$@" >/dev/null 2>"$work/err" || { cat "$work/err" >&2; exit 1; }
  t1=$EPOCHREALTIME
  echo "$(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.4f", b - a }') $(tail -1 "$work/rss")"
}

echo "load average: $(cut -d' ' -f1-3 /proc/loadavg), $(nproc) CPUs"
printf '%-14s %12s %14s   (%d runs of --version)\n' tool "median ms" "peak RSS MiB" "$runs"
for exe in "$build"/bin/btf-*; do
  [ -x "$exe" ] || continue
  : >"$work/runs"
  for _ in $(seq "$runs"); do measure "$exe" --version >>"$work/runs"; done
  ms=$(cut -d' ' -f1 "$work/runs" | median | awk '{ printf "%.1f", $1 * 1000 }')
  mib=$(cut -d' ' -f2 "$work/runs" | median | awk '{ printf "%.1f", $1 / 1024 }')
  printf '%-14s %12s %14s\n' "$(basename "$exe")" "$ms" "$mib"
done

if [ ! -f "$input" ]; then
  echo "rendering $input (once)" >&2
  "$build/bin/btf-synth" btf --preset twill --directions bonn81 --resolution 64 --quiet -o "$input"
fi
: >"$work/tool" && : >"$work/lib" && : >"$work/lib2"
for _ in $(seq "$pca_runs"); do
  measure "$build/bin/btf-compress" "$input" --method pca-view -c 16 --quiet -o "$work/tool.h5" | cut -d' ' -f1 >>"$work/tool"
  # The call twice: the first is what a fresh process (the tool's case) pays; the second reuses the
  # memory the first one's allocator kept (fewer page faults).
  PYTHONPATH=$build/python "$python" -c "
import sys, time, libbtf
for _ in range(2):
    t = time.perf_counter()
    libbtf.compress(sys.argv[1], sys.argv[2], method='pca-view', components=16)
    print(f'{time.perf_counter() - t:.4f}', end=' ')" "$input" "$work/lib.h5" >"$work/pair"
  cut -d' ' -f1 "$work/pair" >>"$work/lib"
  cut -d' ' -f2 "$work/pair" >>"$work/lib2"
done
tool=$(median <"$work/tool") lib=$(median <"$work/lib") lib2=$(median <"$work/lib2")
echo
echo "per-view PCA, 16 components, $(basename "$input") (median of $pca_runs runs each):"
printf '  btf-compress (whole process)                    %8.3f s\n' "$tool"
printf '  libbtf.compress, first call in a Python process %8.3f s\n' "$lib"
printf '  libbtf.compress, second call in that process    %8.3f s\n' "$lib2"
awk -v a="$tool" -v b="$lib" 'BEGIN { printf "  tool / library (first call)                     %8.2f\n", a / b }'
