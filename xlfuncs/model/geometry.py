"""Geometry of the six-factor model, defined once: squared distances between point sets, the
rotation sensitivity G_k of Forbes 2025 eq. (24) and the scale/squareness sensitivity G(u) of
eq. (11), and the rank-7 scale/squareness rows of a length (eq. 29 with eq. 11)."""

from __future__ import annotations

import numpy as np


def sq_dists(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances between the rows of A (n x c) and B (p x c): n x p.

    Summed from the coordinate differences, ``(a_x - b_x)^2 + ...``, never as
    |a|^2 + |b|^2 - 2 a.b: that form cancels (points 500 mm from the origin lose about
    5e-11 mm^2, and a point's distance to itself need not come out 0), which moves the
    kernels exp(-d^2/lambda^2) of eqs. (21), (25), (27) of close points.  Memory: the result
    only (no n x p x c temporary)."""
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    out = (A[:, 0][:, None] - B[:, 0][None, :]) ** 2
    for k in range(1, A.shape[1]):
        out += (A[:, k][:, None] - B[:, k][None, :]) ** 2
    return out


def skew(P: np.ndarray) -> np.ndarray:
    """G_k of Forbes 2025 eq. (24), the sensitivity of R(alpha) p to alpha at alpha = 0 (mm per
    rad), for every row p of P (n x 3, or one point): shape (n, 3, 3).  G_k^T n = n x p."""
    P = np.asarray(P, dtype=float).reshape(-1, 3)
    px, py, pz = P.T
    z = np.zeros_like(px)
    return np.stack([np.stack([z, pz, -py], -1), np.stack([-pz, z, px], -1),
                     np.stack([py, -px, z], -1)], -2)


def G_S(U: np.ndarray) -> np.ndarray:
    """G(u) of Forbes 2025 eq. (11), the 3 x 7 scale/squareness sensitivity at the ram position
    u = x - p_k (mm), for every row of U (n x 3, or one point): shape (n, 3, 7).  The seven
    columns are the b_aa, b_xx, b_yy, b_zz, b_xy, b_xz, b_yz of eq. (12)."""
    U = np.asarray(U, dtype=float).reshape(-1, 3)
    x, y, z = U.T
    o = np.zeros_like(x)
    return np.stack([np.stack([x, x, o, o, y, z, o], -1), np.stack([y, o, y, o, o, o, z], -1),
                     np.stack([z, o, o, z, o, o, o], -1)], -2)


def scale_rows(na: np.ndarray, du: np.ndarray) -> np.ndarray:
    """n^T G(du) for every row: the rank-7 scale/squareness rows of lengths (eqs. 11-14, 29),
    with C_S = g7 diag(V_B) g7^T; ``na`` unit directions, ``du`` = u_J - u_I the ram
    displacement (mm; G is linear in u, eq. 11)."""
    nx, ny, nz = na.T
    ux, uy, uz = du.T
    return np.column_stack([nx * ux + ny * uy + nz * uz, nx * ux, ny * uy, nz * uz, nx * uy, nx * uz, ny * uz])
