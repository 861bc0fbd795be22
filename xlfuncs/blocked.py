"""The point-cloud model of Forbes 2025 evaluated in blocks: never form the 3m x 3m V_X.

A scanning probe delivers thousands of points per feature; the dense V_X of eq. (28) then needs
(3m)^2 numbers per factor (m = 20,000: 29 GB).  Nothing downstream needs V_X itself:

* distances (eq. 29) need only the 3 x 3 blocks V_ii, V_jj, V_ij of their two points
  (:func:`pair_blocks`, and :func:`distance_components`, which reuses the row-block code of
  :func:`xlfuncs.pointcloud.distance_components`);
* a fitted feature needs V_A,f = G_A|X V_X,f G_A|X^T (Forbes 2025 section 5.6), n_A x n_A per
  factor (:func:`V_A_components`).  The explicit factors are low rank or diagonal:

  ====  ==============================================================  =================
  R     sigma_R^2 G G^T                                                 eq. (8)
  PQ    sum_k S_k S_k^T,  S_k = sum_{i in probe k} sigma_PQ,k G_i       rank 3 n_P, eq. (9)
  S     A V_B A^T,  A = sum_i G_i G(x_i - p_k(i))                       rank 7, eqs. (11)-(14)
  W     A A^T,  A = sum_i G_i K_i (K: the columns of V_W)               rank 3, docs/workpiece.md
  ====  ==============================================================  =================

  and the Gaussian-process factors are sums over the kernel,
  ``sum_ij k(z_i, z_j) W_i W_j^T``, evaluated in row blocks of the kernel (block x m numbers at
  a time, upper triangle only) and accumulated:

  ====  =============================================  ===============================  ===========
  ET    k = sigma_ET^2 exp(-|u_i - u_j|^2/lambda_ET^2)  W_i = G_i (n_A x 3)              eq. (21)
  ER    k = sigma_ER^2 exp(-|u_i - u_j|^2/lambda_ER^2)  W_i = G_i G_k(i) (n_A x 3)       eqs. (24)-(25)
  P     k = sigma_P^2 exp(-|n_i - n_j|^2/lambda_P^2),   W_i = G_i n_i (n_A x 1)          eqs. (26)-(27)
        same probe; plus the rank-n_P radius term
  ====  =============================================  ===============================  ===========

  with G_i the three columns of G_A|X of point i and u_i = x_i - p_k(i) the ram position.
  Memory grows linearly in m (the blocks have a fixed number of kernel entries), time as m^2;
  ``method="lowrank"`` replaces each kernel by the controlled Nyström factor of
  :mod:`xlfuncs.lowrank` (time linear in m, error bound reported);
* the covariance of length records (the locator, ``cmmwb calibrate``) is
  :mod:`xlfuncs.record_covariance`, on the same blocks and backends.

Units: as :mod:`xlfuncs.pointcloud` -- coordinates mm, V_X in µm²; V_A,f here is exactly
``G @ V_X_components(...)[f] @ G.T`` (µm² times the squared units of G).

Execution: blocks are independent tasks.  ``backend=None`` runs them on a local thread pool
(numpy releases the GIL); any object with ``map(fn, items, shared)`` returning the results in
order can run them elsewhere -- :mod:`xlfuncs.distributed` provides a Dask backend (local
threads or a cluster given a scheduler address).  ``progress(done, total)`` is called as blocks
finish; :class:`ProgressBar` draws a text bar on stderr for long runs.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from . import pointcloud as pc
from .errors import ModelError
from .execution import ProgressBar, ThreadBackend, run_blocks
from .model import G_S, check_factors, factor_block, skew, sq_dists, workpiece_columns

FACTORS = pc.FACTORS
MILLI = pc.MILLI

#: kernel entries per block (2^22 doubles = 32 MB per temporary array)
BLOCK_ENTRIES = 1 << 22

__all__ = [
    "V_X_block", "V_X_dense", "pair_blocks", "distance_components", "V_A_components",
    "propagate_cloud", "ThreadBackend", "ProgressBar", "FACTORS",
]


# ---------------------------------------------------------------------------------------------
# blocks of V_X (any rows and columns), pair blocks of eq. (29)
# ---------------------------------------------------------------------------------------------

def V_X_block(cloud: pc.PointCloud, params: pc.Parameters, I, J,
              factors: Sequence[str] = FACTORS) -> dict[str, np.ndarray]:
    """Rows of points I and columns of points J of every factor of eq. (28), µm².

    Returns :func:`xlfuncs.model.factor_block` (``{factor: (3|I|) x (3|J|)}``, coordinates
    interleaved as in :func:`xlfuncs.pointcloud.V_X_components`, the same numbers as its
    sub-blocks), plus ``"X"`` (their sum) when all six factors are requested.
    """
    out = factor_block(cloud, params, I, J, factors)
    if tuple(factors) == FACTORS:
        out["X"] = sum(out[f] for f in FACTORS)
    return out


def V_X_dense(cloud: pc.PointCloud, params: pc.Parameters, factors: Sequence[str] = FACTORS, *,
              rows_per_block: int | None = None, progress=None) -> np.ndarray:
    """The total 3m x 3m V_X over ``factors`` (µm²), filled in row blocks: peak memory is the
    result plus one block (the dense :func:`xlfuncs.pointcloud.V_X` holds six 3m x 3m
    contributions and their temporaries).  For covariances that are V_X itself (point records
    of the mismatch locator)."""
    m = cloud.m
    V = np.empty((3 * m, 3 * m))
    b = rows_per_block or max(1, BLOCK_ENTRIES // (9 * max(m, 1)))
    starts = list(range(0, m, b))
    for q, i0 in enumerate(starts):
        I = np.arange(i0, min(i0 + b, m))
        blk = V_X_block(cloud, params, I, slice(None), factors)
        V[3 * i0:3 * (i0 + len(I))] = sum(blk[f] for f in factors)
        if progress is not None:
            progress(q + 1, len(starts))
    return V


def pair_blocks(cloud: pc.PointCloud, params: pc.Parameters, pairs,
                factors: Sequence[str] = FACTORS) -> dict[str, np.ndarray]:
    """The 3 x 3 blocks B_f = V_ii + V_jj - V_ij - V_ji of each factor for each pair (i, j),
    µm², shape (n_pairs, 3, 3): eq. (29) is u_f^2(d_ij) = n_ij^T B_f n_ij.

    Closed forms of the blocks of eq. (28) (equal to the sub-blocks of the dense V_X):
    R 2 sigma_R^2 I; PQ (s_i^2 + s_j^2 - 2 [k(i)=k(j)] s_i s_j) I; S G(du) V_B G(du)^T with
    du = u_j - u_i (G linear, eq. 11); ET 2 sigma^2 (1 - rho) I; ER sigma^2 (G_i G_i^T + G_j G_j^T
    - rho (G_i G_j^T + G_j G_i^T)); P (s0_i^2+sp_i^2) n_i n_i^T + (s0_j^2+sp_j^2) n_j n_j^T
    - c_ij (n_i n_j^T + n_j n_i^T), c_ij = [same probe] (s0_i s0_j + sp_i sp_j k_ij).
    """
    pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= cloud.m):
        raise ModelError("pair index out of range")
    i, j = pairs[:, 0], pairs[:, 1]
    n = len(pairs)
    pa = pc.probe_arrays(cloud, params)
    same = cloud.probe_index[i] == cloud.probe_index[j]
    I3 = np.broadcast_to(np.eye(3), (n, 3, 3))
    U = cloud.ram_mm
    du = U[j] - U[i]
    du2 = np.einsum("ij,ij->i", du, du)
    out: dict[str, np.ndarray] = {}
    for f in factors:
        if f == "R":
            out[f] = 2.0 * params.sigma_R_um**2 * I3
        elif f == "PQ":
            s = pa["sigma_PQ_um"]
            out[f] = (s[i] ** 2 + s[j] ** 2 - 2.0 * np.where(same, s[i] * s[j], 0.0))[:, None, None] * I3
        elif f == "S":
            G = G_S(du)
            out[f] = np.einsum("nak,k,nbk->nab", G, pc.V_S_diag_um_per_mm2(params), G)
        elif f == "ET":
            if params.sigma_ET_um > 0:
                v = -2.0 * params.sigma_ET_um**2 * np.expm1(-du2 / params.lambda_ET_mm**2)
                out[f] = v[:, None, None] * I3
            else:
                out[f] = np.zeros((n, 3, 3))
        elif f == "ER":
            if params.sigma_ER_urad > 0:
                P = cloud.offsets_mm
                Gi, Gj = skew(P[i]), skew(P[j])
                rho = np.exp(-du2 / params.lambda_ER_mm**2)[:, None, None]
                ii = Gi @ Gi.transpose(0, 2, 1)
                jj = Gj @ Gj.transpose(0, 2, 1)
                ij = Gi @ Gj.transpose(0, 2, 1)
                out[f] = (params.sigma_ER_urad * MILLI) ** 2 * (ii + jj - rho * (ij + ij.transpose(0, 2, 1)))
            else:
                out[f] = np.zeros((n, 3, 3))
        elif f == "P":
            N = cloud.N
            s0, sp, lam = pa["sigma_P0_um"], pa["sigma_P_um"], pa["lambda_P"]
            dn = N[j] - N[i]
            dn2 = np.einsum("ij,ij->i", dn, dn)
            lam2 = lam[i] * lam[j]
            kern = np.where(sp[i] * sp[j] > 0, np.exp(-dn2 / np.where(lam2 > 0, lam2, 1.0)), 0.0)
            c = np.where(same, s0[i] * s0[j] + sp[i] * sp[j] * kern, 0.0)[:, None, None]
            ni, nj = N[i][:, :, None], N[j][:, :, None]
            nij = ni @ nj.transpose(0, 2, 1)
            out[f] = ((s0[i] ** 2 + sp[i] ** 2)[:, None, None] * (ni @ ni.transpose(0, 2, 1))
                      + (s0[j] ** 2 + sp[j] ** 2)[:, None, None] * (nj @ nj.transpose(0, 2, 1))
                      - c * (nij + nij.transpose(0, 2, 1)))
        elif f == "W":
            # docs/workpiece.md: (K_i - K_j)(K_i - K_j)^T of V_W = K K^T
            D = workpiece_columns(cloud, params)
            D = D[i] - D[j]
            out[f] = D @ D.transpose(0, 2, 1)
        else:
            raise ModelError(f"unknown influence factor {f!r}; known: {', '.join(FACTORS)}")
    return out


# ---------------------------------------------------------------------------------------------
# distances (eq. 29-30): the row blocks of xlfuncs.pointcloud, on any backend
# ---------------------------------------------------------------------------------------------


def _distance_rows(item, shared):
    """All pairs (i, j > i) with i in rows i0 .. i0+rows-1: d (mm) and variances (µm²)."""
    i0, rows, _ = item
    cloud, params, pa = shared["cloud"], shared["params"], shared["pa"]
    m = cloud.m
    with np.errstate(invalid="ignore", divide="ignore"):
        d, var = pc.rect_variances(cloud, params, pa, slice(i0, i0 + rows), slice(i0 + 1, m))
    keep = np.arange(i0 + 1, m)[None, :] > np.arange(i0, i0 + rows)[:, None]
    return d[keep], {f: v[keep] for f, v in var.items()}


def _distance_pairs(item, shared):
    lo, hi = item
    cloud, params = shared["cloud"], shared["params"]
    return pc.distance_components(cloud, params, shared["pairs"][lo:hi])


def distance_components(cloud: pc.PointCloud, params: pc.Parameters, pairs=None, *,
                        backend=None, progress=None, block: int = pc.PAIR_BLOCK) -> dict[str, np.ndarray]:
    """d_ij (mm), u(d_ij) and the six components (µm) of eqs. (29)-(30), as
    :func:`xlfuncs.pointcloud.distance_components` (same keys, same order, same numbers).

    ``backend=None`` runs that function itself (row blocks on local threads); another backend
    (e.g. :class:`xlfuncs.distributed.DaskBackend`) runs its row blocks as tasks there.
    """
    if backend is None:
        return pc.distance_components(cloud, params, pairs, block=block, progress=progress)
    m = cloud.m
    if pairs is None:
        blocks = pc.row_blocks(m, block)
        total = m * (m - 1) // 2
        out = {"d_mm": np.empty(total), "u_um": np.empty(total)}
        for f in FACTORS:
            out[f"u_{f}_um"] = np.empty(total)
        shared = {"cloud": cloud, "params": params, "pa": pc.probe_arrays(cloud, params)}
        sizes = [rows * (m - 1 - i0) - rows * (rows - 1) // 2 for i0, rows, _ in blocks]
        results = run_blocks(_distance_rows, blocks, shared, backend, progress, sizes)
        for (i0, rows, pos), (d, var) in zip(blocks, results):
            bad = np.flatnonzero(d <= 1e-9)
            if bad.size:  # same message as the local path
                pc.distance_components(cloud, params, _pairs_of_block(m, i0, rows)[bad[:1]])
            pc.store_distances(out, slice(pos, pos + d.size), d, var)
        return out
    pairs = pc.check_pairs(cloud, pairs)
    n = len(pairs)
    chunks = [(lo, min(lo + block, n)) for lo in range(0, n, block)]
    shared = {"cloud": cloud, "params": params, "pairs": pairs}
    results = run_blocks(_distance_pairs, chunks, shared, backend, progress, [hi - lo for lo, hi in chunks])
    if not results:
        return pc.distance_components(cloud, params, pairs)
    return {k: np.concatenate([r[k] for r in results]) for k in results[0]}


def _pairs_of_block(m: int, i0: int, rows: int) -> np.ndarray:
    ii, jj = np.nonzero(np.arange(i0 + 1, m)[None, :] > np.arange(i0, i0 + rows)[:, None])
    return np.column_stack([i0 + ii, i0 + 1 + jj])


# ---------------------------------------------------------------------------------------------
# V_A per factor (Forbes 2025 section 5.6) without V_X
# ---------------------------------------------------------------------------------------------

def _kernel_rows(item, shared):
    """Partial sums of sum_ij k(z_i, z_j) W_i W_j^T over rows i in [i0, i1) and columns j >= i0
    (upper triangle; the off-diagonal part counted with its transpose), per term of problem q."""
    q, i0, i1 = item
    Z, terms = shared["problems"][q]
    ZI = Z[i0:i1]
    D2 = sq_dists(ZI, Z[i0:])
    b = i1 - i0
    out = {}
    K = np.empty_like(D2)
    for name, scale, inv_lam2, W in terms:
        nA, c = W.shape[1], W.shape[2]
        np.multiply(D2, -inv_lam2, out=K)
        np.exp(K, out=K)
        WI = W[i0:i1].reshape(b, nA * c)
        # diagonal block rows I x columns I, then rows I x the columns after
        Yd = K[:, :b] @ WI
        Md = WI.reshape(b, nA, c).transpose(1, 0, 2).reshape(nA, b * c) @ \
            Yd.reshape(b, nA, c).transpose(1, 0, 2).reshape(nA, b * c).T
        M = Md
        if i1 < Z.shape[0]:
            Yo = K[:, b:] @ W[i1:].reshape(-1, nA * c)
            Mo = WI.reshape(b, nA, c).transpose(1, 0, 2).reshape(nA, b * c) @ \
                Yo.reshape(b, nA, c).transpose(1, 0, 2).reshape(nA, b * c).T
            M = Md + Mo + Mo.T
        out[name] = out.get(name, 0.0) + scale * M
    return out


def _kernel_items(problems, block: int) -> tuple[list, list]:
    items, weights = [], []
    for q, (Z, _terms) in enumerate(problems):
        m = Z.shape[0]
        i0 = 0
        while i0 < m:
            rows = max(1, min(m - i0, block // max(m - i0, 1)))
            items.append((q, i0, i0 + rows))
            weights.append(rows * (m - i0) - rows * (rows - 1) / 2)
            i0 += rows
    return items, weights


def V_A_components(G: np.ndarray, cloud: pc.PointCloud, params: pc.Parameters, *,
                   factors: Sequence[str] = FACTORS, block: int = BLOCK_ENTRIES,
                   backend=None, progress=None, method: str = "exact",
                   pivot_tol: float | None = None, approximation=None) -> dict[str, np.ndarray]:
    """V_A,f = G V_X,f G^T for every factor f of eq. (28) without forming V_X.

    ``G`` is n_A x 3m with interleaved columns x1, y1, z1, x2, ... (as
    :func:`xlfuncs.features.G_A_X`); the result has the units of G V_X G^T (V_X in µm²) and
    equals ``G @ V_X_components(cloud, params)[f] @ G.T`` to rounding.  Time O(m^2 n_A) for the
    GP factors, memory O(m n_A + block).  ``block``: kernel entries per task.

    ``method="lowrank"``: the GP factors ET, ER, P through the controlled Nyström factor of
    :mod:`xlfuncs.lowrank` (time O(m r^2), r pivots per kernel; R, PQ, S stay exact); pass an
    :class:`xlfuncs.lowrank.Approximation` as ``approximation`` to receive the ranks and the
    rigorous error bounds (it is filled in).
    """
    if method not in ("exact", "lowrank"):
        raise ModelError(f"unknown V_A method {method!r}; known: exact, lowrank")
    G = np.asarray(G, dtype=float)
    m = cloud.m
    if G.ndim != 2 or G.shape[1] != 3 * m:
        raise ModelError(f"G_A|X must have 3m = {3 * m} columns, got shape {G.shape}")
    if not np.all(np.isfinite(G)):
        raise ModelError("G_A|X has non-finite entries")
    check_factors(factors)
    nA = G.shape[0]
    Gp = G.reshape(nA, m, 3)                   # Gp[:, i, :] = G_i
    Wx = np.ascontiguousarray(Gp.transpose(1, 0, 2))   # m x n_A x 3
    pa = pc.probe_arrays(cloud, params)
    k = cloud.probe_index
    out: dict[str, np.ndarray] = {}
    if "R" in factors:
        out["R"] = params.sigma_R_um**2 * (G @ G.T)
    if "PQ" in factors:
        V = np.zeros((nA, nA))
        s = pa["sigma_PQ_um"]
        for q in range(len(cloud.probes)):
            idx = np.flatnonzero(k == q)
            if idx.size:
                S_k = np.einsum("i,ipa->pa", s[idx], Wx[idx])
                V += S_k @ S_k.T
        out["PQ"] = V
    if "S" in factors:
        GS = G_S(cloud.ram_mm)
        A = np.einsum("ipa,iab->pb", Wx, GS)
        out["S"] = (A * pc.V_S_diag_um_per_mm2(params)) @ A.T
    problems = []
    ram_terms = []
    if "ET" in factors:
        if params.sigma_ET_um > 0:
            ram_terms.append(("ET", params.sigma_ET_um**2, 1.0 / params.lambda_ET_mm**2, Wx))
        else:
            out["ET"] = np.zeros((nA, nA))
    if "ER" in factors:
        if params.sigma_ER_urad > 0:
            GR = skew(cloud.offsets_mm)
            H = np.einsum("ipa,iab->ipb", Wx, GR)    # H_i = G_i G_k(i)
            ram_terms.append(("ER", (params.sigma_ER_urad * MILLI) ** 2, 1.0 / params.lambda_ER_mm**2,
                              np.ascontiguousarray(H)))
        else:
            out["ER"] = np.zeros((nA, nA))
    if ram_terms:
        problems.append((np.ascontiguousarray(cloud.ram_mm), ram_terms))
    if "P" in factors:
        gP = np.einsum("ipa,ia->ip", Wx, cloud.N)      # g_i = G_i n_i
        V = np.zeros((nA, nA))
        s0, sp, lam = pa["sigma_P0_um"], pa["sigma_P_um"], pa["lambda_P"]
        for q in range(len(cloud.probes)):
            idx = np.flatnonzero(k == q)
            if not idx.size:
                continue
            r0 = s0[idx] @ gP[idx]                      # radius term: rank one per probe
            V += np.outer(r0, r0)
            if sp[idx[0]] > 0:
                problems.append((np.ascontiguousarray(cloud.N[idx]),
                                 [("P", sp[idx[0]] ** 2, 1.0 / lam[idx[0]] ** 2,
                                   np.ascontiguousarray(gP[idx][:, :, None]))]))
        out["P"] = V
    if "W" in factors:
        # docs/workpiece.md: V_W = K K^T is rank three, A = sum_i G_i K_i
        A = np.einsum("ipa,iak->pk", Wx, workpiece_columns(cloud, params))
        out["W"] = A @ A.T
    if method == "lowrank":
        from . import lowrank as lr

        approx = approximation if approximation is not None else lr.Approximation()
        if pivot_tol is not None:
            approx.pivot_tol = pivot_tol
        for name, M in lr.gp_terms_V_A(problems, nA, approx, backend=backend,
                                        progress=progress).items():
            out[name] = out.get(name, 0.0) + M
    else:
        items, weights = _kernel_items(problems, block)
        for part in run_blocks(_kernel_rows, items, {"problems": problems}, backend, progress, weights):
            for name, M in part.items():
                out[name] = out.get(name, 0.0) + M
    for f in factors:
        out.setdefault(f, np.zeros((nA, nA)))
        out[f] = 0.5 * (out[f] + out[f].T)
    if method == "lowrank":
        approx.finish({f: out[f] for f in factors})
    return {f: out[f] for f in factors}


def propagate_cloud(fit, cloud: pc.PointCloud, params: pc.Parameters, *, G: np.ndarray | None = None,
                    backend=None, progress=None, block: int = BLOCK_ENTRIES, method: str = "exact",
                    pivot_tol: float | None = None):
    """:func:`xlfuncs.features.propagate` for the point-cloud model without forming V_X: the same
    :class:`~xlfuncs.features.FeatureUncertainty` (V_A per factor in the parameters' units,
    local and reported, and ``"total"``), in memory linear in m.

    ``method="lowrank"``: the GP factors through :mod:`xlfuncs.lowrank` (time linear in m); the
    result's ``approximation`` then holds the ranks and error bounds (``None`` when exact)."""
    from . import features as ft

    G = ft.G_A_X(fit) if G is None else np.asarray(G, dtype=float)
    if cloud.m != fit.m:
        raise ModelError(f"the fit has {fit.m} points, the point cloud {cloud.m}")
    approx = None
    if method == "lowrank":
        from .lowrank import Approximation

        approx = Approximation()
    comps = V_A_components(G, cloud, params, block=block, backend=backend, progress=progress,
                           method=method, pivot_tol=pivot_tol, approximation=approx)
    V_local, V = {}, {}
    total = np.zeros((fit.n, fit.n))
    for f in FACTORS:
        Va = comps[f] * ft.UM2_TO_MM2
        V_local[f] = Va
        V[f] = fit.T @ Va @ fit.T.T
        total = total + Va
    V_local["total"] = total
    V["total"] = fit.T @ total @ fit.T.T
    return ft.FeatureUncertainty(fit=fit, G=G, V_local=V_local, V=V, factors=FACTORS,
                                 approximation=approx)
