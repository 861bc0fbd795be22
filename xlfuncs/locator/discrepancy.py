"""The ``discrepancy`` candidate of the locator's second edition (docs/recordings.md section 7).

When the named effects (section 4) leave the mismatch unexplained, a smooth displacement field
over the machine volume is the last candidate: delta(u) = sum_j phi_j(u) b_j, with u = x - p the
ram position (Forbes 2025 section 4.3), phi_j the products of Legendre polynomials of the
normalized ram coordinates of total degree 2..K, and b_j a vector (µm) per basis function.  The
linear part (degree <= 1) is left out: it is the rigid alignment, the scale and squareness
effects of the named library.  The sensitivity of the records follows effects.py: a length
record sees n_a . (delta(end 2) - delta(end 1)), a point record coordinate c sees delta_c.

Its hyper-parameter, the degree K in DEGREES, is fitted by the likelihood-ratio test against the
fit with the named effects; the smallest p-value is corrected for the degrees tried (Bonferroni,
the look-elsewhere correction), and the field is chosen when that adjusted p-value is below
alpha.  It is tried only after the named search, on a refit that is not explained, so it is never
chosen before a named effect that explains as well.
"""

from __future__ import annotations

import math
from itertools import combinations_with_replacement

import numpy as np

DEGREES = (2, 3, 4)
MAX_COLUMN_SHARE = 0.5      # the field may use at most this share of the remaining dof
AXES = "xyz"


def _legendre(n: int, t: np.ndarray) -> np.ndarray:
    """Legendre polynomial P_n on [-1, 1] (three-term recurrence)."""
    p0, p1 = np.ones_like(t), t
    if n == 0:
        return p0
    for k in range(1, n):
        p0, p1 = p1, ((2 * k + 1) * t * p1 - k * p0) / (k + 1)
    return p1


class Field:
    """The basis phi_j of a field of degree 2..K over the ram positions seen (normalized to [-1, 1]
    per axis; an axis that does not vary is left out)."""

    def __init__(self, U_all: np.ndarray, K: int):
        lo, hi = U_all.min(axis=0), U_all.max(axis=0)
        self.centre = (lo + hi) / 2.0
        self.half = (hi - lo) / 2.0
        self.vary = [a for a in range(U_all.shape[1]) if self.half[a] > 1e-6]
        self.terms: list[tuple[int, ...]] = []
        for deg in range(2, K + 1):
            self.terms += list(combinations_with_replacement(self.vary, deg))
        self.K = K

    def phi(self, U: np.ndarray) -> np.ndarray:
        """n x n_terms values of the basis at ram positions U (mm)."""
        T = np.zeros_like(U)
        for a in self.vary:
            T[:, a] = (U[:, a] - self.centre[a]) / self.half[a]
        out = np.ones((U.shape[0], len(self.terms)))
        for j, term in enumerate(self.terms):
            for a in set(term):
                out[:, j] *= _legendre(term.count(a), T[:, a])
        return out


def columns(design, obs_record: np.ndarray, obs_axis: np.ndarray, K: int):
    """Sensitivity columns (n_obs x 3 n_terms, µm per µm of b_j) and the Field."""
    if design.kind == "length":
        U_all = np.vstack([design.U1, design.U2])
        F = Field(U_all, K)
        d1, d2 = F.phi(design.U1), F.phi(design.U2)
        cols = [design.na[:, c][:, None] * (d2 - d1) for c in range(3)]
        return np.hstack(cols), F, 3
    dims = design.dims
    F = Field(design.U[:, :dims], K)
    ph = F.phi(design.U[:, :dims])[obs_record]
    cols = [ph * (obs_axis == c)[:, None] for c in range(dims)]
    return np.hstack(cols), F, dims


def fit(prep, W, X_sel: np.ndarray, beta_sel: np.ndarray, alpha: float, chi2_named: float, dof_named: int,
        logsf, gls, f_logsf=None) -> dict | None:
    """Try the field after the named effects; the report of section 7 or None when no degree can
    be fitted.  ``logsf(x, df)`` is the chi-square log survival function, ``gls`` the locator's
    GLS (beta, cov, chi2).  With ``f_logsf(F, d1, d2)`` given (the residuals are uniformly larger
    than declared, section 7 "noise level"), the field is judged by the F-test, the scale of the
    covariance estimated from what remains with the field: structure, not a larger noise."""
    D = prep.design
    tried = []
    for K in DEGREES:
        G, F, ncomp = columns(D, prep.obs_record, prep.obs_axis, K)
        if not F.terms:
            continue
        # keep only the field columns not already spanned by the fit with the named effects
        Gw, Xw = W(G), W(X_sel)
        Qx = np.linalg.qr(Xw)[0] if Xw.shape[1] else np.zeros((Gw.shape[0], 0))
        Z = Gw - Qx @ (Qx.T @ Gw)
        norms = np.linalg.norm(Gw, axis=0)
        _, R, piv = _qr_pivot(Z)
        diag = np.abs(np.diag(R)) if R.size else np.zeros(0)
        keep = [int(piv[i]) for i in range(len(diag))
                if diag[i] > 1e-8 * max(float(np.max(norms)), 1e-300)]
        df = len(keep)
        if df == 0 or df > MAX_COLUMN_SHARE * dof_named:
            continue
        X = np.hstack([X_sel, G[:, keep]])
        beta, cov, chi2 = gls(W, X, prep.r_um)
        dchi = max(chi2_named - chi2, 0.0)
        dof_with = W.rank - X.shape[1]
        if f_logsf is not None:
            logp = f_logsf((dchi / df) / (chi2 / dof_with), df, dof_with) if chi2 > 0 else -math.inf
        else:
            logp = logsf(dchi, df)
        tried.append({"K": K, "df": df, "dchi": dchi, "logp": logp, "chi2": chi2,
                      "beta": beta, "cov": cov, "X": X, "keep": keep, "F": F, "ncomp": ncomp, "G": G})
    if not tried:
        return None
    best = min(tried, key=lambda t: t["logp"])
    logp_adj = min(0.0, best["logp"] + math.log(len(tried)))
    chosen = logp_adj < math.log(alpha)
    dof_after = W.rank - best["X"].shape[1]
    logp_after = logsf(best["chi2"], dof_after) if dof_after > 0 else 0.0
    resid = prep.r_um - best["X"] @ best["beta"]
    out = {"chosen": bool(chosen), "test": "F" if f_logsf is not None else "chi2", "degree": best["K"], "degrees_tried": [t["K"] for t in tried],
           "df": best["df"], "delta_chi2": best["dchi"], "p_value": math.exp(best["logp"]),
           "p_adjusted": math.exp(logp_adj), "log10_p_value": best["logp"] / math.log(10),
           "chi2_after": best["chi2"], "dof_after": dof_after, "p_after": math.exp(logp_after),
           "explained": bool(logp_after >= math.log(alpha)),
           "rms_after_um": float(np.sqrt(np.mean(resid**2)))}
    out.update(_where(prep, best, X_sel, beta_sel))
    return out


def _qr_pivot(Z: np.ndarray):
    """Column-pivoted QR by Gram-Schmidt with reorthogonalization (numpy has no pivoted QR)."""
    Z = Z.copy()
    n, m = Z.shape
    piv = list(range(m))
    R = np.zeros((min(n, m), m))
    Q = np.zeros((n, min(n, m)))
    for i in range(min(n, m)):
        nrm = np.linalg.norm(Z[:, i:], axis=0)
        j = i + int(np.argmax(nrm))
        Z[:, [i, j]] = Z[:, [j, i]]
        R[:, [i, j]] = R[:, [j, i]]
        piv[i], piv[j] = piv[j], piv[i]
        v = Z[:, i]
        r = np.linalg.norm(v)
        R[i, i] = r
        if r == 0.0:
            return Q[:, :i], R[:i, :], piv[:i]
        q = v / r
        Q[:, i] = q
        R[i, i + 1:] = q @ Z[:, i + 1:]
        Z[:, i + 1:] -= np.outer(q, R[i, i + 1:])
    return Q, R, piv


def _where(prep, best: dict, X_sel: np.ndarray, beta_sel: np.ndarray) -> dict:
    """Where the fitted field is large, as the records see it: the change it brings to the fitted
    values of every observation, X b (with the field) - X_sel b_sel (named effects only), in µm;
    the largest, the record and ram position(s) there and the axis (for point records the
    coordinate, for lengths the dominant component of the length's direction), and the share of
    the change per axis.  (The field's own coefficients are not all determined, and partly
    overlap the named columns; the change of the fit is what the records determine.)"""
    D = prep.design
    change = best["X"] @ best["beta"] - X_sel @ beta_sel
    q = int(np.argmax(np.abs(change)))
    a = int(prep.obs_record[q])
    if D.kind == "length":
        c = int(np.argmax(np.abs(D.na[a])))
        at = [[float(v) for v in D.U1[a]], [float(v) for v in D.U2[a]]]
        ax = np.argmax(np.abs(D.na), axis=1)[prep.obs_record]
    else:
        c = int(prep.obs_axis[q])
        at = [[float(v) for v in D.U[a, :best["ncomp"]]]]
        ax = prep.obs_axis
    return {"size_um": float(abs(change[q])), "value_um": float(change[q]),
            "record": prep.rec.ids[a], "axis": AXES[c], "at_ram_mm": at,
            "rms_change_um": float(np.sqrt(np.mean(change**2))),
            "size_by_axis_um": {AXES[k]: float(np.max(np.abs(change[ax == k])))
                                for k in range(best["ncomp"]) if np.any(ax == k)},
            "note": "field over the ram position u = x - p of total degree 2..K (Legendre products), "
                    "its linear part left to the named effects; sizes are the change the field brings "
                    "to the fitted records (a length sees the change of the field along its direction)"}


def sentence(d: dict | None) -> str:
    """One sentence for the summary (empty when the field was not tried)."""
    if not d:
        return ""
    if not d["chosen"]:
        return (f"A smooth discrepancy field over the ram position (degree up to {d['degree']}) does not "
                f"improve the fit significantly (adjusted p = {d['p_adjusted']:.2g}).")
    return (f"No named effect explains the rest; a smooth discrepancy field over the ram position (degree "
            f"{d['degree']}, {d['df']} parameters, adjusted p = {d['p_adjusted']:.2g}) changes the fit most "
            f"along {d['axis']}, by {d['size_um']:.2g} um at record {d['record']}; with it chi2 = "
            f"{d['chi2_after']:.1f} on {d['dof_after']} dof (p = {d['p_after']:.2g}, "
            f"{'explained' if d['explained'] else 'still not explained'}).")
