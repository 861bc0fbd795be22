"""Minimum-zone (Chebyshev) form in small-angle form, solved in numpy by an exchange
(revised simplex) algorithm on the dual linear program, with the active-set sensitivities.

The linearised minimum-zone problem (ISO 12781-1 flatness, ISO 12780-1 straightness,
ISO 12181-1 roundness, ISO 12180-1 cylindricity: the minimum zone, "MZ", reference) is, for
residuals d_i of the points to a reference feature and their derivatives -g_i with respect to
the k free parameters p of the zone's orientation/location (small angles and small shifts),

    minimise  u - l   over p, u, l   subject to   l <= d_i - g_i^T p <= u     (i = 1..m).   (P)

Its dual (variables lambda_i, mu_i >= 0 attached to the upper and lower constraints) is

    maximise  sum_i (lambda_i - mu_i) d_i
    subject to  sum lambda = 1,  sum mu = 1,  sum (lambda_i - mu_i) g_i = 0,                (D)

a standard-form LP with only k + 2 rows.  The revised simplex method on (D) is the classical
Chebyshev exchange algorithm: the basis holds k + 2 "contact" points (upper and lower), each
iteration exchanges one.  The simplex multipliers of the optimal basis are (u, -l, p) of (P).

Sensitivity (the value is a maximum of smooth functions, not smooth itself): at an optimal basis
that stays optimal under a small change of the data, h = sum_i w_i d_i with w = lambda - mu fixed,
so dh/dd_i = w_i, and a point moved by delta x_i along the reference feature's normal n_i changes
h by w_i n_i^T delta x_i (the change of g is of second order: it is multiplied by p, itself of
the order of the form deviation over the feature's length).  w is non-zero only at the active
(extreme) points.  Where two active sets compete (a degenerate optimum, or draws of the
measurement errors that change the contact points) the true distribution of h is not that of the
linearisation: the Monte Carlo over V_X says by how much (tests/core/test_characteristics.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ConvergenceError, ModelError

__all__ = ["Zone", "chebyshev_zone", "basis_is_optimal"]


@dataclass(frozen=True)
class Zone:
    """The solution of (P)/(D): width ``h`` = u - l, the free parameters ``p``, the zone limits
    ``upper`` and ``lower`` (in the units of d), the dual weights ``w`` = lambda - mu (one per
    point; dh/dd), the optimal ``basis`` (column indices of (D): i for lambda_i, m + i for mu_i)
    and the number of exchanges."""

    h: float
    p: np.ndarray
    upper: float
    lower: float
    w: np.ndarray
    basis: np.ndarray
    iterations: int

    @property
    def active(self) -> np.ndarray:
        """Indices of the contact points (w != 0)."""
        return np.flatnonzero(self.w != 0.0)


def _columns(g: np.ndarray) -> np.ndarray:
    """The constraint matrix A of (D), (k + 2) x 2m."""
    m, k = g.shape
    A = np.zeros((k + 2, 2 * m))
    A[0, :m] = 1.0
    A[1, m:] = 1.0
    A[2:, :m] = g.T
    A[2:, m:] = -g.T
    return A


def _start_basis(g: np.ndarray) -> np.ndarray:
    """A feasible (degenerate) starting basis: lambda_0 = mu_0 = 1, completed by k columns
    lambda_j for which the g_j - g_0 are linearly independent (greedy, by Gram-Schmidt)."""
    m, k = g.shape
    D = g - g[0]
    chosen: list[int] = []
    Q = np.zeros((k, 0))
    scale = float(np.max(np.abs(D))) if D.size else 0.0
    for j in np.argsort(-np.linalg.norm(D, axis=1), kind="stable"):
        if len(chosen) == k:
            break
        v = D[j] - Q @ (Q.T @ D[j])
        nv = float(np.linalg.norm(v))
        if nv > 1e-9 * scale:
            chosen.append(int(j))
            Q = np.column_stack([Q, v / nv])
    if len(chosen) < k:
        raise ModelError("minimum zone: the points do not determine the zone's orientation "
                         f"and location ({len(chosen)} of {k} free parameters)")
    return np.array([0, m] + chosen, dtype=int)


def chebyshev_zone(d, g, *, basis=None, max_iter: int | None = None) -> Zone:
    """Solve (P) for residuals d (m) and free-parameter derivatives g (m x k).

    ``basis``: a starting basis of (D) (e.g. the optimum of a nearby problem); it is used if it
    is feasible, otherwise the solver starts afresh.  Dantzig's rule, with Bland's rule after
    degenerate exchanges (no cycling).  Raises ModelError for non-finite input and
    ConvergenceError if ``max_iter`` exchanges do not reach the optimum.
    """
    d = np.asarray(d, dtype=float).reshape(-1)
    g = np.asarray(g, dtype=float)
    m = d.size
    if g.ndim != 2 or g.shape[0] != m:
        raise ModelError("minimum zone: g must have one row per residual")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(g))):
        raise ModelError("minimum zone: residuals and their derivatives must be finite")
    k = g.shape[1]
    if m < k + 2:
        raise ModelError(f"minimum zone: {k} free parameters need at least {k + 2} points, got {m}")
    # scaling: d to O(1), every column of g to O(1); p is scaled back at the end
    sd = float(np.max(np.abs(d - d.mean()))) or 1.0
    sg = np.max(np.abs(g - g.mean(axis=0)), axis=0)
    sg = np.where(sg > 0, sg, 1.0)
    ds, gs = (d - d.mean()) / sd, g / sg
    A = _columns(gs)
    c = np.concatenate([ds, -ds])
    b = np.zeros(k + 2)
    b[:2] = 1.0
    tol = 1e-11
    B = None
    if basis is not None:
        B = np.asarray(basis, dtype=int).copy()
        try:
            xB = np.linalg.solve(A[:, B], b)
            if np.any(xB < -tol):
                B = None
        except np.linalg.LinAlgError:
            B = None
    if B is None:
        B = _start_basis(gs)
        xB = np.linalg.solve(A[:, B], b)
    max_iter = max_iter or 50 * (2 * m + k + 2)
    bland = False
    degenerate = 0
    for it in range(max_iter + 1):
        AB = A[:, B]
        y = np.linalg.solve(AB.T, c[B])
        r = c - y @ A
        r[B] = 0.0
        cand = np.flatnonzero(r > tol)
        if cand.size == 0:
            break
        j = int(cand[0]) if bland else int(cand[np.argmax(r[cand])])
        dB = np.linalg.solve(AB, A[:, j])
        pos = dB > tol
        if not np.any(pos):
            raise ConvergenceError("minimum zone: the dual problem is unbounded (cannot happen "
                                   "for finite data; check the input)")
        ratios = np.full(dB.shape, np.inf)
        ratios[pos] = np.clip(xB[pos], 0.0, None) / dB[pos]
        t = float(ratios.min())
        ties = np.flatnonzero(ratios <= t + tol)
        leave = int(ties[np.argmin(B[ties])])   # smallest column index among the ties (Bland)
        if t <= tol:
            degenerate += 1
            if degenerate > 2 * (k + 2):
                bland = True
        else:
            degenerate = 0
        xB = xB - t * dB
        xB[leave] = t
        B[leave] = j
        xB = np.linalg.solve(A[:, B], b)    # re-solve: k + 2 is small, rounding does not build up
    else:
        raise ConvergenceError(f"minimum zone: no optimum after {max_iter} exchanges")
    y = np.linalg.solve(A[:, B].T, c[B])
    x = np.zeros(2 * m)
    x[B] = np.clip(xB, 0.0, None)
    w = x[:m] - x[m:]
    p = y[2:] / sg * sd
    e = d - g @ p
    upper, lower = float(e.max()), float(e.min())
    return Zone(h=upper - lower, p=p, upper=upper, lower=lower, w=w, basis=B, iterations=it)


def basis_is_optimal(d, g, basis, tol: float = 1e-9, feasibility: float = 1e-6):
    """Vectorised check of a given basis for a batch of problems d (M x m), g (M x m x k):
    (ok (M,), h (M,), w (M x m)).  ``ok`` is True where the basis is optimal for that problem
    (its multipliers (u, -l, p) satisfy every constraint of (P): u - l = h is the width of a
    feasible zone, an upper bound of the minimum) and its weights are non-negative to within
    ``feasibility`` (then h exceeds the minimum by at most ``feasibility`` times the sum of the
    constraint slacks, i.e. relatively by about 1e-6: a degenerate basis -- fewer than k + 2
    contact points, as in cylindricity -- has zero weights that a draw makes slightly negative).
    Used by the Monte Carlo: most draws keep the contact points of the reference."""
    d = np.asarray(d, float)
    g = np.asarray(g, float)
    M, m = d.shape
    k = g.shape[2]
    B = np.asarray(basis, int)
    # columns of A for the basis, per problem
    isl = B < m
    idx = np.where(isl, B, B - m)
    AB = np.zeros((M, k + 2, k + 2))
    AB[:, 0, :] = isl
    AB[:, 1, :] = ~isl
    sign = np.where(isl, 1.0, -1.0)
    AB[:, 2:, :] = np.transpose(g[:, idx, :], (0, 2, 1)) * sign
    b = np.zeros(k + 2)
    b[:2] = 1.0
    cB = d[:, idx] * sign
    try:
        xB = np.linalg.solve(AB, np.broadcast_to(b, (M, k + 2))[..., None])[..., 0]
        y = np.linalg.solve(np.transpose(AB, (0, 2, 1)), cB[..., None])[..., 0]
    except np.linalg.LinAlgError:      # a draw made the basis singular: solve every draw afresh
        return np.zeros(M, bool), np.zeros(M), np.zeros((M, m))
    # reduced costs: lambda_i: d_i - y0 - g_i.y2 ; mu_i: -d_i - y1 + g_i.y2
    gy = np.einsum("Mik,Mk->Mi", g, y[:, 2:])
    r_l = d - y[:, :1] - gy
    r_m = -d - y[:, 1:2] + gy
    scale = np.max(np.abs(d - d.mean(axis=1, keepdims=True)), axis=1) + 1e-300
    ok = (np.all(xB >= -feasibility, axis=1) & np.all(r_l <= tol * scale[:, None], axis=1)
          & np.all(r_m <= tol * scale[:, None], axis=1))
    w = np.zeros((M, m))
    for j in range(B.size):
        w[:, idx[j]] += xB[:, j] * sign[j]
    h = np.einsum("Mi,Mi->M", w, d)
    return ok, h, w
