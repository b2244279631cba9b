"""The kernels' numeric helpers: the numba shim (``jit``: compiled when numba is importable, plain
Python otherwise), small-array reductions without numpy's call overhead (``fast``), small linear
algebra (``linalg``), the records the compiled kernels take (``records``) and the BLAS thread
limit (``threads``). Every other part of the core builds on these; they import none of it.
"""
