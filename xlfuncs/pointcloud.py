"""Point-cloud variance V_X from six CMM influence factors (Forbes 2025, sections 4-6): the
dense V_X, distances and their uncertainty components, the summary formula and the MPE check.

The model itself (``FACTORS``, :class:`Parameters`, :class:`Probe`, :class:`PointCloud`, the
six factor covariances of eq. 28) lives in :mod:`xlfuncs.model`; its names are importable from
here as well.  Units: coordinates mm, uncertainties µm, variances µm² (see :mod:`xlfuncs.model`).

Two evaluation paths give the same numbers:

* ``V_X_components`` builds the dense 3m x 3m matrices of eq. (28) (what the workbook shows);
* ``distance_components`` evaluates the quadratic form of eq. (29) for many pairs at once
  without forming V_X (memory linear in the number of pairs processed per block).
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from .errors import DegenerateGeometryError, ModelError

# the model's names, also importable from here (xlfuncs.pointcloud.Parameters, ...)
from .model import (  # noqa: F401
    FACTORS,
    MAX_PARAMETER,
    MILLI,
    MIN_LENGTH_SCALE,
    Parameters,
    PointCloud,
    Probe,
    V_S_diag_um_per_mm2,
    factor_block,
    gauss_kernel,
    probe_arrays,
    scale_rows,
    sq_dists,
    workpiece_columns,
)

# ---------------------------------------------------------------------------------------------
# Dense V_X (Forbes 2025 eq. 28), one 3m x 3m matrix per factor, µm²
# ---------------------------------------------------------------------------------------------

def V_X_components(cloud: PointCloud, params: Parameters, *, d_log_lambda: bool = False) -> dict[str, np.ndarray]:
    """The six 3m x 3m contributions of Forbes 2025 eq. (28), in µm², keyed by ``FACTORS``:
    :func:`xlfuncs.model.factor_block` over every point.

    Coordinates are interleaved ``x1, y1, z1, x2, ...`` (the paper's x_{1:m}).
    ``d_log_lambda``: the GP factors ET, ER and P with their kernels replaced by the derivative
    in log lambda (:func:`gauss_kernel`; the radius part of P dropped), the closed-form dV/d(log
    lambda) of the hyper-parameter fit (:mod:`xlfuncs.calibrate`).
    """
    return factor_block(cloud, params, d_log_lambda=d_log_lambda)


def V_X(cloud: PointCloud, params: Parameters) -> np.ndarray:
    """Total point-cloud variance matrix of Forbes 2025 eq. (28), µm²."""
    return sum(V_X_components(cloud, params).values())


# ---------------------------------------------------------------------------------------------
# Distances (Forbes 2025 section 6, eqs. 29-30) without forming V_X
# ---------------------------------------------------------------------------------------------

def all_pairs(m: int) -> np.ndarray:
    """Every unordered pair (i < j) of m points, as a (m(m-1)/2) x 2 index array."""
    i, j = np.triu_indices(m, k=1)
    return np.column_stack([i, j])


def check_pairs(cloud: PointCloud, pairs: np.ndarray) -> np.ndarray:
    """Validate a pair index array; coincident points make eq. (29)'s n_ij undefined."""
    pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= cloud.m):
        raise ModelError("pair index out of range")
    d = np.linalg.norm(cloud.X_mm[pairs[:, 1]] - cloud.X_mm[pairs[:, 0]], axis=1)
    bad = np.flatnonzero(d <= 1e-9)
    if bad.size:
        i, j = pairs[bad[0]]
        raise DegenerateGeometryError(
            f"points {cloud.labels[i]} and {cloud.labels[j]} are at the same place: "
            "the distance direction n_ij of Forbes 2025 eq. (29) is undefined")
    return pairs


def _distance_block(cloud: PointCloud, params: Parameters, pa: dict, i: np.ndarray,
                    j: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Distances and per-factor variances (µm²) for pairs (i, j): the quadratic form of eq. (29)
    with g = [-n_ij; n_ij], n_ij = (x_j - x_i)/d_ij, evaluated factor by factor."""
    X, N, U = cloud.X_mm, cloud.N, cloud.ram_mm
    delta = X[j] - X[i]
    d = np.sqrt(np.einsum("ij,ij->i", delta, delta))
    n = delta / d[:, None]
    same = cloud.probe_index[i] == cloud.probe_index[j]
    var: dict[str, np.ndarray] = {}

    var["R"] = np.full(d.shape, 2.0 * params.sigma_R_um**2)

    sPQ = pa["sigma_PQ_um"]
    var["PQ"] = np.where(same, 0.0, sPQ[i] ** 2 + sPQ[j] ** 2)

    # S: n^T (G(u_j) - G(u_i)) = n^T G(u_j - u_i), G linear (eq. 11)
    du = U[j] - U[i]
    var["S"] = scale_rows(n, du) ** 2 @ V_S_diag_um_per_mm2(params)

    du2 = np.einsum("ij,ij->i", du, du)
    if params.sigma_ET_um > 0:
        var["ET"] = 2.0 * params.sigma_ET_um**2 * -np.expm1(-du2 / params.lambda_ET_mm**2)
    else:
        var["ET"] = np.zeros_like(d)

    if params.sigma_ER_urad > 0:
        # m_i = G_k(i)^T n with G_k of eq. (24): G^T n = n x p  (section 6.5)
        P = cloud.offsets_mm
        mi = np.cross(n, P[i])
        mj = np.cross(n, P[j])
        rho = np.exp(-du2 / params.lambda_ER_mm**2)
        var["ER"] = (params.sigma_ER_urad * MILLI) ** 2 * (
            np.einsum("ij,ij->i", mi, mi) + np.einsum("ij,ij->i", mj, mj)
            - 2.0 * rho * np.einsum("ij,ij->i", mi, mj))
    else:
        var["ER"] = np.zeros_like(d)

    # P (section 6.6): o_i = n_i.n_ij, o_j = n_j.n_ij
    oi = np.einsum("ij,ij->i", N[i], n)
    oj = np.einsum("ij,ij->i", N[j], n)
    s0, sp, lam = pa["sigma_P0_um"], pa["sigma_P_um"], pa["lambda_P"]
    dn = N[j] - N[i]
    dn2 = np.einsum("ij,ij->i", dn, dn)
    with np.errstate(divide="ignore", invalid="ignore"):
        kern = np.where(sp[i] * sp[j] > 0, np.exp(-dn2 / (lam[i] * lam[j])), 0.0)
    cross = s0[i] * s0[j] + sp[i] * sp[j] * kern
    var["P"] = ((s0[i] ** 2 + sp[i] ** 2) * oi**2 + (s0[j] ** 2 + sp[j] ** 2) * oj**2
                - 2.0 * np.where(same, cross, 0.0) * oi * oj)

    # W (docs/workpiece.md): n^T (K_j - K_i), the rank-3 columns of V_W; d u(eps) for one temperature
    if cloud.W_on:
        K = workpiece_columns(cloud, params)
        g = np.einsum("pa,pak->pk", n, K[j] - K[i])
        var["W"] = np.einsum("pk,pk->p", g, g)
    else:
        var["W"] = np.zeros_like(d)
    return d, var


def pair_arrays(cloud: PointCloud, pa: dict, params: Parameters | None = None) -> dict:
    """Per-point arrays of the all-pairs kernel :func:`rect_variances`, coordinate-major and
    contiguous (row slices broadcast without strided gathers); ``pa``: :func:`probe_arrays`.
    With ``params`` and the factor W on: ``W2`` = u^2(eps) (µm/mm)² of one temperature, or ``Kt``
    (3 x 3 x m: coordinate, column, point) the columns of V_W with a temperature per point.

    The terms that are constant per probe pair (k(i), k(j)) come as K x m tables ``T[k, j]`` =
    value for a point of probe k against point j: a block's rows are copied out of them
    (``np.take`` along the probe axis, a memory copy) instead of being formed per pair."""
    P = cloud.offsets_mm
    lam = pa["lambda_P"]
    k = cloud.probe_index
    K = len(cloud.probes)
    first = np.array([np.flatnonzero(k == q)[0] if np.any(k == q) else 0 for q in range(K)], dtype=int)
    same = np.arange(K)[:, None] == k[None, :]
    sPQ2 = pa["sigma_PQ_um"] ** 2
    s0, sp = pa["sigma_P0_um"], pa["sigma_P_um"]
    Pk = P[first] if cloud.m else np.zeros((K, 3))
    ilam = 1.0 / np.where(lam > 0, lam, 1.0)
    M = cloud.N * ilam[:, None]
    W: dict = {}
    if params is not None and cloud.W_on:
        wp = cloud.workpiece
        if cloud.temperature_C is None:
            W["W2"] = (wp.u_eps_ppm(params.u_alpha_ppm_per_K, params.u_T_K) * MILLI) ** 2
        else:
            W["Kt"] = np.ascontiguousarray(workpiece_columns(cloud, params).transpose(1, 2, 0))
    return W | {"Xt": np.ascontiguousarray(cloud.X_mm.T), "Nt": np.ascontiguousarray(cloud.N.T),
            "Ut": np.ascontiguousarray(cloud.ram_mm.T),
            "Pt": np.ascontiguousarray(P.T), "p2": np.einsum("ij,ij->i", P, P),
            "any_offset": bool(np.any(P != 0)),
            "sPQ2": sPQ2, "sP2": s0 ** 2 + sp ** 2,
            # normals over lambda_P: |M_i - M_j|^2 = |n_i - n_j|^2 / lambda^2 for points of one
            # probe, formed as 2 M_i.M_j - |M_i|^2 - |M_j|^2 (outer products, no full-size reads)
            "Mt": np.ascontiguousarray(M.T), "M2t": np.ascontiguousarray(2.0 * M.T),
            "mm": np.einsum("ij,ij->i", M, M),
            # per probe pair (eq. 9, section 6.5, section 6.6): PQ is sigma_PQ,i^2 + sigma_PQ,j^2
            # for different probes, p_i.p_j, and the same-probe factors of the probing covariance
            "T_PQ": np.where(same, 0.0, sPQ2[first][:, None] + sPQ2[None, :]),
            "T_pij": (Pk[:, 0][:, None] * P[:, 0][None, :] + Pk[:, 1][:, None] * P[:, 1][None, :]
                      + Pk[:, 2][:, None] * P[:, 2][None, :]),
            # (doubled, exactly: the factor 2 of the cross term 2 C o_i o_j)
            "T_2s0": np.where(same, 2.0 * (s0[first][:, None] * s0[None, :]), 0.0),
            "T_2sp": np.where(same, 2.0 * (sp[first][:, None] * sp[None, :]), 0.0)}


class PairWorkspace:
    """Reusable float64 buffers of one thread of the all-pairs kernel (``out=`` targets), so that
    a block allocates nothing: ``ws(name, shape)`` is a view of the buffer ``name``, grown on
    demand."""

    def __init__(self):
        self.flat: dict[str, np.ndarray] = {}

    def __call__(self, name: str, shape: tuple[int, int]) -> np.ndarray:
        size = shape[0] * shape[1]
        b = self.flat.get(name)
        if b is None or b.size < size:
            b = self.flat[name] = np.empty(max(size, 1))
        return b[:size].reshape(shape)

    def planes(self, name: str, k: int, shape: tuple[int, int]) -> np.ndarray:
        """A (k, rows, columns) buffer: k numbers per pair, plane by plane (the operands of one
        einsum over the planes)."""
        return self(name, (k * shape[0], shape[1])).reshape((k,) + tuple(shape))

    def xyz(self, name: str, shape: tuple[int, int]) -> np.ndarray:
        """The x, y and z planes of one vector per pair."""
        return self.planes(name, 3, shape)


def rect_variances(cloud: PointCloud, params: Parameters, pa: dict, I: slice, J: slice,
                   ws: PairWorkspace | None = None):
    """Distances and per-factor variances (µm²) for every (i in I, j in J), as 2-D arrays.

    The quadratic form of eq. (29) with g = [-n_ij; n_ij], factor by factor, written per
    coordinate so that everything is a broadcast of row slices (no gathers); the vectors per pair
    (n, u_j - u_i) are stacked x, y, z planes and their dot products one ``np.einsum`` each
    (no BLAS; the products summed in the order x, y, z, as the passes they replace):
    S: n^T G(u_j - u_i) (eq. 11); ET: 2 sigma^2 (1 - rho); ER: m = n x p (section 6.5), with
    |n x p|^2 = |p|^2 - (n.p)^2 and (n x p_i).(n x p_j) = p_i.p_j - (n.p_i)(n.p_j);
    P: o_i = n_i.n_ij, o_j = n_j.n_ij (section 6.6).  R (eq. 8) is one number for every pair
    (a read-only broadcast); PQ, p_i.p_j and the probing factors are copied per row from the
    per-probe-pair tables of :func:`pair_arrays`.  Every step writes into a buffer of ``ws``
    (a :class:`PairWorkspace`; the arrays returned are views of it, valid until its next use).
    ``pa``: :func:`probe_arrays`, with :func:`pair_arrays` merged in (else computed here).
    """
    if "T_PQ" not in pa:
        pa = {**pa, **pair_arrays(cloud, pa, params)}
    ws = ws if ws is not None else PairWorkspace()
    X, N, P = pa["Xt"], pa["Nt"], pa["Pt"]
    shape = (I.stop - I.start, J.stop - J.start)
    col = lambda A, k: A[k, J][None, :]  # noqa: E731
    row = lambda A, k: A[k, I][:, None]  # noqa: E731
    mul, add, sub = np.multiply, np.add, np.subtract
    t = ws("t", shape)
    # dot products over x, y, z as one einsum of the stacked planes (one pass, not five; the
    # products summed in the same order x, y, z)
    n3 = ws.xyz("n", shape)
    for k in range(3):
        sub(col(X, k), row(X, k), out=n3[k])
    d = np.einsum("kij,kij->ij", n3, n3, out=ws("d", shape))
    np.sqrt(d, out=d)
    n3 *= np.divide(1.0, d, out=t)
    nx, ny, nz = n3
    var: dict[str, np.ndarray] = {}
    var["R"] = np.broadcast_to(np.float64(2.0 * params.sigma_R_um**2), shape)
    kI = cloud.probe_index[I]
    var["PQ"] = np.take(pa["T_PQ"][:, J], kI, axis=0, out=ws("PQ", shape))
    # ram differences u_j - u_i (eq. 11: G is linear in the ram position)
    U = pa["Ut"]
    u3 = ws.xyz("u", shape)
    for k in range(3):
        sub(col(U, k), row(U, k), out=u3[k])
    c = V_S_diag_um_per_mm2(params)
    a0 = np.einsum("kij,kij->ij", n3, u3, out=ws("a", shape))
    u3 *= u3
    ux2, uy2, uz2 = u3
    # sum_k c_k g_k^2 with g = (n.u, nx ux, ny uy, nz uz, nx uy, nx uz, ny uz), grouped by n_a^2
    S = mul(a0, c[0], out=ws("S", shape))
    S *= a0
    s2 = ws("s2", shape)
    mul(ux2, c[1], out=t)
    t += mul(uy2, c[4], out=s2)
    t += mul(uz2, c[5], out=s2)
    t *= mul(nx, nx, out=s2)
    S += t
    mul(uy2, c[2], out=t)
    t += mul(uz2, c[6], out=s2)
    t *= mul(ny, ny, out=s2)
    S += t
    mul(nz, nz, out=t)
    t *= uz2
    t *= c[3]
    S += t
    var["S"] = S
    du2 = ux2
    du2 += uy2
    du2 += uz2
    if params.sigma_ET_um > 0:
        e = mul(du2, -1.0 / params.lambda_ET_mm**2, out=ws("ET", shape))
        np.expm1(e, out=e)
        e *= -2.0 * params.sigma_ET_um**2
        var["ET"] = e
    else:
        var["ET"] = np.broadcast_to(np.float64(0.0), shape)
    if params.sigma_ER_urad > 0 and pa["any_offset"]:   # (no offsets: n x p = 0, ER = 0)
        ai, aj = ws("ai", shape), ws("aj", shape)
        np.einsum("kij,ki->ij", n3, P[:, I], out=ai)
        np.einsum("kij,kj->ij", n3, P[:, J], out=aj)
        rho = mul(du2, -1.0 / params.lambda_ER_mm**2, out=ws("rho", shape))
        np.exp(rho, out=rho)
        er = add(pa["p2"][I][:, None], pa["p2"][J][None, :], out=ws("ER", shape))
        er -= mul(ai, ai, out=t)
        er -= mul(aj, aj, out=t)
        pij = np.take(pa["T_pij"][:, J], kI, axis=0, out=t)
        ai *= aj
        pij -= ai
        rho *= 2.0
        rho *= pij
        er -= rho
        er *= (params.sigma_ER_urad * MILLI) ** 2
        var["ER"] = er
    else:
        var["ER"] = np.broadcast_to(np.float64(0.0), shape)
    o2 = ws.planes("o", 2, shape)
    oi = np.einsum("kij,ki->ij", n3, N[:, I], out=o2[0])
    oj = np.einsum("kij,kj->ij", n3, N[:, J], out=o2[1])
    # exp(-|n_i - n_j|^2 / lambda^2) = exp(2 M_i.M_j - |M_i|^2 - |M_j|^2), M = n / lambda_P;
    # only pairs of one probe (one lambda) use it
    kern = np.einsum("ki,kj->ij", pa["M2t"][:, I], pa["Mt"][:, J], out=ws("kern", shape))
    kern -= pa["mm"][I][:, None]
    kern -= pa["mm"][J][None, :]
    np.exp(kern, out=kern)
    # 2 C = 2 (s0_i s0_j + sp_i sp_j kern) for one probe, 0 otherwise (tables doubled exactly)
    kern *= np.take(pa["T_2sp"][:, J], kI, axis=0, out=t)
    cross = kern
    cross += np.take(pa["T_2s0"][:, J], kI, axis=0, out=t)
    so = ws.planes("so", 2, shape)
    mul(oi, pa["sP2"][I][:, None], out=so[0])
    mul(oj, pa["sP2"][J][None, :], out=so[1])
    Pv = np.einsum("kij,kij->ij", so, o2, out=ws("P", shape))
    cross *= oi
    cross *= oj
    Pv -= cross
    var["P"] = Pv
    # W (docs/workpiece.md): one temperature for every point (a task): u_W^2 = d^2 u^2(eps) exactly;
    # a temperature per point (records): the rank-3 columns, n^T (K_j - K_i)
    if "W2" in pa:
        W = mul(d, d, out=ws("W", shape))
        W *= pa["W2"]
        var["W"] = W
    elif "Kt" in pa:
        W = ws("W", shape)
        W.fill(0.0)
        for k in range(3):
            g = np.einsum("kij,kj->ij", n3, pa["Kt"][:, k, J], out=ws("gW", shape))
            g -= np.einsum("kij,ki->ij", n3, pa["Kt"][:, k, I], out=t)
            g *= g
            W += g
        var["W"] = W
    else:
        var["W"] = np.broadcast_to(np.float64(0.0), shape)
    return d, var


def row_blocks(m: int, block: int) -> list[tuple[int, int, int]]:
    """(first row, rows, first output position) of the all-pairs blocks (i < j in ``all_pairs``
    order), each with about ``block`` pairs: rows i0 .. i0+rows-1 against columns i0+1 .. m-1."""
    blocks = []
    i0 = pos = 0
    while i0 < m - 1:
        rows = max(1, min(m - 1 - i0, block // max(m - i0 - 1, 1)))
        blocks.append((i0, rows, pos))
        pos += rows * (m - 1 - i0) - rows * (rows - 1) // 2
        i0 += rows
    return blocks


#: pairs per block of the all-pairs kernel: the 24 planes of a thread's :class:`PairWorkspace`
#: (3.1 MB) stay near the cache while the Python overhead per block (about 80 numpy calls) stays
#: small (measured at m = 3,000, one thread, CPU time per pair under load, before the einsum
#: dot products: 76 ns with blocks of 4,096 pairs, 69 ns 8,192, 62 ns 16,384, 63 ns 32,768, 69 ns
#: 65,536; after them, without output writes, min of 9 at load 7: 68 ns 8,192, 64 ns 12,288,
#: 66 ns 16,384, 64 ns 24,576, 64 ns 32,768; bench/results/pairs.md)
PAIR_BLOCK = 16_384


def _all_pairs_block(cloud, params, pa, b, out, base=0, ws=None):
    """The pairs i < j of row block ``b`` (:func:`row_blocks`) into the output arrays ``out`` of
    :func:`distance_components` from position ``b[2] - base`` on, in ``all_pairs`` order.

    The variances are clipped and summed on the block's rectangle (the numbers of
    :func:`store_distances`: every factor clipped at 0, summed in the order of ``FACTORS``), then
    each row's part j > i goes out through the square root, written straight into ``out``;
    returns the number of pairs written."""
    i0, rows, pos = b
    m = cloud.m
    ws = ws if ws is not None else PairWorkspace()
    with np.errstate(invalid="ignore", divide="ignore"):
        d, var = rect_variances(cloud, params, pa, slice(i0, i0 + rows), slice(i0 + 1, m), ws)
        # R, PQ, S and ET are >= 0 by construction; ER and P are differences (clip rounding)
        for f in ("ER", "P"):
            if var[f].flags.writeable:       # a read-only broadcast 0 when the factor is off
                np.maximum(var[f], 0.0, out=var[f])
        total = np.add(var["R"], var["PQ"], out=ws("total", d.shape))
        for f in FACTORS[2:]:
            if var[f].flags.writeable:       # (a read-only broadcast here is the 0 of a factor that is off)
                total += var[f]
    start = pos - base
    p = start
    w = m - 1 - i0
    u_R = np.sqrt(var["R"][0, 0]) if var["R"].size else 0.0
    roots = [("u_um", total)] + [(f"u_{f}_um", var[f]) for f in FACTORS[1:]]
    for q in range(rows):
        e = p + w - q
        out["d_mm"][p:e] = d[q, q:]
        for key, a in roots:
            np.sqrt(a[q, q:], out=out[key][p:e])
        p = e
    out["u_R_um"][start:p] = u_R
    seg = out["d_mm"][start:p]
    if seg.size and seg.min() <= 1e-9:
        i, j = all_pairs_index(m, i0, rows, int(np.flatnonzero(seg <= 1e-9)[0]))
        raise DegenerateGeometryError(
            f"points {cloud.labels[i]} and {cloud.labels[j]} are at the same place: "
            "the distance direction n_ij of Forbes 2025 eq. (29) is undefined")
    return p - start


def all_pairs_index(m: int, i0: int, rows: int, q: int) -> tuple[int, int]:
    """(i, j) of the q-th pair of the row block starting at i0 with ``rows`` rows."""
    for i in range(i0, i0 + rows):
        if q < m - 1 - i:
            return i, i + 1 + q
        q -= m - 1 - i
    raise IndexError(q)


def iter_distance_components(cloud: PointCloud, params: Parameters, *, block: int = PAIR_BLOCK,
                             workers: int = 1):
    """Every pair i < j streamed in blocks, in ``all_pairs`` order: yields ``(sl, part)`` with
    ``part`` the arrays of :func:`distance_components` (float64) for the pairs ``sl`` of the
    whole result.  Memory is a few blocks, whatever m: a consumer that writes or reduces the
    blocks handles m(m-1)/2 pairs without holding them.  Blocks run on ``workers`` threads
    (default one: on the 2-core machine a second thread made it slower, GIL hand-offs at every
    numpy call; bench/results/pairs.md), at most two blocks ahead of the consumer per thread."""
    pa = probe_arrays(cloud, params)
    pa.update(pair_arrays(cloud, pa, params))

    local = threading.local()         # one PairWorkspace per thread

    def work(b):
        i0, rows, pos = b
        size = rows * (cloud.m - 1 - i0) - rows * (rows - 1) // 2
        part = {"d_mm": np.empty(size), "u_um": np.empty(size)}
        for f in FACTORS:
            part[f"u_{f}_um"] = np.empty(size)
        if not hasattr(local, "ws"):
            local.ws = PairWorkspace()
        _all_pairs_block(cloud, params, pa, b, part, base=pos, ws=local.ws)
        return slice(pos, pos + size), part

    yield from _ordered_blocks(work, row_blocks(cloud.m, block), workers)


def _ordered_blocks(work, blocks, workers):
    """work(b) for every block on ``workers`` threads (at least one), in order, at most two
    blocks ahead of the consumer per thread."""
    workers = min(len(blocks), workers or 1)
    if workers <= 1:
        yield from map(work, blocks)
        return
    pool = ThreadPoolExecutor(max_workers=workers)
    try:
        pending = []
        for b in blocks:
            pending.append(pool.submit(work, b))
            if len(pending) > 2 * workers:
                yield pending.pop(0).result()
        for f in pending:
            yield f.result()
    finally:
        pool.shutdown(cancel_futures=True)


def distance_components(cloud: PointCloud, params: Parameters, pairs: np.ndarray | None = None,
                        *, block: int = PAIR_BLOCK, progress=None,
                        workers: int = 1) -> dict[str, np.ndarray]:
    """d_ij (mm), u(d_ij) (µm) and the per-factor u (µm) of eq. (30) for many pairs.

    ``pairs=None`` means every pair i < j, in the order of ``all_pairs`` (the blocks of
    :func:`iter_distance_components`; to stream them instead of holding 8 m(m-1)/2 numbers, use
    that function).  Evaluates the quadratic form of eq. (29) factor by factor without forming
    V_X, about ``block`` pairs at a time, so memory grows only through the outputs.  Returns a
    dict with keys ``d_mm``, ``u_um`` and ``u_<factor>_um``.  ``progress(done, total)`` is
    called after every block.  ``workers``: threads for the blocks of all pairs (default one, as
    :func:`iter_distance_components`).
    """
    pa = probe_arrays(cloud, params)
    m = cloud.m
    if pairs is None:
        total = m * (m - 1) // 2
        out = {"d_mm": np.empty(total), "u_um": np.empty(total)}
        for f in FACTORS:
            out[f"u_{f}_um"] = np.empty(total)
        pa.update(pair_arrays(cloud, pa, params))

        local = threading.local()         # one PairWorkspace per thread

        def work(b):                      # each block writes its own rows of the outputs
            if not hasattr(local, "ws"):
                local.ws = PairWorkspace()
            return _all_pairs_block(cloud, params, pa, b, out, ws=local.ws)

        done = 0
        for size in _ordered_blocks(work, row_blocks(m, block), workers):
            done += size
            if progress is not None:
                progress(done, total)
        return out
    pairs = check_pairs(cloud, pairs)
    n = len(pairs)
    out = {"d_mm": np.empty(n), "u_um": np.empty(n)}
    for f in FACTORS:
        out[f"u_{f}_um"] = np.empty(n)
    for start in range(0, n, block):
        sl = slice(start, min(start + block, n))
        i, j = pairs[sl, 0], pairs[sl, 1]
        d, var = _distance_block(cloud, params, pa, i, j)
        store_distances(out, sl, d, var)
        if progress is not None:
            progress(sl.stop, n)
    return out


def store_distances(out: dict, sl: slice, d: np.ndarray, var: dict) -> None:
    """Distances ``d`` and their per-factor variances ``var`` into rows ``sl`` of the output
    arrays of :func:`distance_components` (u per factor and in total)."""
    out["d_mm"][sl] = d
    total = np.zeros_like(d)
    for f in FACTORS:
        v = np.maximum(var[f], 0.0)  # clip -1e-20 rounding of exact zeros
        total += v
        out[f"u_{f}_um"][sl] = np.sqrt(v)
    out["u_um"][sl] = np.sqrt(total)


def distance_u_dense(V: np.ndarray, X_mm: np.ndarray, i: int, j: int) -> float:
    """u(d_ij) from a dense V_X block by eq. (29) literally (reference implementation)."""
    n = (X_mm[j] - X_mm[i]) / np.linalg.norm(X_mm[j] - X_mm[i])
    g = np.zeros(V.shape[0])
    g[3 * i:3 * i + 3] = -n
    g[3 * j:3 * j + 3] = n
    return float(np.sqrt(max(g @ V @ g, 0.0)))


def distance_difference_u(V: np.ndarray, X_mm: np.ndarray, ij: tuple[int, int],
                          rs: tuple[int, int]) -> float:
    """u(d_ij - d_rs) of Forbes 2025 section 6 (12 x 12 quadratic form) from a dense V_X."""
    g = np.zeros(V.shape[0])
    for (a, b), sign in ((ij, 1.0), (rs, -1.0)):
        n = (X_mm[b] - X_mm[a]) / np.linalg.norm(X_mm[b] - X_mm[a])
        g[3 * a:3 * a + 3] -= sign * n
        g[3 * b:3 * b + 3] += sign * n
    return float(np.sqrt(max(g @ V @ g, 0.0)))


# ---------------------------------------------------------------------------------------------
# Summary formula and the MPE check (Forbes 2025 sections 6.7-6.8)
# ---------------------------------------------------------------------------------------------

def summary_components_um(d_mm, params: Parameters, P_mm: float) -> dict[str, np.ndarray]:
    """Terms of eq. (33) as standard uncertainties (µm): ``A`` (sigma_A of eq. 34), ``S``,
    ``ET``, ``ER`` and the total ``u``.  ``P_mm`` is the longest probe length."""
    d = np.asarray(d_mm, dtype=float)
    sA2 = 2.0 * (params.sigma_R_um**2 + params.sigma_PQ_um**2 + params.sigma_P_um**2
                 + 2.0 * params.sigma_P0_um**2)
    S2 = (params.sigma_S_ppm**2 + params.sigma_Sa_ppm**2 + params.sigma_Q_ppm**2) * (MILLI * d) ** 2
    ET2 = (2.0 * params.sigma_ET_um**2 * -np.expm1(-(d**2) / params.lambda_ET_mm**2)
           if params.sigma_ET_um > 0 else np.zeros_like(d))
    ER2 = (2.0 * (params.sigma_ER_urad * MILLI * P_mm) ** 2 * -np.expm1(-(d**2) / params.lambda_ER_mm**2)
           if params.sigma_ER_urad > 0 else np.zeros_like(d))
    return {"A": np.sqrt(sA2) + 0 * d, "S": np.sqrt(S2), "ET": np.sqrt(ET2), "ER": np.sqrt(ER2),
            "u": np.sqrt(sA2 + S2 + ET2 + ER2)}


def mpe_um(d_mm, A_um: float, B_mm: float):
    """MPE statement A + d/B in µm, d in mm (B_mm is "mm per µm", as in E = 3 + L/200)."""
    return A_um + np.asarray(d_mm, dtype=float) / B_mm


def C_of_d(d_mm, params: Parameters, A_um: float, B_mm: float, K: float, P_mm: float) -> np.ndarray:
    """C(d) = K u(d) / (A + d/B) of Forbes 2025 eq. (36) with u(d) from eq. (33)."""
    return K * summary_components_um(d_mm, params, P_mm)["u"] / mpe_um(d_mm, A_um, B_mm)


@dataclass(frozen=True)
class MPECheck:
    K: float
    C_max: float
    d_at_max_mm: float
    L_max_mm: float
    conforms: bool


def mpe_check(params: Parameters, A_um: float, B_mm: float, K: float, P_mm: float,
              L_max_mm: float = 1000.0, n_grid: int = 201) -> MPECheck:
    """Maximum of C(d) of eq. (36) over the grid d = 0, L_max/(n-1), ..., L_max (section 6.8).

    The grid (not a continuous search) is what the workbook's MPE sheet evaluates, so the
    workbook and the JSON report the same C_max and d_at_max.
    """
    if A_um <= 0 or B_mm <= 0 or K <= 0 or L_max_mm <= 0 or n_grid < 2:
        raise ModelError("A_um, B_mm, K and L_max_mm must be positive")
    d = L_max_mm * np.arange(n_grid) / (n_grid - 1)
    c = C_of_d(d, params, A_um, B_mm, K, P_mm)
    k = int(np.argmax(c))
    return MPECheck(K=K, C_max=float(c[k]), d_at_max_mm=float(d[k]), L_max_mm=L_max_mm,
                    conforms=bool(c[k] <= 1.0))


def conforming_parameters(params: Parameters, C_max: float) -> Parameters:
    """Parameters divided by C_max so that C(d) <= 1 (Forbes 2025 section 6.8).  Parameters
    that already conform (C_max <= 1) are returned unchanged."""
    return params if C_max <= 1.0 else params.scaled(C_max)
