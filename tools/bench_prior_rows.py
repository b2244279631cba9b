"""The learned priors' layer pass per row at a few row counts, and what decides its speed here.

    OMP_NUM_THREADS=1 .venv/bin/python tools/bench_prior_rows.py [--rows 1 2 8 32 72] [--reps 5]

For the node's prior and the offline (temporal) prior: microseconds per row of the compiled layer
pass (:meth:`PosePrior._forward_small`, what the lift runs) and of the same network through
numpy's float32 matrix products (BLAS), for the network's inputs of random 2D skeletons (one
joint in ten missing); the median of ``--reps`` timings of about 600 rows each. One row reads
every weight (4-5 MB): at 1 row the pass is bound by reading them, at many rows by arithmetic.
Then the CPU model, numba's target, OpenBLAS's kernel (threadpoolctl) and whether any weight is a
subnormal float: the facts that differ between machines (docs/bench.md, the CPU kinds).
"""

from __future__ import annotations

import argparse
import functools
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pose_lifter.core.model.prior import DEFAULT_OFFLINE_PRIOR_PATH, PosePrior


def cpu_model() -> str:
    """The CPU's model name as /proc/cpuinfo gives it (else the platform's processor string)."""
    info = Path("/proc/cpuinfo")
    if info.is_file():
        for line in info.read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or "unknown"


def blas_forward(prior: PosePrior, x: NDArray[np.float32]) -> NDArray[np.float32]:
    """The prior's hidden and output layers (before de-standardising) through numpy's matrix
    products in float32."""
    layers = prior._layers32
    h = np.maximum(x @ layers[0][0] + layers[0][1], 0.0)
    for k in range(prior.blocks):
        (wa, ba), (wb, bb) = layers[1 + 2 * k], layers[2 + 2 * k]
        h = h + np.maximum(np.maximum(h @ wa + ba, 0.0) @ wb + bb, 0.0)
    out: NDArray[np.float32] = h @ layers[-1][0] + layers[-1][1]
    return out


def per_row_us(f: Callable[[], Any], rows: int, reps: int) -> float:
    """Median over ``reps`` timings of ``f`` (each repeated to about 600 rows), microseconds per row."""
    f()
    calls = max(1, 600 // rows)
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        for _ in range(calls):
            f()
        times.append((time.perf_counter() - t) / calls / rows * 1e6)
    return statistics.median(times)


def inputs(prior: PosePrior, rows: int, rng: np.random.Generator) -> NDArray[np.float32]:
    """The network's inputs (rows, 36 * window) for random 2D skeletons, one joint in ten missing."""
    w = prior.window
    pts = rng.normal(size=(rows, w, 12, 2))
    vis = rng.random((rows, w, 12)) > 0.1
    vis[..., :2] = True
    feats = [prior.features(pts[i, 0] if w == 1 else pts[i], vis[i, 0] if w == 1 else vis[i])[0]
             for i in range(rows)]
    return np.ascontiguousarray(np.stack(feats), dtype=np.float32)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rows", nargs="+", type=int, default=[1, 2, 8, 32, 72])
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    print(f"CPU: {cpu_model()}")
    try:
        import llvmlite.binding as llvm

        print(f"numba's target: {llvm.get_host_cpu_name()}")
    except ImportError:
        print("numba's target: numba not installed (the layer pass runs as numpy)")
    try:
        from threadpoolctl import threadpool_info

        blas = [f"{i.get('internal_api')} {i.get('version')} kernel {i.get('architecture')}, "
                f"{i.get('num_threads')} threads" for i in threadpool_info() if i.get("user_api") == "blas"]
        print(f"BLAS: {'; '.join(blas) or 'not found'}")
    except ImportError:
        print("BLAS: threadpoolctl not installed")
    for name, path in (("node's prior", None), ("offline prior", DEFAULT_OFFLINE_PRIOR_PATH)):
        prior = PosePrior.load(path)
        layers = prior._layers32
        size = sum(w.nbytes + b.nbytes for w, b in layers)
        tiny = np.finfo(np.float32).tiny
        sub = sum(int(np.count_nonzero((w != 0) & (np.abs(w) < tiny))) for w, _ in layers)
        print(f"\n{name}: window {prior.window}, {len(layers)} layers, "
              f"{size / 1e6:.2f} MB of float32 weights, {sub} subnormal")
        print(f"{'rows':>5}  {'compiled us/row':>15}  {'BLAS us/row':>11}")
        for n in args.rows:
            x = inputs(prior, n, rng)
            compiled = per_row_us(functools.partial(prior._forward_small, x), n, args.reps)
            gemm = per_row_us(functools.partial(blas_forward, prior, x), n, args.reps)
            print(f"{n:5d}  {compiled:15.1f}  {gemm:11.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
