"""What a hyper-parameter fit of ``cmmwb calibrate`` (:func:`xlfuncs.calibrate.calibrate`) gives
the user to check it by: the records' standardized GLS residuals, the REML likelihood profile of
each estimate, the fitted model against E_L,MPE (Forbes 2025 eq. 36, u(d) of eq. 33), and the GLS
estimates of the fixed effects with the chi-square of the records against a model.

numpy only.
"""

from __future__ import annotations

import math

import numpy as np

from . import calibrate as cb
from . import pointcloud as pc
from .calibrate import Calibration
from .errors import ModelError
from .reml import NAMES, UNIT, RecordSet, bounds, maximize, reml_terms, values_from_log


def standardized_residuals(s: RecordSet, params: pc.Parameters) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """GLS residual e = r - X beta (µm), its standard uncertainty sqrt(diag(C - X cov(beta) X^T))
    and z = e/u, with C the fitted model's covariance."""
    if getattr(s.op, "structured", False):
        return s.op.standardized_residuals(params, s.y, s.Q)
    values = {n: float(getattr(params, n)) for n in NAMES}
    C, _ = s.op.evaluate(values, [])
    L = np.linalg.cholesky(C)
    Li = np.linalg.inv(L)
    Ci = Li.T @ Li
    Q = s.Q
    if Q.shape[1]:
        M = Q.T @ Ci @ Q
        covb = np.linalg.inv(M)
        b = covb @ (Q.T @ Ci @ s.y)
        e = s.y - Q @ b
        var = np.diag(C) - np.einsum("ij,jk,ik->i", Q, covb, Q)
    else:
        e, var = s.y.copy(), np.diag(C).copy()
    u = np.sqrt(np.maximum(var, 1e-30))
    return e, u, e / u


def profile(cal: Calibration, name: str, points: int = 9, width: float = 3.0) -> dict:
    """The REML log-likelihood profile of one estimated hyper-parameter: on a grid of its log over
    +- ``width`` u, the others re-optimized (warm start); returns value, loglik - max."""
    grid, lls, _ = _profile_points(cal, name, points, width)
    return {"name": name, "unit": UNIT[name], "value": np.exp(grid).tolist(),
            "delta_loglik": (np.array(lls) - cal.loglik).tolist()}


def _profile_points(cal: Calibration, name: str, points: int = 9, width: float = 3.0
                    ) -> tuple[np.ndarray, list[float], list[dict[str, float]]]:
    """The grid of :func:`profile` in log, the log-likelihood at every point and the estimated
    hyper-parameters there (the others re-optimized)."""
    if name not in cal.free:
        raise ModelError(f"{name} was not estimated")
    k = cal.free.index(name)
    centre = math.log(cal.estimates[name].value)
    u = math.sqrt(cal.cov_log[k, k])
    others = [n for n in cal.free if n != name]
    base = {n: float(getattr(cal.params, n)) for n in NAMES}
    grid = centre + np.linspace(-width, width, points) * u
    out, at = [], []
    for x in grid:
        v = dict(base)
        v[name] = math.exp(x)
        if others:
            box = bounds(cal.sets, v, others)
            box.lo = np.minimum(box.lo, np.log([v[n] for n in others]) - 3)
            phi, t, _ = maximize(cal.sets, v, others, box, max_iter=20, tol=1e-5)
            ll = t.loglik
            v = values_from_log(v, others, phi)
        else:
            ll = reml_terms(cal.sets, v, [], fisher=False).loglik
        out.append(ll)
        at.append({n: v[n] for n in cal.free})
    return grid, out, at


def profiles_at_maximum(cal: Calibration, rounds: int = 3) -> tuple[Calibration, list[dict]]:
    """The profiles of every estimated hyper-parameter (:func:`profile`), and the fit moved to a
    higher peak where a profile reaches one: a profile point more likely than the fit by
    :data:`xlfuncs.calibrate.PEAK_GAIN` shows that the fit stopped on a lower peak of the
    likelihood; the fit is repeated from that point (:func:`xlfuncs.calibrate.calibrate` with
    ``warm``, the peaks found so far kept) and the profiles computed again about the new maximum
    (at most ``rounds`` times).  Returns the calibration and its profiles."""
    profs: list[dict] = []
    for _ in range(rounds):
        best = (cal.loglik + cb.PEAK_GAIN, None, "")
        profs = []
        for name in cal.free:
            grid, lls, at = _profile_points(cal, name)
            profs.append({"name": name, "unit": UNIT[name], "value": np.exp(grid).tolist(),
                          "delta_loglik": (np.array(lls) - cal.loglik).tolist()})
            j = int(np.argmax(lls))
            if lls[j] > best[0]:
                best = (lls[j], at[j], f"the profile of {name} at {math.exp(grid[j]):.4g} {UNIT[name]}")
        if best[1] is None:
            return cal, profs
        higher = cb.calibrate(cal.sets, cal.start, fixed=cal.fixed, u_log_max=cal.u_log_max, warm=best[1],
                              found_by=best[2], known=cal.peaks)
        if higher.loglik <= cal.loglik + cb.PEAK_GAIN:
            return cal, profs
        cal = higher
    return cal, [profile(cal, n) for n in cal.free]


def mpe_consistency(params: pc.Parameters, A_um: float, B_mm: float, K: float, P_mm: float,
                    L_max_mm: float, cal: Calibration | None = None, n_grid: int = 201,
                    held: frozenset[str] | set[str] = frozenset()) -> dict:
    """E_L,MPE = A + L/B against the fitted model's C(d) = K u(d)/(A + d/B) (Forbes 2025 eq. 36,
    u(d) of eq. 33): C_max, where, the margin 1 - C_max and, with ``cal``, u(C_max) from the
    covariance of the estimates (delta method in log) over the estimated parameters not in
    ``held`` (those the feedback replaced: their values are no longer the estimates, and their own
    uncertainty is not part of u(C_max))."""
    chk = pc.mpe_check(params, A_um, B_mm, K, P_mm, L_max_mm, n_grid)
    d = L_max_mm * np.arange(n_grid) / (n_grid - 1)
    c = pc.C_of_d(d, params, A_um, B_mm, K, P_mm)
    u_c = None
    free = [n for n in cal.free if n not in held] if cal is not None else []
    if cal is not None and free:
        keep = [cal.free.index(n) for n in free]
        cov_log = cal.cov_log[np.ix_(keep, keep)]
        g = np.zeros(len(free))
        h = 1e-5
        for a, name in enumerate(free):
            vals = {n: float(getattr(params, n)) for n in NAMES}
            hi, lo = dict(vals), dict(vals)
            hi[name] *= math.exp(h)
            lo[name] *= math.exp(-h)
            g[a] = (pc.C_of_d(chk.d_at_max_mm, pc.Parameters(**hi), A_um, B_mm, K, P_mm)
                    - pc.C_of_d(chk.d_at_max_mm, pc.Parameters(**lo), A_um, B_mm, K, P_mm)) / (2 * h)
        u_c = float(math.sqrt(max(g @ cov_log @ g, 0.0)))
    return {"A_um": A_um, "B_mm": B_mm, "K": K, "P_mm": P_mm, "L_max_mm": L_max_mm,
            "C_max": chk.C_max, "u_C_max": u_c, "d_at_max_mm": chk.d_at_max_mm,
            "margin": 1.0 - chk.C_max, "conforms": chk.conforms,
            "d_mm": d.tolist(), "C": c.tolist()}


def gls_fit(s: RecordSet, params: pc.Parameters, y: np.ndarray | None = None,
            X: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float, int]:
    """GLS of ``y`` (default: the records' residual) on ``X`` (default: the set's fixed effects)
    with the covariance of ``params``: (beta, cov(beta), chi2, dof).  The fixed-effect estimates
    at the fitted hyper-parameters and the chi-square of the records against a model."""
    y = s.y if y is None else y
    X = s.X if X is None else X
    if getattr(s.op, "structured", False):
        return s.op.gls_fit(params, y, X)
    values = {n: float(getattr(params, n)) for n in NAMES}
    C, _ = s.op.evaluate(values, [])
    Li = np.linalg.inv(np.linalg.cholesky(C))
    yw, Xw = Li @ y, Li @ X
    if X.shape[1]:
        Qw, R = np.linalg.qr(Xw)
        keep = np.abs(np.diag(R)) > 1e-10 * max(np.max(np.abs(np.diag(R))), 1e-300)
        beta = np.zeros(X.shape[1])
        cov = np.zeros((X.shape[1], X.shape[1]))
        Xk = Xw[:, keep]
        G = Xk.T @ Xk
        covk = np.linalg.inv(G)
        bk = covk @ (Xk.T @ yw)
        beta[keep] = bk
        cov[np.ix_(keep, keep)] = covk
        e = yw - Xk @ bk
        p = int(keep.sum())
    else:
        beta, cov, e, p = np.zeros(0), np.zeros((0, 0)), yw, 0
    return beta, cov, float(e @ e), len(y) - p
