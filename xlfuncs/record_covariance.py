"""The covariance of length records, C = G V_X G^T with g_a = [-n_a; n_a] (Forbes 2025 eq. 29 for
every pair of records): the record covariance of the mismatch locator (``cmmwb diagnose``) and of
the REML fit of ``cmmwb calibrate``, for the six factors of eq. (28) defined in
:mod:`xlfuncs.model`.

Every entry involves four kernel values at the records' end points, summed in one place
(:func:`_record_sums`) from kernels either computed directly in row blocks of records (memory
that of C; a given ``block`` or ``backend``, run by :func:`xlfuncs.execution.run_blocks` locally
or on Dask, bit-equal) or, for a few unique points, formed once for all point pairs and gathered
(:class:`_GatheredKernels`).  Units: coordinates mm, C in µm².
"""

from __future__ import annotations

import threading

import numpy as np

from . import pointcloud as pc
from .blocked import BLOCK_ENTRIES
from .errors import ModelError
from .execution import run_blocks
from .model import gauss_kernel, scale_rows, sq_dists, workpiece_columns

FACTORS = pc.FACTORS
MILLI = pc.MILLI


#: exp(-q) is below the smallest normal double (2.2e-308) beyond this q; numpy's exp takes 10-100
#: times longer on such arguments (subnormal and underflowing results), and a calibration that
#: tries a short length scale meets them for most point pairs
UNDERFLOW_Q = 708.0


def _kernel(D2: np.ndarray, lam2, dll: bool) -> np.ndarray:
    """:func:`xlfuncs.model.gauss_kernel`, the entries with D^2/lambda^2 > :data:`UNDERFLOW_Q` set to 0
    without evaluating them (they differ from it by less than 1e-304; every other entry is its
    value, to the bit)."""
    far = D2 > UNDERFLOW_Q * lam2
    if not far.any():
        return gauss_kernel(D2, lam2, dll)
    near = ~far
    K = np.zeros_like(D2)
    K[near] = gauss_kernel(D2[near], lam2[near] if np.ndim(lam2) else lam2, dll)
    return K


class _PointKernels:
    """The point kernels of the GP factors of eq. (28) between end points s and t of records,
    k_f(s, t) (|s| x |t|, unscaled: the sigma^2 of ET and ER is applied to the sums), evaluated
    directly from the coordinates: memory of the block asked for, whatever m (row blocks).

    ET (eq. 21) and ER (eq. 25): exp(-|u_s - u_t|^2/lambda^2) of the ram positions u; P
    (eqs. 26-27): same probe x (sigma_P0,s sigma_P0,t + sigma_P,s sigma_P,t
    exp(-|n_s - n_t|^2/(lambda_P,s lambda_P,t))).  With ``d_log_lambda`` every exp(-D^2/lambda^2)
    is replaced by its derivative in log lambda and the radius part of P is dropped
    (:func:`_kernel`).  ``factors``: the GP factors that are not zero at these parameters."""

    def __init__(self, cloud: pc.PointCloud, params: pc.Parameters, pa: dict, d_log_lambda: bool):
        self.cloud, self.params, self.pa, self.dll = cloud, params, pa, d_log_lambda
        self.factors = tuple(f for f, on in (
            ("ET", params.sigma_ET_um > 0), ("ER", params.sigma_ER_urad > 0),
            ("P", bool(np.any(pa["sigma_P_um"] > 0) or (not d_log_lambda and np.any(pa["sigma_P0_um"] > 0)))))
            if on)

    def __call__(self, s: np.ndarray, t: np.ndarray) -> dict[str, np.ndarray]:
        return self._kernels(s, t, lambda Z: sq_dists(Z[s], Z[t]))

    def _kernels(self, s, t, sq) -> dict[str, np.ndarray]:
        """The kernels between the points s and t, ``sq(Z)`` the squared distances of Z[s], Z[t]."""
        cloud, params, pa, dll = self.cloud, self.params, self.pa, self.dll
        out = {}
        if "ET" in self.factors or "ER" in self.factors:
            D2 = sq(cloud.ram_mm)
            if "ET" in self.factors:
                out["ET"] = _kernel(D2, params.lambda_ET_mm**2, dll)
            if "ER" in self.factors:
                out["ER"] = _kernel(D2, params.lambda_ER_mm**2, dll)
        if "P" in self.factors:
            kp = cloud.probe_index
            s0, sp, lam = pa["sigma_P0_um"], pa["sigma_P_um"], pa["lambda_P"]
            same = kp[s][:, None] == kp[t][None, :]
            spp = np.outer(sp[s], sp[t])
            kern = np.where(spp > 0, _kernel(sq(cloud.N), np.outer(lam[s], lam[t]), dll), 0.0)
            out["P"] = same * ((0.0 if dll else np.outer(s0[s], s0[t])) + spp * kern)
        return out


#: the squared distances sq_dists(Z, Z) of the last few point sets Z (ram positions, normals) of
#: at most ``_POINT_D2_MAX_M`` points, by content (read-only; 64 MB at most): the likelihood of
#: ``cmmwb calibrate`` forms the kernels of the same points for every trial of the length scales
_POINT_D2: dict[bytes, np.ndarray] = {}
_POINT_D2_KEEP = 8
_POINT_D2_MAX_M = 1000
_POINT_D2_LOCK = threading.Lock()


def _unique_points_d2(Z: np.ndarray) -> np.ndarray:
    """:func:`xlfuncs.model.sq_dists` (Z, Z), remembered for small Z (:data:`_POINT_D2`)."""
    if Z.shape[0] > _POINT_D2_MAX_M:
        return sq_dists(Z, Z)
    key = np.ascontiguousarray(Z, dtype=float).tobytes()
    with _POINT_D2_LOCK:
        D2 = _POINT_D2.pop(key, None)
    if D2 is None:
        D2 = sq_dists(Z, Z)
        D2.setflags(write=False)
    with _POINT_D2_LOCK:
        _POINT_D2.pop(key, None)
        while len(_POINT_D2) >= _POINT_D2_KEEP:
            _POINT_D2.pop(next(iter(_POINT_D2)))
        _POINT_D2[key] = D2           # the most recent last
    return D2


class _GatheredKernels(_PointKernels):
    """The same kernels, those of all unique points formed once (m x m each, at most three) and
    gathered for the end points asked for: the records of a calibration's likelihood (a few
    hundred, on as many points) need each point pair four times, and the likelihood evaluates
    them many times (the points' squared distances are remembered: :func:`_unique_points_d2`)."""

    def __init__(self, cloud: pc.PointCloud, params: pc.Parameters, pa: dict, d_log_lambda: bool):
        super().__init__(cloud, params, pa, d_log_lambda)
        every = np.arange(cloud.m)
        self.K = self._kernels(every, every, _unique_points_d2) if self.factors else {}

    def __call__(self, s: np.ndarray, t: np.ndarray) -> dict[str, np.ndarray]:
        if not self.K:
            return {}
        flat = s[:, None] * self.cloud.m + t[None, :]
        return {f: K.take(flat) for f, K in self.K.items()}


def _record_sums(item, shared) -> dict[str, np.ndarray]:
    """Rows a0 .. a1-1 of C_f = G V_X,f G^T for every factor f of eq. (28), µm²: the one place
    where the length-record sums are written (both forms of :func:`record_covariance`; which
    form only decides where ``shared["kernels"]`` takes the GP kernels from).

    A record a is g_a = -n_a at point I[a] and +n_a at J[a] (eq. 29), so
    C_f[a, b] = sum over the ends s of a and t of b of sign_s sign_t k_f(s_a, t_b) w_{a,s} . w_{b,t},
    with the point kernel k_f of the factor and its direction term w: n_a for R (eq. 8, one
    probing, one repeatability draw), PQ (eq. 9, same probe) and ET (eq. 21, independent axes);
    w = G_k^T n_a = n_a x p_k for ER (eqs. 24-25); w = n_a . n_point for P (eqs. 26-27).  S is rank
    7 at the ram positions (eq. 11), W rank 3 at the points (docs/workpiece.md).  A factor that is zero at these parameters is left out (the
    caller's zeros)."""
    a0, a1 = item
    cloud, params, pa = shared["cloud"], shared["params"], shared["pa"]
    I, J, na, kernels = shared["I"], shared["J"], shared["na"], shared["kernels"]
    rows, n, b = slice(a0, a1), len(I), a1 - a0
    kp, sPQ = cloud.probe_index, pa["sigma_PQ_um"]
    live = [f for f, on in (("R", params.sigma_R_um > 0), ("PQ", bool(np.any(sPQ > 0)))) if on]
    live += kernels.factors
    sums = {f: np.zeros((b, n)) for f in live}
    # direction terms of the records' ends (the first end I, the second J): rows, every record
    W = {}
    if "ER" in live:
        P = cloud.offsets_mm
        W["ER"] = [(np.cross(na[rows], P[e[rows]]), np.cross(na, P[e])) for e in (I, J)]
    if "P" in live:
        N = cloud.N
        W["P"] = [(np.einsum("ij,ij->i", na[rows], N[e[rows]])[:, None],
                   np.einsum("ij,ij->i", na, N[e])[:, None]) for e in (I, J)]
    for i, s in enumerate((I, J)):
        sa = s[rows]
        for j, t in enumerate((I, J)):
            add = np.add if i == j else np.subtract      # sign_s sign_t: -1 for I, +1 for J
            if "R" in live:
                add(sums["R"], sa[:, None] == t[None, :], out=sums["R"])
            if "PQ" in live:
                add(sums["PQ"], (kp[sa][:, None] == kp[t][None, :]) * np.outer(sPQ[sa], sPQ[t]), out=sums["PQ"])
            K = kernels(sa, t)
            if "ET" in live:
                add(sums["ET"], K["ET"], out=sums["ET"])
            for f in ("ER", "P"):
                if f in live:
                    w = W[f][i][0] @ W[f][j][1].T
                    add(sums[f], np.multiply(K[f], w, out=w), out=sums[f])
    NN = na[rows] @ na.T
    out = {}
    if "R" in live:
        out["R"] = params.sigma_R_um**2 * sums["R"] * NN
    if "PQ" in live:
        out["PQ"] = sums["PQ"] * NN
    if "ET" in live:
        out["ET"] = params.sigma_ET_um**2 * sums["ET"] * NN
    if "ER" in live:
        out["ER"] = (params.sigma_ER_urad * MILLI) ** 2 * sums["ER"]
    if "P" in live:
        out["P"] = sums["P"]
    V_S = pc.V_S_diag_um_per_mm2(params)
    if np.any(V_S > 0):
        g7 = shared["g7"]
        out["S"] = (g7[rows] * V_S) @ g7.T
    gW = shared.get("gW")
    if gW is not None:           # W (docs/workpiece.md): rank 3, g_a^T K = n_a^T (K_J - K_I)
        out["W"] = gW[rows] @ gW.T
    return out


#: few unique points (every record set the locator and the calibration treat densely): the
#: kernels of the unique points are formed once (three m x m arrays of at most this many bytes)
#: and gathered for the records' four end-point combinations; beyond it, row blocks
POINT_KERNEL_BYTES = 1 << 29


def record_covariance(cloud: pc.PointCloud, params: pc.Parameters, I, J, *, components: bool = False,
                      d_log_lambda: bool = False, block: int | None = None, backend=None,
                      progress=None):
    """Covariance (µm²) of the lengths d_a = ||x_J[a] - x_I[a]||: C = G V_X G^T with
    g_a = -n_a at point I[a] and +n_a at J[a] (eq. 29), per factor if ``components``.

    The one implementation of the length-record covariance (the locator's
    :func:`xlfuncs.locator.model.length_covariance` is this function): each factor of eq. (28)
    is a point kernel times a direction term, so every entry is built from the kernel at the
    records' four end-point combinations (w = n_a for R, PQ, ET; n_a x p for ER, eq. 24;
    n_a . n_point for P, eq. 26; S is rank 7, eq. 11), summed by :func:`_record_sums`.  Where the
    kernels come from is the only difference between the two forms:

    * a given ``block`` or ``backend``: row blocks of records, each evaluating the kernels at its
      end points (:class:`_PointKernels`): no m x m kernel of the unique points is formed,
      memory O(n^2) for n records whatever m, the same numbers on any backend;
    * otherwise, when the unique points' kernels take at most ``POINT_KERNEL_BYTES``: the m x m
      kernels formed once and gathered (:class:`_GatheredKernels`; the likelihood of
      ``cmmwb calibrate`` evaluates this many times for a few hundred records).  The same sums
      over the same kernel values: equal to the row blocks to rounding.

    A factor whose standard deviations are all zero is zeros, not summed; kernel entries with
    D^2/lambda^2 > :data:`UNDERFLOW_Q` are 0 (below 1e-304, :func:`_kernel`).

    ``d_log_lambda`` (with ``components``): the GP factors ET, ER and P with every kernel
    exp(-D^2/lambda^2) replaced by its derivative in log lambda (:func:`xlfuncs.model.gauss_kernel`),
    the radius part of P dropped: the closed-form dC/d(log lambda) of the hyper-parameter fit
    (:mod:`xlfuncs.calibrate`).
    """
    I = np.asarray(I, dtype=int).reshape(-1)
    J = np.asarray(J, dtype=int).reshape(-1)
    if I.shape != J.shape:
        raise ModelError("I and J must have the same length")
    if I.size and (min(I.min(), J.min()) < 0 or max(I.max(), J.max()) >= cloud.m):
        raise ModelError("point index out of range")
    n = len(I)
    d = cloud.X_mm[J] - cloud.X_mm[I]
    dn = np.linalg.norm(d, axis=1)
    if np.any(dn <= 1e-9):
        a = int(np.flatnonzero(dn <= 1e-9)[0])
        raise ModelError(f"record {a + 1}: both ends at the same place, the direction n of "
                         "Forbes 2025 eq. (29) is undefined")
    na = d / dn[:, None]
    pa = pc.probe_arrays(cloud, params)
    shared = {"cloud": cloud, "params": params, "pa": pa, "I": I, "J": J, "na": na,
              "g7": scale_rows(na, cloud.ram_mm[J] - cloud.ram_mm[I])}
    if cloud.W_on:
        K = workpiece_columns(cloud, params)
        shared["gW"] = np.einsum("pa,pak->pk", na, K[J] - K[I])
    if backend is None and block is None and 3 * 8 * cloud.m**2 <= POINT_KERNEL_BYTES:
        shared["kernels"] = _GatheredKernels(cloud, params, pa, d_log_lambda)
        out = _record_sums((0, n), shared)
    else:       # row blocks (those of a given ``block`` size or ``backend``: the same on any backend)
        shared["kernels"] = _PointKernels(cloud, params, pa, d_log_lambda)
        rows = max(1, (block or BLOCK_ENTRIES // 16) // max(n, 1))
        items = [(a0, min(a0 + rows, n)) for a0 in range(0, n, rows)]
        parts = run_blocks(_record_sums, items, shared, backend, progress, [a1 - a0 for a0, a1 in items])
        out = {f: np.empty((n, n)) for f in parts[0]} if parts else {}
        for (a0, a1), part in zip(items, parts):
            for f, M in part.items():
                out[f][a0:a1] = M
    for f in FACTORS:
        out[f] = 0.5 * (out[f] + out[f].T) if f in out else np.zeros((n, n))
    if components:
        return out
    total = sum(out[f] for f in FACTORS)
    return 0.5 * (total + total.T)
