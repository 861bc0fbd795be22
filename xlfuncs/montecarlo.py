"""Monte Carlo of the Forbes 2025 point-cloud model (JCGM 101), to compare with the direct
(law of propagation) evaluation of :mod:`xlfuncs.pointcloud` and :mod:`xlfuncs.blocked`.

The influence factors are drawn, not V_X: each factor f of eq. (28) is a linear map of
independent standard normal effects, delta_f = A_f z_f (µm, 3m values, x1 y1 z1 x2 ...), with
A_f A_f^T = V_X,f:

====  =================================================================================  ===========
R     sigma_R z (one effect per coordinate)                                              eq. (8)
PQ    e_PQ,k ~ N(0, sigma_PQ,k^2 I_3) per probe, the same for every point of the probe   eq. (9)
S     b ~ N(0, V_B), delta_i = G(x_i - p_k(i)) b                                         eqs. (10)-(13)
ET    e(u_i) per axis, a Gaussian-process draw L z with L L^T = exp(-D^2/lambda^2)       eq. (21)
ER    alpha(u_i) per axis drawn likewise, delta_i = G_k(i) alpha_i                       eqs. (22)-(25)
P     per probe: e_P0 (radius) + a GP draw over the normals, delta_i = (e_P0 + e_P,i) n_i  eqs. (26)-(27)
W     alpha ~ N(alpha, u^2(alpha)), T ~ N(T, u^2(T)) + U(-dT/2, dT/2): the part expands by    docs/workpiece.md
      alpha (T - 20) - alpha_c (T_est - 20) about x0 (the physical model, not linearised)
====  =================================================================================  ===========

(L from the eigen-decomposition of the kernel matrix, eigenvalues below ``rank_tol`` times the
largest dropped: Gaussian kernels are numerically of low rank.)  Each draw perturbs the points,
x_i + delta_i, and the measurand is evaluated exactly (not linearised): the distance
||x_j + delta_j - x_i - delta_i|| (Forbes 2025 section 6), or the least-squares element refitted
to the perturbed points by Gauss-Newton (Forbes 2022).  The number of draws follows the
adaptive procedure of JCGM 101:2008 section 7.9: batches of M draws until twice the standard
deviation of the batch estimates' mean, 2 s_u, is at most the numerical tolerance delta of
u with ``n_dig`` significant digits (delta = 10^l / 2 for u = c 10^l, c an n_dig-digit integer).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from . import pointcloud as pc
from .errors import ModelError
from .model import G_S, REFERENCE_C, skew, sq_dists, workpiece_columns

FACTORS = pc.FACTORS
MILLI = pc.MILLI
#: the dense maps A_f need (3m)^2 numbers; Monte Carlo is a comparison for tasks up to this size
MAX_POINTS = 3000


# ---------------------------------------------------------------------------------------------
# drawing the influence factors
# ---------------------------------------------------------------------------------------------

def kernel_basis(K: np.ndarray, rank_tol: float = 1e-13) -> tuple[np.ndarray, np.ndarray]:
    """(L, Q^T) of a symmetric positive semi-definite kernel matrix K: L = Q diag(w)^(1/2) (n x r,
    L L^T = K) from its eigen-decomposition, eigenvalues below ``rank_tol`` times the largest dropped
    (below 1e-13 an eigenvalue is rounding, ~1e-16 of the largest, and its eigenvector differs from
    CPU to CPU), and the r x n matrix Q^T of its eigenvectors.  A draw L (Q^T z), z of length n, is K^(1/2) z: unique, whatever basis the BLAS
    kernel chose for a degenerate eigenvalue (a regular grid has many), so a seeded Monte Carlo
    gives the same numbers on every CPU; L z' with z' of length r would not."""
    if K.size == 0:
        return np.zeros((K.shape[0], 0)), np.zeros((0, K.shape[0]))
    w, Q = np.linalg.eigh(K)
    keep = w > rank_tol * max(w[-1], 0.0)
    return Q[:, keep] * np.sqrt(w[keep]), Q[:, keep].T.copy()


class PointCloudSampler:
    """Draws of the six influence factors of a point cloud as coordinate perturbations (µm).

    ``maps[f]`` is A_f (3m x r_f) with delta_f = A_f z_f, or a number s for R (delta = s z).
    ``inputs[f]`` says how z_f is drawn: segments (n, reps, T) of standard normals (n x reps),
    mapped by T (r x n, the kernel's eigenvectors) where a Gaussian-process factor is low rank
    (:func:`kernel_basis`), their columns in the order of A_f.
    """

    def __init__(self, cloud: pc.PointCloud, params: pc.Parameters, factors: Sequence[str] = FACTORS,
                 rank_tol: float = 1e-13):
        m = cloud.m
        if m > MAX_POINTS:
            raise ModelError(f"the Monte Carlo comparison handles up to {MAX_POINTS} points, got {m}")
        for f in factors:
            if f not in FACTORS:
                raise ModelError(f"unknown influence factor {f!r}")
        self.cloud, self.params, self.factors = cloud, params, tuple(factors)
        pa = pc.probe_arrays(cloud, params)
        k = cloud.probe_index
        U, N = cloud.ram_mm, cloud.N
        maps: dict[str, np.ndarray | float] = {}
        inputs: dict[str, list] = {}
        if "R" in factors:
            maps["R"] = float(params.sigma_R_um)
        if "PQ" in factors:
            nP = len(cloud.probes)
            A = np.zeros((m, 3, nP, 3))
            A[np.arange(m), :, k, :] = pa["sigma_PQ_um"][:, None, None] * np.eye(3)
            maps["PQ"] = A.reshape(3 * m, 3 * nP)
            inputs["PQ"] = [(3 * nP, 1, None)]
        if "S" in factors:
            maps["S"] = G_S(cloud.ram_mm).reshape(-1, 7) * np.sqrt(pc.V_S_diag_um_per_mm2(params)) if m else np.zeros((0, 7))
            inputs["S"] = [(7, 1, None)]
        D2 = None
        if ("ET" in factors and params.sigma_ET_um > 0) or ("ER" in factors and params.sigma_ER_urad > 0):
            D2 = sq_dists(U, U)
        if "ET" in factors:
            if params.sigma_ET_um > 0:
                L, T = kernel_basis(np.exp(-D2 / params.lambda_ET_mm**2), rank_tol)
                maps["ET"] = params.sigma_ET_um * np.einsum("ir,ac->iarc", L, np.eye(3)).reshape(3 * m, -1)
                inputs["ET"] = [(m, 3, T)]
            else:
                maps["ET"] = np.zeros((3 * m, 0))
        if "ER" in factors:
            if params.sigma_ER_urad > 0:
                L, T = kernel_basis(np.exp(-D2 / params.lambda_ER_mm**2), rank_tol)
                GR = skew(cloud.offsets_mm)
                maps["ER"] = params.sigma_ER_urad * MILLI * np.einsum("iac,ir->iarc", GR, L).reshape(3 * m, -1)
                inputs["ER"] = [(m, 3, T)]
            else:
                maps["ER"] = np.zeros((3 * m, 0))
        if "P" in factors:
            cols, segs = [], []
            s0, sp, lam = pa["sigma_P0_um"], pa["sigma_P_um"], pa["lambda_P"]
            for q in range(len(cloud.probes)):
                idx = np.flatnonzero(k == q)
                if not idx.size:
                    continue
                c0 = np.zeros((m, 1))
                c0[idx, 0] = s0[idx]
                cols.append(c0)
                segs.append((1, 1, None))
                if sp[idx[0]] > 0:
                    L, T = kernel_basis(np.exp(-sq_dists(N[idx], N[idx]) / lam[idx[0]] ** 2), rank_tol)
                    cP = np.zeros((m, L.shape[1]))
                    cP[idx] = sp[idx[0]] * L
                    cols.append(cP)
                    segs.append((len(idx), 1, T))
            C = np.hstack(cols) if cols else np.zeros((m, 0))
            maps["P"] = np.einsum("ia,ir->iar", N, C).reshape(3 * m, -1)
            inputs["P"] = segs
        if "W" in factors:
            # the linear map of V_W = K K^T (its covariance); the draws perturb alpha and T (draw)
            maps["W"] = workpiece_columns(cloud, params).reshape(3 * m, 3)
            inputs["W"] = [(3, 1, None)]
        self.maps, self.inputs = maps, inputs

    def covariance(self, f: str) -> np.ndarray:
        """A_f A_f^T: the V_X,f that the draws of factor f follow (µm²)."""
        A = self.maps[f]
        if isinstance(A, float):
            return A**2 * np.eye(3 * self.cloud.m)
        return A @ A.T

    def draw(self, M: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """M draws of every factor: {f: (M, m, 3) coordinate perturbations in µm}."""
        m = self.cloud.m
        out = {}
        for f in self.factors:
            A = self.maps[f]
            if f == "W":
                out[f] = self._workpiece(M, rng)
            elif isinstance(A, float):
                out[f] = A * rng.standard_normal((M, m, 3))
            elif A.shape[1] == 0:
                out[f] = np.zeros((M, m, 3))
            else:
                out[f] = (self._coefficients(f, M, rng) @ A.T).reshape(M, m, 3)
        return out

    def _workpiece(self, M: int, rng: np.random.Generator) -> np.ndarray:
        """M draws of the part's thermal error (M, m, 3), µm: alpha and the part's temperature drawn
        (normal alpha and thermometer error, a uniform spread over the temperature difference dT
        across the part), the part expanded by alpha_q (t_i + dT_q - 20) about the fixture point and
        corrected by the CMM with alpha_c at the estimated t_i: e_i = eps_q,i (x_i - x0)."""
        cloud, p = self.cloud, self.params
        m = cloud.m
        if not cloud.W_on:
            return np.zeros((M, m, 3))
        wp = cloud.workpiece
        t = np.full(m, wp.T_degC) if cloud.temperature_C is None else cloud.temperature_C
        z = rng.standard_normal((M, 2))
        spread = rng.uniform(-0.5, 0.5, M) * wp.dT_K
        alpha = wp.alpha_ppm_per_K + p.u_alpha_ppm_per_K * z[:, 0]
        dT = p.u_T_K * z[:, 1] + spread
        eps = alpha[:, None] * (t[None, :] + dT[:, None] - REFERENCE_C) - wp.alpha_c * (t[None, :] - REFERENCE_C)
        return eps[:, :, None] * ((cloud.X_mm - np.asarray(wp.fixture_mm)) * MILLI)[None]

    def _coefficients(self, f: str, M: int, rng: np.random.Generator) -> np.ndarray:
        """z_f (M x r_f) of every draw, segment by segment (see ``inputs``)."""
        parts = []
        for n, reps, T in self.inputs[f]:
            z = rng.standard_normal((M, n, reps))
            if T is not None:
                z = np.einsum("rn,Mnc->Mrc", T, z)
            parts.append(z.reshape(M, -1))
        return np.concatenate(parts, axis=1)


# ---------------------------------------------------------------------------------------------
# JCGM 101 section 7.9: adaptive number of draws
# ---------------------------------------------------------------------------------------------

@dataclass
class MCResult:
    """Monte Carlo standard uncertainties of the outputs ``names`` (pooled over all draws)."""

    names: list[str]
    u: np.ndarray                              # per output
    components: dict[str, np.ndarray]          # per factor, per output (drawn alone)
    draws: int
    batches: int
    seconds: float
    converged: bool
    s_u: np.ndarray                            # standard deviation of the mean of the batch u's
    tolerance: np.ndarray                      # delta of JCGM 101 7.9.2 for n_dig digits
    n_dig: int
    history: list[tuple[int, float]] = field(default_factory=list)   # (draws, seconds)


def numerical_tolerance(u: np.ndarray, n_dig: int) -> np.ndarray:
    """delta = 10^l / 2 with u = c 10^l, c an integer of n_dig digits (JCGM 101 7.9.2)."""
    u = np.asarray(u, dtype=float)
    with np.errstate(divide="ignore"):
        l = np.floor(np.log10(np.where(u > 0, u, 1.0))) - (n_dig - 1)
    return np.where(u > 0, 0.5 * 10.0**l, 0.0)


def adaptive(batch_fn: Callable[[int, np.random.Generator], dict[str, np.ndarray]], names: list[str], *,
             n_dig: int = 2, batch: int = 10_000, max_draws: int = 10_000_000,
             rng: np.random.Generator | None = None, progress=None) -> MCResult:
    """Run ``batch_fn(M, rng) -> {"total": (M, n_out), factor: (M, n_out), ...}`` in batches of
    M = ``batch`` draws until 2 s_u <= delta for every output's u (JCGM 101 7.9.4) or
    ``max_draws``.  u is the standard deviation of all draws; components the same for each
    factor drawn alone."""
    if n_dig < 1 or batch < 2:
        raise ModelError("n_dig >= 1 and batch >= 2 draws are needed")
    rng = np.random.default_rng() if rng is None else rng
    t0 = time.perf_counter()
    acc: dict[str, list] = {}   # Welford: count, mean, M2 per key
    batch_u = []
    h = 0
    converged = False
    history = []
    while True:
        ys = batch_fn(batch, rng)
        h += 1
        for key, y in ys.items():
            n_b = y.shape[0]
            mean_b = y.mean(axis=0)
            m2_b = ((y - mean_b) ** 2).sum(axis=0)
            if key not in acc:
                acc[key] = [n_b, mean_b, m2_b]
            else:
                n_a, mean_a, m2_a = acc[key]
                n = n_a + n_b
                dm = mean_b - mean_a
                acc[key] = [n, mean_a + dm * n_b / n, m2_a + m2_b + dm**2 * n_a * n_b / n]
        batch_u.append(np.std(ys["total"], axis=0, ddof=1))
        n_tot, _, m2 = acc["total"]
        u = np.sqrt(m2 / (n_tot - 1))
        tol = numerical_tolerance(u, n_dig)
        s_u = (np.std(np.array(batch_u), axis=0, ddof=1) / math.sqrt(h)) if h >= 2 else np.full_like(u, np.inf)
        history.append((h * batch, time.perf_counter() - t0))
        if progress is not None:
            progress(h * batch, max_draws)
        if h >= 2 and np.all(2.0 * s_u <= tol):
            converged = True
            break
        if (h + 1) * batch > max_draws:
            break
    comps = {k: np.sqrt(v[2] / (v[0] - 1)) for k, v in acc.items() if k != "total"}
    return MCResult(names=list(names), u=u, components=comps, draws=h * batch, batches=h,
                    seconds=time.perf_counter() - t0, converged=converged, s_u=s_u, tolerance=tol,
                    n_dig=n_dig, history=history)


# ---------------------------------------------------------------------------------------------
# measurands: distances, fitted elements
# ---------------------------------------------------------------------------------------------

def _sub_batches(M: int, m: int, budget: int = 4_000_000) -> list[int]:
    """Split M draws so that one sub-batch holds about ``budget`` coordinates per factor."""
    step = max(1, budget // max(3 * m, 1))
    return [min(step, M - s) for s in range(0, M, step)]


def distances(cloud: pc.PointCloud, params: pc.Parameters, pairs, *, components: bool = True,
              n_dig: int = 2, batch: int = 10_000, max_draws: int = 10_000_000,
              rng: np.random.Generator | None = None, sampler: PointCloudSampler | None = None,
              progress=None) -> MCResult:
    """Monte Carlo u (µm) of the distances d_ij = ||x_j - x_i|| for ``pairs``: every draw moves
    the points by the drawn influence factors and the distance is evaluated exactly."""
    pairs = pc.check_pairs(cloud, pairs)
    i, j = pairs[:, 0], pairs[:, 1]
    a = cloud.X_mm[j] - cloud.X_mm[i]
    na = np.linalg.norm(a, axis=1)
    sampler = sampler or PointCloudSampler(cloud, params)

    def delta_d_um(dlt):   # exact change of the distance, µm, without cancellation
        b = (dlt[:, j, :] - dlt[:, i, :]) * MILLI
        ab = a[None] + b
        return (2.0 * np.einsum("pk,mpk->mp", a, b) + np.einsum("mpk,mpk->mp", b, b)) / \
            (np.linalg.norm(ab, axis=2) + na[None]) / MILLI

    def batch_fn(M, g):
        out: dict[str, list] = {"total": []}
        for Mb in _sub_batches(M, cloud.m):
            drawn = sampler.draw(Mb, g)
            out["total"].append(delta_d_um(sum(drawn.values())))
            if components:
                for f, dl in drawn.items():
                    out.setdefault(f, []).append(delta_d_um(dl))
        return {k: np.concatenate(v) for k, v in out.items()}

    names = [f"{cloud.labels[p]}-{cloud.labels[q]}" for p, q in pairs]
    return adaptive(batch_fn, names, n_dig=n_dig, batch=batch, max_draws=max_draws, rng=rng,
                    progress=progress)


FIT_KINDS = ("plane", "sphere", "cylinder", "line", "circle")


def refit_batch(fit, X_mm: np.ndarray, *, max_iter: int = 20) -> np.ndarray:
    """Refit ``fit``'s element to a batch of perturbed point sets X_mm (B, m, 3) by Gauss-Newton
    from the reference solution; return the paper's local parameters of each refitted element
    in the reference solution frame (B, n): for the reference points they are the fit's
    ``local_values`` and their changes are what G_A|X describes to first order."""
    from .features import local_model, rot_xy_batch

    kind = fit.kind
    if kind not in FIT_KINDS:
        raise ModelError(f"the Monte Carlo refit handles {', '.join(FIT_KINDS)}, not {kind}")
    B = X_mm.shape[0]
    o = np.broadcast_to(fit.origin_mm, (B, 3)).copy()
    R = np.broadcast_to(fit.R, (B, 3, 3)).copy()
    r = np.full(B, fit.shape[0]) if fit.shape else np.zeros(B)
    wr = np.repeat(fit.weights, fit.k)
    scale = float(np.max(np.ptp(fit.X_mm, axis=0)))
    for _ in range(max_iter):
        P = np.einsum("bmi,bij->bmj", X_mm - o[:, None, :], R)
        d, J, _ = local_model(kind, P, (r[:, None],) if fit.shape else ())
        d = d.reshape(B, -1) * wr
        J = J.reshape(B, d.shape[1], -1) * wr[None, :, None]
        H = np.einsum("bki,bkj->bij", J, J)
        g = np.einsum("bki,bk->bi", J, d)
        step = -np.linalg.solve(H, g[..., None])[..., 0]
        if kind == "sphere":
            o = o + step[:, :3]
            r = r + step[:, 3]
        elif kind == "plane":
            o = o + R[:, :, 2] * step[:, :1]
            R = R @ rot_xy_batch(step[:, 1], step[:, 2])
        elif kind == "circle":   # in a coordinate plane: x0, y0, r0
            o = o + np.einsum("bij,bj->bi", R[:, :, :2], step[:, :2])
            r = r + step[:, 2]
        elif kind == "line":
            o = o + np.einsum("bij,bj->bi", R[:, :, :2], step[:, :2])
            R = R @ rot_xy_batch(step[:, 2], step[:, 3])
        else:  # cylinder
            o = o + np.einsum("bij,bj->bi", R[:, :, :2], step[:, :2])
            R = R @ rot_xy_batch(step[:, 2], step[:, 3])
            r = r + step[:, 4]
        if np.max(np.abs(step)) <= 1e-14 * scale:
            break
    # the refitted element in the reference frame
    if kind == "sphere":
        return np.column_stack([o, r])
    if kind == "circle":
        return np.column_stack([(o @ fit.R)[:, :2], r])
    q = np.einsum("bi,ij->bj", o - fit.origin_mm, fit.R)     # a point of the element, ref. frame
    v = np.einsum("bi,ij->bj", R[:, :, 2], fit.R)             # its axis / normal, ref. frame
    v = v * np.sign(v[:, 2:3])
    rot_x = -np.arcsin(v[:, 1])
    rot_y = np.arctan2(v[:, 0], v[:, 2])
    if kind == "plane":
        z_A = np.einsum("bi,bi->b", v, q) / v[:, 2]
        return np.column_stack([z_A, rot_x, rot_y])
    t = q[:, 2] / v[:, 2]
    xy = q[:, :2] - t[:, None] * v[:, :2]
    if kind == "line":
        return np.column_stack([xy, rot_x, rot_y])
    return np.column_stack([xy, rot_x, rot_y, r])


def feature(fit, cloud: pc.PointCloud, params: pc.Parameters, *, components: bool = False,
            n_dig: int = 2, batch: int = 10_000, max_draws: int = 10_000_000,
            rng: np.random.Generator | None = None, sampler: PointCloudSampler | None = None,
            progress=None) -> MCResult:
    """Monte Carlo u of the local parameters (``fit.local_names``; mm, rad) of a least-squares
    element refitted to every draw of the perturbed points (``FIT_KINDS``)."""
    if fit.kind not in FIT_KINDS:
        raise ModelError(f"the Monte Carlo refit handles {', '.join(FIT_KINDS)}, not {fit.kind}")
    if cloud.m != fit.m:
        raise ModelError(f"the fit has {fit.m} points, the point cloud {cloud.m}")
    sampler = sampler or PointCloudSampler(cloud, params)
    ref = refit_batch(fit, fit.X_mm[None])[0]

    def params_of(dlt):
        return refit_batch(fit, fit.X_mm[None] + dlt * MILLI) - ref

    def batch_fn(M, g):
        out: dict[str, list] = {"total": []}
        for Mb in _sub_batches(M, cloud.m, 1_000_000):
            drawn = sampler.draw(Mb, g)
            out["total"].append(params_of(sum(drawn.values())))
            if components:
                for f, dl in drawn.items():
                    out.setdefault(f, []).append(params_of(dl))
        return {k: np.concatenate(v) for k, v in out.items()}

    return adaptive(batch_fn, list(fit.local_names), n_dig=n_dig, batch=batch, max_draws=max_draws,
                    rng=rng, progress=progress)
