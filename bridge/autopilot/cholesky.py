"""A quadratic form through a Cholesky factor: the NEES of an estimate against its covariance.

In:  a symmetric n×n matrix C (row-major, n² values; NaN where unknown) and an n-vector e
Out: eᵀ C⁻¹ e, or NaN if C is not positive definite

Plain Python on sequences, so that :mod:`bridge.autopilot.estimator` runs it on a covariance's tuples
and :mod:`bridge.autopilot.ekfkernels` compiles the same source with numba for the EKF.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


def weighted_square(C: Sequence[float], e: Sequence[float]) -> float:
    """eᵀ C⁻¹ e for a symmetric n×n C (row-major, n = len(e)), by its Cholesky factor L (C = L Lᵀ,
    eᵀ C⁻¹ e = |L⁻¹ e|²); NaN unless C is positive definite (NaN entries: unknown). Plain Python that
    :mod:`bridge.autopilot.ekfkernels` compiles as it is (the EKF's NEES, every tenth control step)."""
    n = len(e)
    L = [0.0] * (n * n)
    total = 0.0
    z = [0.0] * n
    for i in range(n):
        for j in range(i + 1):
            s = C[n * i + j]
            for k in range(j):
                s -= L[n * i + k] * L[n * j + k]
            if i == j:
                if not (s > 0.0 and s < math.inf):  # NaN, zero, negative or infinite: not positive definite
                    return math.nan
                L[n * i + i] = math.sqrt(s)
            else:
                L[n * i + j] = s / L[n * j + j]
        s = e[i]  # forward substitution: row i of L is complete
        for k in range(i):
            s -= L[n * i + k] * z[k]
        z[i] = s / L[n * i + i]
        total += z[i] * z[i]
    return total
