"""What a fair peer needs, shared by bench/vs_numpy.py and bench/neural_vs_torch.py.

OPENBLAS_CORETYPE and OPENBLAS_L2_SIZE, set on some machines for old OpenBLAS builds, force a
current OpenBLAS onto an older kernel and slow NumPy and PyTorch. fair_environment() re-executes
the script without them before either library loads (ours does not use OpenBLAS) and returns what
it unset; blas_kernel() names the BLAS the peer runs.
"""
import os
import sys

SLOWING = ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE")
_MARK = "BTF_PEER_UNSET"


def fair_environment():
    """Call before importing NumPy or PyTorch. Returns the unset variables as 'NAME=value,...' ('' if none)."""
    if any(v in os.environ for v in SLOWING):
        env = {k: v for k, v in os.environ.items() if k not in SLOWING}
        env[_MARK] = ",".join(f"{v}={os.environ[v]}" for v in SLOWING if v in os.environ)
        os.execve(sys.executable, [sys.executable, *sys.argv], env)
    return os.environ.get(_MARK, "")


def blas_kernel():
    """(words, optimised): the BLAS loaded in this process (threadpoolctl; Debian
    python3-threadpoolctl) and whether it is an optimised one (OpenBLAS, BLIS or MKL; Debian's
    reference libblas3 is not, and threadpoolctl does not list it)."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return "unknown (threadpoolctl missing: Debian python3-threadpoolctl)", False
    blas = [i for i in threadpool_info() if i.get("user_api") == "blas"]
    words = "; ".join(f"{i.get('internal_api')} {i.get('version')} kernel {i.get('architecture')} "
                      f"threads {i.get('num_threads')}" for i in blas)
    if not words:
        return "none that threadpoolctl knows: the reference BLAS (Debian: install libopenblas0-pthread)", False
    return words, True
