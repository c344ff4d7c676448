"""Effective sample size: the integrated autocorrelation time of a residual. No rclpy.

SG smoothing and slow model errors make neighbouring samples far from independent; the plain
n would make every wiggle "significant". forward.py divides each block's sample count by
tau_int of what the step's terms leave (one n_eff per block, shared by all candidates).
``GRID_SCALES``: parameter fields profiled on a grid (reported without interval).
"""
from __future__ import annotations

import numpy as np

#: nonlinear scales profiled on a grid (fixed in bootstrap refits, so reported without CI)
GRID_SCALES = {'velocity_rad_s', 'exponent', 'time_constant_s', 't0_s', 'period_rad',
               'torque_smoothing_nm', 'offset_m'}


def tau_int(r: np.ndarray, max_lag: int = 300) -> float:
    """Integrated autocorrelation time of a series r (n,) (>= 1), summed to the first lag
    where the autocorrelation drops below 0.05."""
    r = np.asarray(r, float)
    r = r - r.mean()
    n = len(r)
    var = float(r @ r)
    if n < 4 or var <= 0:
        return 1.0
    f = np.fft.rfft(r, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[:min(max_lag, n - 1) + 1] / var
    s = 0.0
    for k in range(1, len(ac)):
        if ac[k] < 0.05:
            break
        s += ac[k]
    return max(1.0, 1.0 + 2.0 * s)
