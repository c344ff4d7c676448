"""Denavit-Hartenberg forward kinematics, thesis eq. 3.2-3.4 (a plain reference, numpy only).

Kept independent of the URDF/pinocchio model on purpose: tests compare the two.
"""
from __future__ import annotations

import numpy as np


def dh_matrix(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """A_i = Rot_z(theta) Trans_z(d) Trans_x(a) Rot_x(alpha), (4, 4) (eq. 3.2-3.3)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([
        [ct, -st * ca, st * sa, a * ct],
        [st, ct * ca, -ct * sa, a * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ])


def dh_forward(q: np.ndarray, a: np.ndarray, alpha: np.ndarray, d: np.ndarray,
               offset: np.ndarray) -> np.ndarray:
    """T_6^0 = A_1 ... A_6 (eq. 3.4), (4, 4); q (6,) [rad], a, d [m], alpha, offset [rad]."""
    T = np.eye(4)
    for i in range(6):
        T = T @ dh_matrix(q[i] + offset[i], d[i], a[i], alpha[i])
    return T
