"""Controlled low-rank factors of the squared-exponential kernels of Forbes 2025 (ET, ER, P).

The Gaussian-process factors contribute ``V_A,f = s_f sum_ij k(z_i, z_j) W_i W_j^T`` to the
feature covariance (Forbes 2022 V_A = G V_X G^T with the kernels of Forbes 2025 eqs. (21),
(24)-(25), (26)-(27); :func:`xlfuncs.blocked.V_A_components` evaluates the double sum exactly in
O(m^2) time).  The kernel ``k(z, z') = exp(-|z - z'|^2 / lambda^2)`` is smooth at the scale of a
feature, so K (m x m) is numerically of low rank.  This module replaces it by the Nyström factor
of r pivot points chosen by a greedy pivoted Cholesky,

    K ~ K_mP K_PP^-1 K_Pm = L L^T,   L = K_mP C^-T,   C C^T = K_PP,

so that ``V_A,f ~ s_f Y^T Y`` with ``Y = L^T W`` (r x n_A c): time O(m r (r + n_A c)), memory
O(block r) -- L is never stored.

Error control (never silent).  The residual R = K - L L^T is positive semidefinite (a Schur
complement), hence ``||R||_2 <= trace(R) = sum_i (1 - |l_i|^2)``, which the pass over all m
points computes exactly (up to rounding).  With ``M = sum_i W_i W_i^T`` (n_A x n_A) the neglected
part ``Delta = s_f W^T R W`` of V_A is positive semidefinite and

    0 <= a^T Delta a <= s_f trace(R) a^T M a      for every a,

so every entry obeys ``|Delta_pq| <= s_f trace(R) sqrt(M_pp M_qq)`` and
``||Delta||_2 <= s_f trace(R) ||M||_2``.  :class:`Approximation` carries these bounds; the
exact O(m^2) path stays available (``method="exact"``).

The pivots are chosen on a seeded pseudo-random sub-sample of the points; if the
pass over all points finds a residual diagonal above the tolerance there, the offending points
join the pool and the pivots are chosen again, so the result does not depend on the sub-sample
beyond the stated bound.  Blocks are accumulated in a fixed order on any backend
(:mod:`xlfuncs.blocked`), so the numbers do not depend on the backend.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import solve_triangular

from .errors import ModelError
from .model import sq_dists

#: stop choosing pivots when the largest residual diagonal of the (unit) kernel is below this
PIVOT_TOL = 1e-12
#: points of the sub-sample the pivots are chosen from
POOL_SIZE = 20_000
#: most pivots per kernel
MAX_RANK = 2_000
#: kernel entries per block of the pass over all points
BLOCK_ENTRIES = 1 << 21

__all__ = ["KernelFactor", "Approximation", "pivots", "nystrom_project", "PIVOT_TOL"]


def _kernel(A, B, inv_lam2):
    """exp(-|a - b|^2 inv_lam2) for the rows of A and B (the unit kernel of eqs. 21, 25, 27)."""
    K = sq_dists(A, B)
    K *= -inv_lam2
    return np.exp(K, out=K)


class RankError(ModelError):
    """A kernel needs more pivots than :data:`MAX_RANK`: the low-rank path is refused, with what fits."""


#: most work m r^2 of a low-rank factor (the projection of m points on r pivots; 5e11 is a few
#: minutes on one core): m = 10^6 points allow r = 707 pivots, m = 125,000 the whole MAX_RANK
WORK_LIMIT = 5e11
#: the section proposed in a refusal aims at this share of the pivots allowed (the estimate is rough)
SECTION_SHARE = 0.8
#: side of the cells (in correlation lengths) whose count over the points estimates the pivots a
#: kernel needs at PIVOT_TOL (measured at lambda = 30 mm: 3.7 pivots per lambda on a line, 15-17
#: per lambda^2 on a plane, 75-120 per lambda^3 in a volume, i.e. about one per cell of lambda/4)
CELL = 0.25


def occupied_cells(Z: np.ndarray, side: float) -> int:
    """How many cubes of the grid with this side (mm) hold at least one point of Z."""
    keys = np.ascontiguousarray(np.floor((Z - Z.min(axis=0)) / side).astype(np.int64))
    return int(len(np.unique(keys.view(np.dtype((np.void, 8 * keys.shape[1]))).ravel())))


def rank_estimate(Z: np.ndarray, inv_lam2: float) -> tuple[int, float, int]:
    """(estimated pivots, dimension of the points at the scale of lambda, pivots of the region
    once densely filled): the cells of side CELL lambda that the points occupy; the dimension is
    the smaller of the number of directions along which the points extend beyond lambda and log2
    of the ratio of the cells of side lambda to those of side 2 lambda (a surface in space counts
    2); the filled estimate scales the cells of side lambda by (1/CELL)^dimension."""
    lam = 1.0 / np.sqrt(inv_lam2)
    n1 = occupied_cells(Z, CELL * lam)
    n2, n4 = occupied_cells(Z, lam), occupied_cells(Z, 2.0 * lam)
    axes = int(np.count_nonzero(np.linalg.svd(Z - Z.mean(axis=0), compute_uv=False) / np.sqrt(len(Z))
                                > lam / np.sqrt(12.0))) if len(Z) > 1 else 1
    dim = float(min(3.0, max(1.0, min(axes, np.log2(max(n2, 1) / max(n4, 1))))))
    return n1, dim, int(max(n1, n2 * (1.0 / CELL) ** dim))


def check_rank(Z: np.ndarray, inv_lam2: float, name: str, max_rank: int | None = None,
               found: int | None = None) -> None:
    """Refuse (:class:`RankError`) a kernel whose rank would exceed ``max_rank``: by the cell
    estimate before any pivoting (time O(m)), or when the pivots actually ran into the limit
    (``found``); the message says what fits (a section, a correlation length, the exact path)."""
    m = len(Z)
    max_rank = MAX_RANK if max_rank is None else max_rank
    limit = max(1, min(max_rank, int(np.sqrt(WORK_LIMIT / max(m, 1)))))
    est, dim, filled = rank_estimate(Z, inv_lam2)
    if found is None and est <= limit:
        return
    max_rank = limit if found is None else max_rank
    lam = 1.0 / np.sqrt(inv_lam2)
    ext = np.ptp(Z, axis=0)
    need = max(filled, found or 0)                 # a section is measured as densely
    share = (SECTION_SHARE * max_rank / need) ** (1.0 / dim)
    sizes = " x ".join(f"{v * share:.0f}" for v in ext if v > lam)
    how = (f"ran into the limit of {max_rank:,} pivots with residual left" if found is not None
           else f"needs about {est:,} pivots (points in {est:,} cells of lambda/4 = {CELL * lam:.3g} mm)")
    raise RankError(
        f"{name}: the correlation length {lam:g} mm is short against the extent of the "
        f"{len(Z):,} points ({' x '.join(f'{v:.0f}' for v in ext)} mm): the low-rank factor {how}, "
        f"more than the {max_rank:,} it allows for {m:,} points (pivot tolerance {PIVOT_TOL:g}, work "
        f"m r^2 <= {WORK_LIMIT:.0e}). What fits: a "
        f"section of about {sizes or '-'} mm, or a correlation length of at least about "
        f"{lam / share:.0f} mm, or the exact O(m^2) path (--exact, va_method = \"exact\"; about 10^5 points "
        "in minutes)")


def unit_kernel(A: np.ndarray, B: np.ndarray, inv_lam2: float) -> np.ndarray:
    """The unit squared-exponential kernel exp(-|a - b|^2 inv_lam2), rows A, columns B."""
    return _kernel(A, B, inv_lam2)


def pivots(Z: np.ndarray, inv_lam2: float, *, tol: float = PIVOT_TOL, max_rank: int | None = None,
           pool: np.ndarray | None = None) -> np.ndarray:
    """Indices into ``Z`` of the pivots of a greedy pivoted Cholesky of the unit SE kernel on the
    points ``pool`` (default: all of Z), stopped when the largest residual diagonal is <= tol;
    :class:`RankError` when ``max_rank`` (default MAX_RANK) pivots leave more than tol."""
    max_rank = MAX_RANK if max_rank is None else max_rank
    idx = np.arange(len(Z)) if pool is None else np.asarray(pool, dtype=int)
    Zp = Z[idx]
    s = len(idx)
    d = np.ones(s)
    L = np.empty((min(max_rank, s), s))
    chosen = []
    for r in range(min(max_rank, s)):
        j = int(np.argmax(d))
        if d[j] <= tol:
            break
        chosen.append(j)
        row = _kernel(Zp[j:j + 1], Zp, inv_lam2)[0]
        if r:
            row -= L[:r, j] @ L[:r]
        row /= np.sqrt(d[j])
        L[r] = row
        d -= row * row
        d[chosen] = 0.0
    else:
        if s > max_rank and np.max(d) > tol:
            raise RankError(f"the kernel needs more than {max_rank} pivots")
    return idx[np.asarray(chosen, dtype=int)]


@dataclass
class KernelFactor:
    """The Nyström factor of one SE kernel: pivot points ``Zp`` (r x dim) and the Cholesky
    factor ``C`` (lower) of their kernel matrix."""

    Zp: np.ndarray
    C: np.ndarray
    inv_lam2: float

    @classmethod
    def at(cls, Z: np.ndarray, piv: np.ndarray, inv_lam2: float) -> "KernelFactor":
        Zp = np.ascontiguousarray(Z[piv])
        K = _kernel(Zp, Zp, inv_lam2)
        try:
            C = np.linalg.cholesky(K)
        except np.linalg.LinAlgError:
            raise ModelError("the pivots' kernel matrix is not positive definite; "
                             "raise the pivot tolerance") from None
        return cls(Zp, C, inv_lam2)

    @property
    def rank(self) -> int:
        return len(self.Zp)

    def rows(self, Zb: np.ndarray) -> np.ndarray:
        """l_i^T for the points Zb: (r x b), l_i = C^-1 k_P(z_i)."""
        return solve_triangular(self.C, _kernel(self.Zp, Zb, self.inv_lam2), lower=True,
                                check_finite=False)


def _project_block(item, shared):
    """For points i0..i1 of problem q: Y_b = L_b^T W_b (r x n_A c), the residual diagonal
    1 - |l_i|^2 (per point) and M_b = sum_i W_i W_i^T."""
    q, i0, i1 = item
    Z, W, fac = shared["problems"][q]
    Lb = fac.rows(Z[i0:i1])                          # r x b
    Wb = W[i0:i1].reshape(i1 - i0, -1)               # b x n_A c
    d = 1.0 - np.einsum("rb,rb->b", Lb, Lb)
    return Lb @ Wb, d


def nystrom_project(problems, *, backend=None, progress=None, block: int = BLOCK_ENTRIES):
    """For every problem ``(Z, W, factor)``: ``Y = L^T W`` (r x n_A*c) and the residual
    diagonal (length m) over all points, in blocks on ``backend`` (fixed summation order)."""
    from .execution import run_blocks

    items, weights = [], []
    for q, (Z, _W, fac) in enumerate(problems):
        m = Z.shape[0]
        b = max(1, block // max(fac.rank, 1))
        for i0 in range(0, m, b):
            items.append((q, i0, min(i0 + b, m)))
            weights.append(min(i0 + b, m) - i0)
    Y = [np.zeros((fac.rank, W[0].size if len(W) else 0)) for Z, W, fac in problems]
    D = [np.empty(Z.shape[0]) for Z, _W, _f in problems]
    for (q, i0, i1), (Yb, d) in zip(items, run_blocks(_project_block, items, {"problems": problems},
                                                 backend, progress, weights)):
        Y[q] += Yb
        D[q][i0:i1] = d
    return Y, D


@dataclass
class Approximation:
    """What the low-rank evaluation neglected, per factor (see the module docstring).

    ``rank[f]``: pivots per kernel (one per probe for P); ``trace_residual[f]``: the scaled
    trace of the neglected kernel part, ``bound_abs[f]``: the bound of ``|Delta_pq|`` (n_A x
    n_A, units of V_A), ``bound_rel[f]``: ``max_pq bound_abs / ||V_A,f||_2`` (0 for exact
    factors).
    """

    method: str = "nystrom-pivoted-cholesky"
    pivot_tol: float = PIVOT_TOL
    rank: dict = field(default_factory=dict)
    trace_residual: dict = field(default_factory=dict)
    bound_abs: dict = field(default_factory=dict)
    bound_rel: dict = field(default_factory=dict)

    def add(self, name: str, rank: int, trace: float, bound: np.ndarray) -> None:
        self.rank.setdefault(name, []).append(rank)
        self.trace_residual[name] = self.trace_residual.get(name, 0.0) + trace
        self.bound_abs[name] = self.bound_abs.get(name, 0.0) + bound

    def finish(self, V: dict) -> None:
        """Relative bounds against the computed V_A,f (units of V_A cancel)."""
        for f in V:
            if f in self.bound_abs:
                norm = float(np.linalg.norm(V[f], 2))
                b = float(np.max(self.bound_abs[f]))
                self.bound_rel[f] = b / norm if norm > 0 else (0.0 if b == 0 else float("inf"))

    def as_dict(self) -> dict:
        """The JSON form (``approximation`` key of the results)."""
        return {"method": self.method, "pivot_tol": self.pivot_tol,
                "rank": {f: list(map(int, r)) for f, r in self.rank.items()},
                "relative_error_bound": {f: float(v) for f, v in self.bound_rel.items()},
                "note": "exact factors R, PQ, S; for ET, ER, P the neglected part Delta of V_A is "
                        "positive semidefinite with |Delta_pq| <= trace(R_K) s_f sqrt(M_pp M_qq); "
                        "relative_error_bound = max_pq of that bound / ||V_A,f||_2"}


def initial_pool(m: int) -> np.ndarray:
    """The points the pivots are first chosen from: all, or a fixed pseudo-random sample of
    POOL_SIZE (seeded: the same every run; a stride could alias with interleaved probes)."""
    if m <= POOL_SIZE:
        return np.arange(m)
    return np.sort(np.random.default_rng(20251).choice(m, POOL_SIZE, replace=False))


def controlled_factor(Z: np.ndarray, inv_lam2: float, tol: float = PIVOT_TOL,
                      block: int = 4096, name: str = "kernel") -> tuple[KernelFactor, float]:
    """The Nyström factor of the unit SE kernel on Z and the trace of its residual over all
    points (with the rounding allowance), re-choosing the pivots with the worst points added
    while any residual diagonal exceeds CHECK_FACTOR * tol.  A kernel whose rank would exceed
    MAX_RANK is refused (:func:`check_rank`, named ``name``)."""
    eps = np.finfo(float).eps
    m = Z.shape[0]
    pool = initial_pool(m)
    check_rank(Z, inv_lam2, name)
    for rnd in range(MAX_ROUNDS):
        try:
            piv = pivots(Z, inv_lam2, tol=tol, pool=pool)
        except RankError:
            check_rank(Z, inv_lam2, name, found=MAX_RANK)
            raise
        fac = KernelFactor.at(Z, piv, inv_lam2)
        d = np.empty(m)
        for i0 in range(0, m, block):
            L = fac.rows(Z[i0:i0 + block])
            d[i0:i0 + block] = 1.0 - np.einsum("rb,rb->b", L, L)
        bad = np.flatnonzero(d > CHECK_FACTOR * tol)
        if not bad.size or rnd + 1 == MAX_ROUNDS:
            break
        pool = np.union1d(pool, bad[np.argsort(-d[bad], kind="stable")[:POOL_SIZE // 4]])
    return fac, float(np.sum(np.clip(d, 0.0, None))) + m * (fac.rank + 2) * eps


#: a point whose residual diagonal exceeds this (after the pivots were chosen on the pool)
#: joins the pool and the pivots are chosen again
CHECK_FACTOR = 100.0
#: rounds of pool enlargement
MAX_ROUNDS = 4


def gp_terms_V_A(problems, nA: int, approx: Approximation, *, backend=None, progress=None) -> dict:
    """The GP terms of :func:`xlfuncs.blocked.V_A_components` (``problems``: a list of
    ``(Z, [(name, scale, inv_lam2, W), ...])``, W m x n_A x c) through the Nyström factor:
    ``{name: V (n_A x n_A)}`` summed over the terms of each name; ``approx`` receives the ranks
    and the bounds (module docstring)."""
    eps = np.finfo(float).eps
    terms = [(Z, name, scale, inv_lam2, W) for Z, ts in problems for name, scale, inv_lam2, W in ts]
    pools, facs = [], []
    for Z, _n, _s, inv_lam2, _W in terms:
        pools.append(initial_pool(Z.shape[0]))
        facs.append(None)
    todo = list(range(len(terms)))
    results: dict[int, tuple] = {}
    for Z, name, _s, inv_lam2, _W in terms:
        check_rank(Z, inv_lam2, name)
    for rnd in range(MAX_ROUNDS):
        for t in todo:
            Z, name, _s, inv_lam2, _W = terms[t]
            try:
                piv = pivots(Z, inv_lam2, tol=approx.pivot_tol, pool=pools[t])
            except RankError:
                check_rank(Z, inv_lam2, name, found=MAX_RANK)
                raise
            facs[t] = KernelFactor.at(Z, piv, inv_lam2)
        Ys, Ds = nystrom_project([(terms[t][0], terms[t][4], facs[t]) for t in todo],
                                 backend=backend, progress=progress)
        again = []
        for t, Y, d in zip(todo, Ys, Ds):
            results[t] = (Y, d)
            bad = np.flatnonzero(d > CHECK_FACTOR * approx.pivot_tol)
            if bad.size and rnd + 1 < MAX_ROUNDS:
                worst = bad[np.argsort(-d[bad], kind="stable")[:POOL_SIZE // 4]]
                pools[t] = np.union1d(pools[t], worst)
                again.append(t)
        todo = again
        if not todo:
            break
    out: dict[str, np.ndarray] = {}
    for t, (Z, name, scale, _il, W) in enumerate(terms):
        Y, d = results[t]
        r = facs[t].rank
        m, c = W.shape[0], W.shape[2]
        Y3 = Y.reshape(r, nA, c).transpose(0, 2, 1).reshape(r * c, nA)
        out[name] = out.get(name, 0.0) + scale * (Y3.T @ Y3)
        # trace of the PSD residual, with an allowance for the rounding of 1 - |l_i|^2
        trace = float(np.sum(np.clip(d, 0.0, None))) + m * (r + 2) * eps
        Wf = W.transpose(0, 2, 1).reshape(m * c, nA)
        Md = np.einsum("ip,ip->p", Wf, Wf)           # diagonal of M = sum_i W_i W_i^T
        approx.add(name, r, scale * trace, scale * trace * np.sqrt(np.outer(Md, Md)))
    return out
