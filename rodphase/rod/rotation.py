"""The matrix log of a rotation, shared by the laws of the kernel (kernel.py, neo_hookean.py)."""

import numpy as np

from ._jit import njit


@njit(cache=True, inline="always")
def log_factor(s2, cos_th):
    """θ/sinθ from sin²θ and cosθ, for the matrix log."""
    if s2 < 0.09 and cos_th > 0.0:
        # asin(s)/s = Σ (2k)! / (4^k (k!)² (2k+1)) s^{2k} to k = 9: truncation < 1e-12 for
        # s < 0.3 (θ < 17°), which covers a rod bent to a radius of 3 element lengths
        return 1.0 + s2 * (1.0 / 6.0 + s2 * (3.0 / 40.0 + s2 * (5.0 / 112.0 + s2 * (
            35.0 / 1152.0 + s2 * (63.0 / 2816.0 + s2 * (231.0 / 13312.0 + s2 * (
                143.0 / 10240.0 + s2 * (6435.0 / 557056.0 + s2 * 12155.0 / 1245184.0))))))))
    s = np.sqrt(s2)
    return np.arctan2(s, cos_th) / s
