"""Set before numpy loads: the matrices here are small (≤ a few hundred rows), where
OpenBLAS's threads cost more than they give (2–8× slower Cholesky on 2 cores, with
numba loaded).  A user's own setting wins."""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
