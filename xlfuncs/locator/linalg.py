"""Whitening with the record covariance, orthogonal projections and generalized least squares
(docs/diagnose.md section 3): W with W C W^T = I, Gram-Schmidt of whitened columns, canonical
correlations between column spaces, GLS estimates and their covariance."""

from __future__ import annotations

import numpy as np

from ..errors import ModelError
from . import effects as fx
from .model import Prepared, group_labels

                            # coordinates (µm in hundreds of mm) that the columns are built from
DEPENDENT = 1e-6            # a column whose projected norm is below this share is dependent


# ---------------------------------------------------------------------------------------------
# whitening and GLS
# ---------------------------------------------------------------------------------------------

class Whitener:
    """W with W C W^T = I on the range of C: C = L L^T (Cholesky, W = L^-1) when C is
    well-conditioned, else the eigen-decomposition restricted to eigenvalues above 1e-10 of the
    largest (rank-deficient C: records that repeat a combination of others)."""

    def __init__(self, C: np.ndarray):
        n = C.shape[0]
        diag = np.diag(C)
        if np.any(diag <= 0):
            raise ModelError("the simulation gives some records zero uncertainty: set sigma_R_um > 0 "
                             "(or other parameters) in [parameters]")
        self.mode = "cholesky"
        try:
            L = np.linalg.cholesky(C)
            if np.min(np.diag(L)) ** 2 < 1e-10 * np.max(diag):
                raise np.linalg.LinAlgError
            self.W = np.linalg.inv(L)
            self.rank = n
            self.L = L
        except np.linalg.LinAlgError:
            self.mode = "eigen"
            lam, V = np.linalg.eigh(C)
            keep = lam > 1e-10 * lam.max()
            self.W = (V[:, keep] / np.sqrt(lam[keep])).T
            self.rank = int(keep.sum())
            self.L = None

    def __call__(self, M: np.ndarray) -> np.ndarray:
        return self.W @ M


def orth(M: np.ndarray, ref_norms: np.ndarray | None = None, tol: float = DEPENDENT):
    """Greedy Gram-Schmidt (twice) of the columns of M: returns (Q, kept column indices).
    A column is dependent when its remainder is below ``tol`` times ``ref_norms`` (default:
    its own norm)."""
    n = M.shape[0]
    Q = np.zeros((n, 0))
    kept = []
    for j in range(M.shape[1]):
        v = M[:, j].copy()
        ref = float(np.linalg.norm(v) if ref_norms is None else ref_norms[j])
        if ref == 0.0:
            continue
        for _ in range(2):
            v -= Q @ (Q.T @ v)
        nv = float(np.linalg.norm(v))
        if nv > tol * ref:
            Q = np.column_stack([Q, v / nv])
            kept.append(j)
    return Q, kept


def project_out(Q: np.ndarray, M: np.ndarray) -> np.ndarray:
    """M with the span of the orthonormal Q projected out."""
    return M - Q @ (Q.T @ M) if Q.shape[1] else M.copy()


def cancorr(Qa: np.ndarray, Qb: np.ndarray) -> float:
    """Largest canonical correlation of two orthonormal column sets."""
    if Qa.shape[1] == 0 or Qb.shape[1] == 0:
        return 0.0
    return float(min(1.0, np.linalg.svd(Qa.T @ Qb, compute_uv=False)[0]))


def psd_chi2(e: np.ndarray, C: np.ndarray) -> tuple[float, int]:
    lam, V = np.linalg.eigh(0.5 * (C + C.T))
    keep = lam > 1e-10 * max(lam.max(), 1e-300)
    w = (V[:, keep].T @ e) / np.sqrt(lam[keep])
    return float(w @ w), int(keep.sum())


def structured_whitener(prep: Prepared, names=None):
    """The Gram whitener of :mod:`xlfuncs.locator.structured` on the residual, the alignment and the
    columns of every applicable candidate (or of ``names``), with the group Grams."""
    parts, where = [prep.r_um[:, None], prep.A], {}
    pos = 1 + prep.A.shape[1]
    for eff in fx.EFFECTS:
        if (names is not None and eff.name not in names) or eff.name in fx.PERIODIC:
            continue            # periodic_*: scanned with the dense covariance only
        try:
            X = fx.columns(prep.design, eff.name).X
        except fx.NotApplicable:
            continue
        parts.append(X)
        where[eff.name] = pos
        pos += X.shape[1]
    B = np.column_stack(parts)
    groups = {}
    if names is None:
        for by, lab in group_labels(prep).items():
            lab_obs = np.array([lab[a] for a in prep.obs_record], dtype=object)
            for g in dict.fromkeys(lab):
                groups[(by, g)] = np.flatnonzero(lab_obs == g)
    W = prep.C.whitener(B, groups)
    W.where = where
    return W


def gls(W: Whitener, X: np.ndarray, r: np.ndarray):
    """GLS estimate, its covariance and the chi-square of the residual."""
    yw = W(r)
    if X.shape[1] == 0:
        return np.zeros(0), np.zeros((0, 0)), float(yw @ yw)
    Xw = W(X)
    Qx, Rx = np.linalg.qr(Xw)
    beta = np.linalg.solve(Rx, Qx.T @ yw)
    Rinv = np.linalg.inv(Rx)
    cov = Rinv @ Rinv.T
    e = yw - Xw @ beta
    return beta, cov, float(e @ e)
