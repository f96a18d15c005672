#!/usr/bin/env bash
# The headline figures of docs/performance.md in one run, in this order: the peers (NumPy /
# scikit-learn, with their BLAS kernel and both GEMM rates; PyTorch's training step), then tool
# start-up and the tool against the library call. Each part prints its own table and load
# average. `./run bench` runs it after the benchmark programs.
#   bench/headline.sh [BUILD_DIR]   (default: build; needs the Python module, bench_compress and
#                                    bench_neural; the peers' packages: ./run bench installs them)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=${1:-build}
section() { printf '\n== %s\n' "$*"; }
section "ours against NumPy / scikit-learn (bench/vs_numpy.py)"
/usr/bin/python3 "$here/vs_numpy.py" "$build"
section "the neural training step against PyTorch's (bench/neural_vs_torch.py)"
/usr/bin/python3 "$here/neural_vs_torch.py" "$build"
section "tool start-up and the tool against the library (bench/startup.sh)"
"$here/startup.sh" "$build"
