"""core.numeric.threads: the node and the CLI run BLAS on one thread."""

from __future__ import annotations

import subprocess
import sys

import threadpoolctl  # noqa: F401  (required: in the lock; a broken install fails here)

CHILD = """
import numpy
from threadpoolctl import threadpool_info
from pose_lifter.core.numeric.threads import one_blas_thread
before = max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
assert one_blas_thread()
after = max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
print(before, after)
"""


def test_one_blas_thread_limits_the_process_blas() -> None:
    # a fresh interpreter without the test run's OMP_NUM_THREADS=1, so the limit is what changes it
    env = {"PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "2"}
    out = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, env=env, check=True)
    before, after = map(int, out.stdout.split())
    assert (before, after) == (2, 1)
