"""The six factor covariances of Forbes 2025 eq. (28), and the workpiece's W, defined once (µm²).

====  ==========================================  =====================
R     repeatability                               eq. (8)
PQ    probe qualification, per probe              eq. (9)
S     scale and squareness, G(x_i - p_k(i))       eqs. (10)-(14)
ET    spatially correlated location errors (GP)   eqs. (20)-(21), 5.3
ER    spatially correlated rotation errors (GP)   eqs. (22)-(25)
P     probing: radius + direction-correlated GP   eqs. (26)-(27)
W     workpiece expansion about the fixture       docs/workpiece.md
====  ==========================================  =====================

The spatial kernels of ET and ER act on the machine (ram) positions ``x_i - p_k(i)``
(section 5.3, multiple probes); probing effects of different probes are independent
(section 5.5).

Two forms, the way a kernel library offers ``K(X, Y)`` and ``diag(X)``:

* :func:`factor_block` -- rows of points I, columns of points J of every factor
  (3|I| x 3|J|, coordinates interleaved x1, y1, z1, x2, ...); I = J = all points is the dense
  V_X of eq. (28);
* :func:`factor_diagonal` -- the 3 x 3 blocks V_ii of every point (m x 3 x 3).

Every evaluation path (dense, blocked, low-rank, structured, Monte Carlo, simulator, locator)
is checked against these two in ``tests/core/test_model_paths.py``.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..errors import ModelError
from .geometry import G_S, skew, sq_dists
from .hyperparameters import PROBE_OVERRIDES, S_COLUMNS
from .parameters import FACTORS, MILLI, Parameters, PointCloud


def V_S_diag_um_per_mm2(params: Parameters) -> np.ndarray:
    """Diagonal of V_B of eq. (13), converted from ppm² to (µm/mm)²."""
    s = np.array([getattr(params, n) for n in S_COLUMNS]) * MILLI
    return s**2


def probe_arrays(cloud: PointCloud, params: Parameters) -> dict[str, np.ndarray]:
    """Per point (length m): the hyper-parameters a probe may override (``PROBE_OVERRIDES``:
    sigma_PQ_um, sigma_P0_um, sigma_P_um, lambda_P) of its probe, per-probe overrides resolved
    against the task-wide defaults."""
    probes = [p.resolved(params) for p in cloud.probes]
    k = cloud.probe_index
    return {n: np.array([getattr(p, n) for p in probes], dtype=float)[k] for n in PROBE_OVERRIDES}


def workpiece_columns(cloud: PointCloud, params: Parameters) -> np.ndarray:
    """K of V_W = K K^T, per point (m x 3 x 3, µm): (x_i - x0) times the three coefficients of
    :meth:`xlfuncs.model.workpiece.Workpiece.coefficients_ppm` (10^-6; ppm x mm = 10^-3 µm).
    Zeros without a workpiece or with W switched off."""
    wp = cloud.workpiece
    if wp is None or not wp.enabled:
        return np.zeros((cloud.m, 3, 3))
    c = wp.coefficients_ppm(params.u_alpha_ppm_per_K, params.u_T_K, cloud.temperature_C, cloud.m)
    w = cloud.X_mm - np.asarray(wp.fixture_mm)
    return w[:, :, None] * (c * MILLI)[:, None, :]


def gauss_kernel(D2: np.ndarray, lam2, d_log_lambda: bool = False) -> np.ndarray:
    """The squared-exponential correlation exp(-D^2/lambda^2) of eqs. (21), (25), (27)
    (``lam2`` = lambda^2, a number or an array), or with ``d_log_lambda`` its derivative in
    log lambda, (2 D^2/lambda^2) exp(-D^2/lambda^2)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        q = D2 / lam2
        k = np.exp(-q)
        return 2.0 * q * k if d_log_lambda else k


def point_index(cloud: PointCloud, I) -> np.ndarray:
    """Point indices from ``None`` (all), a slice or an integer array (checked)."""
    if I is None:
        return np.arange(cloud.m)
    if isinstance(I, slice):
        return np.arange(cloud.m)[I]
    I = np.asarray(I, dtype=int).reshape(-1)
    if I.size and (I.min() < 0 or I.max() >= cloud.m):
        raise ModelError("point index out of range")
    return I


def check_factors(factors: Sequence[str]) -> None:
    for f in factors:
        if f not in FACTORS:
            raise ModelError(f"unknown influence factor {f!r}; known: {', '.join(FACTORS)}")


def factor_block(cloud: PointCloud, params: Parameters, I=None, J=None, factors: Sequence[str] = FACTORS,
                 *, d_log_lambda: bool = False) -> dict[str, np.ndarray]:
    """Rows of points I and columns of points J of the factors of eq. (28), µm²:
    ``{factor: (3|I|) x (3|J|)}``, coordinates interleaved (the paper's x_{1:m}).  ``None``
    means every point, so ``factor_block(cloud, params)`` is the dense V_X per factor.

    ``d_log_lambda``: the GP factors ET, ER and P with their kernels replaced by the derivative
    in log lambda (:func:`gauss_kernel`; the radius part of P dropped), the closed-form
    dV/d(log lambda) of the hyper-parameter fit (:mod:`xlfuncs.calibrate`)."""
    I, J = point_index(cloud, I), point_index(cloud, J)
    check_factors(factors)
    pa = probe_arrays(cloud, params)
    ki, kj = cloud.probe_index[I], cloud.probe_index[J]
    same = (ki[:, None] == kj[None, :]).astype(float)
    shape = (3 * len(I), 3 * len(J))
    I3 = np.eye(3)
    U = cloud.ram_mm
    D2: Any = None                       # squared distances of the ram positions, when a GP factor needs them
    if ("ET" in factors and params.sigma_ET_um > 0) or ("ER" in factors and params.sigma_ER_urad > 0):
        D2 = sq_dists(U[I], U[J])
    out: dict[str, np.ndarray] = {}
    for f in factors:
        if f == "R":
            # eq. (8): sigma_R^2 I, one probing, one repeatability draw
            out[f] = params.sigma_R_um**2 * np.kron((I[:, None] == J[None, :]).astype(float), I3)
        elif f == "PQ":
            # eq. (9): G_X|PQ V_PQ G_X|PQ^T, same probe -> sigma_PQ,k^2 I_3 in every block pair
            s = pa["sigma_PQ_um"]
            out[f] = np.kron(same * np.outer(s[I], s[J]), I3)
        elif f == "S":
            # eqs. (11)-(14) at x_i - p_k(i)
            GI = G_S(U[I]).reshape(-1, 7)
            GJ = G_S(U[J]).reshape(-1, 7)
            out[f] = (GI * V_S_diag_um_per_mm2(params)) @ GJ.T
        elif f == "ET":
            # eq. (21): independent axes, kernel on ram positions
            out[f] = (np.kron(params.sigma_ET_um**2 * gauss_kernel(D2, params.lambda_ET_mm**2, d_log_lambda), I3)
                      if params.sigma_ET_um > 0 else np.zeros(shape))
        elif f == "ER":
            # eq. (25): sigma_ER^2 exp(-d_ij^2/lambda^2) G_k(i) G_k(j)^T
            if params.sigma_ER_urad > 0:
                P = cloud.offsets_mm
                GRI, GRJ = skew(P[I]).reshape(-1, 3), skew(P[J]).reshape(-1, 3)   # mm/rad
                rho = gauss_kernel(D2, params.lambda_ER_mm**2, d_log_lambda)
                out[f] = (params.sigma_ER_urad * MILLI) ** 2 * np.kron(rho, np.ones((3, 3))) * (GRI @ GRJ.T)
            else:
                out[f] = np.zeros(shape)
        elif f == "P":
            # eqs. (26)-(27): N V_DP N^T, probes independent
            N = cloud.N
            lam, sP, s0 = pa["lambda_P"], pa["sigma_P_um"], pa["sigma_P0_um"]
            spp = np.outer(sP[I], sP[J])
            with np.errstate(divide="ignore", invalid="ignore"):
                kern = np.where(spp > 0, gauss_kernel(sq_dists(N[I], N[J]), np.outer(lam[I], lam[J]),
                                                       d_log_lambda), 0.0)
            radius = 0.0 if d_log_lambda else np.outer(s0[I], s0[J])
            V_DP = same * (radius + spp * kern)
            NN = np.einsum("ia,jb->iajb", N[I], N[J]).reshape(shape)
            out[f] = np.kron(V_DP, np.ones((3, 3))) * NN
        elif f == "W":
            # docs/workpiece.md: u^2(eps) (x_i - x0)(x_j - x0)^T, as K_I K_J^T
            K = workpiece_columns(cloud, params)
            out[f] = K[I].reshape(-1, 3) @ K[J].reshape(-1, 3).T
    return out


def factor_diagonal(cloud: PointCloud, params: Parameters, factors: Sequence[str] = FACTORS,
                    *, d_log_lambda: bool = False) -> dict[str, np.ndarray]:
    """The 3 x 3 blocks V_ii of every point of the factors of eq. (28), µm²: ``{factor: m x 3 x 3}``,
    the diagonal blocks of :func:`factor_block` (a kernel at distance 0 is 1; its derivative
    in log lambda is 0)."""
    check_factors(factors)
    m = cloud.m
    pa = probe_arrays(cloud, params)
    I3 = np.broadcast_to(np.eye(3), (m, 3, 3))
    k0 = 0.0 if d_log_lambda else 1.0
    out: dict[str, np.ndarray] = {}
    for f in factors:
        if f == "R":
            out[f] = params.sigma_R_um**2 * I3
        elif f == "PQ":
            out[f] = (pa["sigma_PQ_um"] ** 2)[:, None, None] * I3
        elif f == "S":
            G = G_S(cloud.ram_mm)
            out[f] = np.einsum("iak,k,ibk->iab", G, V_S_diag_um_per_mm2(params), G)
        elif f == "ET":
            out[f] = (params.sigma_ET_um**2 * k0) * I3
        elif f == "ER":
            GR = skew(cloud.offsets_mm)
            out[f] = (params.sigma_ER_urad * MILLI) ** 2 * k0 * (GR @ GR.transpose(0, 2, 1))
        elif f == "P":
            sP, s0 = pa["sigma_P_um"], pa["sigma_P0_um"]
            v = (0.0 if d_log_lambda else s0**2) + sP**2 * k0
            out[f] = v[:, None, None] * np.einsum("ia,ib->iab", cloud.N, cloud.N)
        elif f == "W":
            K = workpiece_columns(cloud, params)
            out[f] = K @ K.transpose(0, 2, 1)
    return out
