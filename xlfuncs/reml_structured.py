"""The REML likelihood of :mod:`xlfuncs.reml` on the structured record covariance of ``diagnose``,
C = D + U U^T (:mod:`xlfuncs.locator.structured_lengths` for length records,
:mod:`xlfuncs.locator.structured` for point records), never forming an n x n matrix.

Every derivative of C in phi = log(hyper-parameter) has the same structure.  Let Z = [U, E, Q]
(n x K): U the operator's columns, E the columns of the length-scale derivatives (below), Q the
orthonormal basis of the fixed effects.  Then

    dC/dphi_k = c_k D + Z S_k Z^T

with c_k = 2 for sigma_R (D = sigma_R^2 x (probings of its own)) and 0 otherwise, and S_k a
small K x K matrix: for a standard deviation 2 on the diagonal of its factor's columns (each
column of U belongs to one standard deviation: R shared probings, PQ, the seven V_B entries of
S (eq. 13), ET, ER, P0, P); for a length scale the derivative of the Nyström factor of
:mod:`xlfuncs.lowrank` at its pivots P,

    K ~ L L^T, l_i = C_P^-1 k_P(z_i):   d(l_i^T l_j)/dlog lambda = l'_i^T l_j + l_i^T l'_j - l_i^T N l_j,
    l'_i = C_P^-1 k'_P(z_i),  N = C_P^-1 K'_PP C_P^-T,  k' = (2 d^2 / lambda^2) exp(-d^2 / lambda^2),

so E_f holds the factor's columns with l' in place of l and S_k = [[-N (x) I, I], [I, 0]] on
(U_f, E_f).  With the Woodbury identity (A = I + U^T D^-1 U, M = Q^T C^-1 Q) the REML projector is

    P = D^-1 - D^-1 Z H Z^T D^-1,   H = J_U A^-1 J_U^T + W M^-1 W^T,  W = [-A^-1 G_UQ; 0; I],

and one pass over the records in blocks gives G = Z^T D^-1 Z, b = Z^T D^-1 y and y^T D^-1 y, from
which (Phi = Z^T P Z = G - G H G, Psi = Z^T P D P Z = R^T G R, R = I - H G, u = Z^T P y):

    log|C| = sum log D + log|A|,   y^T P y = y^T D^-1 y - b^T H b,
    tr(P dC_k) = c_k (n - tr(H G)) + tr(S_k Phi),
    (Py)^T dC_k (Py) = c_k (y^T D^-1 y - 2 b^T H b + b^T H G H b) + u^T S_k u,
    tr(P dC_k P dC_l) = c_k c_l (n - 2 tr(HG) + tr(HGHG)) + c_k tr(S_l Psi) + c_l tr(S_k Psi)
                        + tr(S_k Phi S_l Phi),

the gradient -1/2 tr(P dC_k) + 1/2 (Py)^T dC_k (Py) and the expected information 1/2 tr(P dC_k P dC_l)
of :mod:`xlfuncs.reml` in time O(n K^2) and memory O(block K + K^2).

Approximation.  The GP factors (ET, ER, P) are the controlled Nyström factors of ``diagnose``
(pivot tolerance :data:`xlfuncs.lowrank.PIVOT_TOL`, pivots chosen afresh at every lambda): C is
exact to ||C - C_lowrank||_2 <= eps_C (the operator's own bound, :attr:`StructuredRecordCovariance.eps_C`
at the last evaluation); the gradient is the derivative of the low-rank C at the pivots chosen
(the pivots are piecewise constant in lambda).  At PIVOT_TOL = 1e-12 the log-likelihood, gradient
and estimates agree with the dense path to relative 1e-8 (``tests/calibration/test_reml_structured.py``).

numpy, scipy only.
"""

from __future__ import annotations

import copy
import math

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.linalg.blas import dsyrk

from . import lowrank as lr
from . import pointcloud as pc
from .errors import ModelError
from .locator.model import Prepared
from .locator.structured import StructuredCovariance
from .locator.structured_lengths import LengthCovariance
from .model import sq_dists
from .model.hyperparameters import GP, S_COLUMNS, SIGMAS

#: records (length) or points per block of the pass over U
BLOCK = 2048
# S_COLUMNS: the S columns (eq. 13, V_B diagonal) and the standard deviation each belongs to;
# GP: the GP factors (standard deviation, length scale, factor); both from the records
# (xlfuncs.model.hyperparameters)


class DerivativeFactor:
    """The Nyström factor with its rows differentiated in log lambda at fixed pivots:
    ``rows(Z)`` = l'(z) = C_P^-1 k'_P(z) (same interface as :class:`xlfuncs.lowrank.KernelFactor`)."""

    def __init__(self, fac: lr.KernelFactor):
        self.Zp, self.C, self.inv_lam2 = fac.Zp, fac.C, fac.inv_lam2

    @property
    def rank(self) -> int:
        return len(self.Zp)

    def kernel(self, Zb: np.ndarray) -> np.ndarray:
        q = sq_dists(self.Zp, Zb) * self.inv_lam2
        return 2.0 * q * np.exp(-q)

    def rows(self, Zb: np.ndarray) -> np.ndarray:
        return solve_triangular(self.C, self.kernel(Zb), lower=True, check_finite=False)

    def N(self) -> np.ndarray:
        """C_P^-1 K'_PP C_P^-T (r x r)."""
        X = solve_triangular(self.C, self.kernel(self.Zp), lower=True, check_finite=False)
        X = solve_triangular(self.C, X.T, lower=True, check_finite=False)
        return 0.5 * (X + X.T)


def _params(values: dict[str, float]) -> pc.Parameters:
    v = dict(values)
    for s, lm, _f in GP:
        if v[s] <= 0:
            v[lm] = 0.0
    return pc.Parameters(**v)


class StructuredRecordCovariance:
    """C(theta) of one prepared record set as the structured operator of ``diagnose`` (the same
    interface as :class:`xlfuncs.reml.DenseRecordCovariance`: ``cloud``, ``n``, ``reml``; GLS
    through :meth:`gls_fit` and :meth:`standardized_residuals`, never n x n).  ``ranks``, ``eps_C``
    and ``chi2_bound``: the operator's at the last evaluation (the pivots, the bound
    ||C - C_lowrank||_2 and the first-order relative chi-square bound of ``diagnose``)."""

    structured = True

    def __init__(self, prep: Prepared, cloud: pc.PointCloud, pivot_tol: float = lr.PIVOT_TOL):
        self.prep = prep
        self.cloud = cloud
        self.n = prep.r_um.shape[0]
        self.pivot_tol = pivot_tol
        self.dims = None if prep.ends is not None else (2 if prep.design.dims == 2 else 3)
        self.eps_C = 0.0
        self.ranks: dict = {}
        self.chi2_bound = 0.0
        # records the operator cannot take are refused here (with the reason), not in the fit
        self.operator(_params({n: 0.0 for n in pc.Parameters.__dataclass_fields__} | {"sigma_R_um": 1.0}))

    # -- the operator of diagnose at these values ------------------------------------------------
    def operator(self, params: pc.Parameters):
        if self.prep.ends is not None:
            I, J = self.prep.ends
            return LengthCovariance(self.cloud, params, I, J, pivot_tol=self.pivot_tol)
        return StructuredCovariance(self.cloud, params, self.dims, pivot_tol=self.pivot_tol)

    def _rows(self, op, i0: int, i1: int) -> np.ndarray:
        if isinstance(op, LengthCovariance):
            return op.U_rows(slice(i0, i1))
        return op.U_rows(i0, i1)

    def _D(self, op, r0: int, r1: int) -> np.ndarray:
        if isinstance(op, LengthCovariance):
            return op.D[r0:r1]
        return np.full(r1 - r0, op.d)

    def _blocks(self):
        """(block start, end) in the operator's units (records or points) and its observation rows."""
        m = self.n if self.prep.ends is not None else self.cloud.m
        f = 1 if self.prep.ends is not None else self.dims
        for i0 in range(0, m, BLOCK):
            i1 = min(i0 + BLOCK, m)
            yield i0, i1, f * i0, f * i1

    def _columns(self, op) -> dict[str, np.ndarray]:
        """The columns of U each standard deviation scales (its factor's)."""
        lengths = isinstance(op, LengthCovariance)
        nP = len(self.cloud.probes)
        dims = 3 if lengths else self.dims
        cols: dict[str, list] = {n: [] for n in SIGMAS}
        cols["sigma_PQ_um"] = list(range(nP * dims))
        for j, s in enumerate(S_COLUMNS):
            cols[s].append(op.off_S + j)
        cols["sigma_ET_um"] = list(range(op.off_ET, op.off_ER))
        cols["sigma_ER_urad"] = list(range(op.off_ER, op.off_rad))
        cols["sigma_P0_um"] = list(range(op.off_rad, op.off_rad + nP))
        end_P = op.off_R if lengths else op.k
        cols["sigma_P_um"] = list(range(op.off_rad + nP, end_P))
        if lengths:
            cols["sigma_R_um"] = list(range(op.off_R, op.k))
        return {n: np.asarray(c, dtype=int) for n, c in cols.items()}

    def _gp_factors(self, op) -> dict[str, list]:
        """{factor: [(KernelFactor, first column of U, columns per pivot), ...]} (P: one per probe)."""
        lengths = isinstance(op, LengthCovariance)
        out = {"ET": [], "ER": [], "P": []}
        facs = {k: (v if lengths else v[0]) for k, v in op.facs.items()}
        if "ET" in facs:
            out["ET"].append((facs["ET"], op.off_ET, 3 if lengths else self.dims))
        if "ER" in facs:
            out["ER"].append((facs["ER"], op.off_ER, 3))
        for q, off in op.off_P.items():
            out["P"].append((facs[f"P{q}"], off, 1))
        return out

    def _derivative_rows(self, op, dop, factor: str, i0: int, i1: int, dU: np.ndarray | None) -> np.ndarray:
        """E_f for the block: the factor's columns of U with l' in place of l (``dU``: the rows
        of the derivative operator ``dop`` of this block)."""
        lengths = isinstance(op, LengthCovariance)
        if lengths and factor == "ET":
            fac = dop.facs["ET"]
            ram, I, J = self.cloud.ram_mm, op.I[i0:i1], op.J[i0:i1]
            kd = fac.kernel(ram[J]) - fac.kernel(ram[I])
            dL = solve_triangular(fac.C, kd, lower=True, check_finite=False).T * op.params.sigma_ET_um
            return (dL[:, :, None] * op.na[i0:i1, None, :]).reshape(i1 - i0, -1)
        U = dU
        if factor == "ET":
            return U[:, op.off_ET:op.off_ER]
        if factor == "ER":
            return U[:, op.off_ER:op.off_rad]
        nP = len(self.cloud.probes)
        return U[:, op.off_rad + nP:(op.off_R if lengths else op.k)]

    def _derivative_operator(self, op):
        """A shallow copy of ``op`` whose GP factors give l' (rows of :class:`DerivativeFactor`)."""
        dop = copy.copy(op)
        if isinstance(op, LengthCovariance):
            dop.facs = {k: DerivativeFactor(v) for k, v in op.facs.items()}
        else:
            dop.facs = {k: (DerivativeFactor(v[0]), v[1]) for k, v in op.facs.items()}
        return dop

    def _S(self, op, values, free, gps, e_off):
        """[(J_k, S_k[J_k, J_k])] and c_k of dC/dphi_k = c_k D + Z S_k Z^T (module docstring)."""
        cols = self._columns(op)
        S, c = [], []
        for name in free:
            J, Sk, ck = np.zeros(0, dtype=int), np.zeros((0, 0)), 0.0
            f = next((f for _s, lm, f in GP if lm == name), None)
            if name in cols:
                if values[name] > 0:
                    J = cols[name]
                    Sk = 2.0 * np.eye(len(J))
                if name == "sigma_R_um":
                    ck = 2.0
            elif f is not None and values[next(s_ for s_, lm, _f in GP if lm == name)] > 0 and f in e_off:
                e0, _e1 = e_off[f]
                Js, blocks = [], []
                for fac, off, per in gps[f]:
                    w = fac.rank * per
                    Js += [np.arange(off, off + w), np.arange(e0, e0 + w)]
                    blk = np.zeros((2 * w, 2 * w))
                    blk[:w, :w] = -np.kron(DerivativeFactor(fac).N(), np.eye(per))
                    blk[:w, w:] = blk[w:, :w] = np.eye(w)
                    blocks.append(blk)
                    e0 += w
                J = np.concatenate(Js)
                Sk = np.zeros((len(J), len(J)))
                o = 0
                for blk in blocks:
                    Sk[o:o + len(blk), o:o + len(blk)] = blk
                    o += len(blk)
            c.append(ck)
            S.append((J, Sk))
        return S, c

    # -- the REML terms -----------------------------------------------------------------------
    def reml(self, y: np.ndarray, Q: np.ndarray, values: dict[str, float], free: list[str],
             fisher: bool = True):
        """The REML terms of this record set (module docstring), as
        :meth:`xlfuncs.reml.DenseRecordCovariance.reml`: (loglik, gradient, expected information,
        y^T P y, n - p), which :func:`xlfuncs.reml.reml_terms` takes as its ``RemlTerms``."""
        op = self.operator(_params(values))
        self.eps_C, self.ranks, self.chi2_bound = op.eps_C, dict(op.ranks), op.chi2_bound()
        n, p = len(y), Q.shape[1]
        k = op.k
        gps = self._gp_factors(op)
        lam_free = [(s, lm, f) for s, lm, f in GP if lm in free and values[s] > 0 and gps[f]]
        dop = self._derivative_operator(op) if lam_free else None
        need_dU = any(f != "ET" or self.prep.ends is None for _s, _lm, f in lam_free)
        # column layout of Z: U | E_f ... | Q
        e_off, o = {}, k
        for s, lm, f in lam_free:
            w = sum(fac.rank * c for fac, _off, c in gps[f])
            e_off[f] = (o, o + w)
            o += w
        q0 = o
        K = q0 + p
        G = np.zeros((K, K), order="F")
        b = np.zeros(K)
        yDy = 0.0
        logD = 0.0
        for i0, i1, r0, r1 in self._blocks():
            parts = [self._rows(op, i0, i1)]
            dU = self._rows(dop, i0, i1) if need_dU else None
            for s, lm, f in lam_free:
                parts.append(self._derivative_rows(op, dop, f, i0, i1, dU))
            parts.append(Q[r0:r1])
            Zb = np.concatenate(parts, axis=1)
            Db = self._D(op, r0, r1)
            W = Zb / np.sqrt(Db)[:, None]
            G = dsyrk(1.0, W, beta=1.0, c=G, trans=1, lower=1, overwrite_c=1)    # += W^T W (lower)
            b += Zb.T @ (y[r0:r1] / Db)
            yDy += float(y[r0:r1] @ (y[r0:r1] / Db))
            logD += float(np.sum(np.log(Db)))
        iu = np.triu_indices(K, 1)
        G[iu] = G.T[iu]
        # H is zero outside the columns of U and Q (index set h): every product runs on blocks
        iQ = np.arange(q0, K)
        h = np.concatenate([np.arange(k), iQ])
        cA = cho_factor(np.eye(k) + G[:k, :k], lower=True)
        logdetA = 2.0 * float(np.sum(np.log(np.diag(cA[0]))))
        Hs = np.zeros((k + p, k + p))                      # H[h, h]
        Hs[:k, :k] = cho_solve(cA, np.eye(k))
        if p:
            AiGq = cho_solve(cA, G[:k, iQ])                 # A^-1 G_UQ
            M = G[np.ix_(iQ, iQ)] - G[:k, iQ].T @ AiGq       # Q^T C^-1 Q
            cM = cho_factor(0.5 * (M + M.T), lower=True)
            logdetM = 2.0 * float(np.sum(np.log(np.diag(cM[0]))))
            Wq = np.vstack([-AiGq, np.eye(p)])
            Hs += Wq @ cho_solve(cM, Wq.T)
        else:
            logdetM = 0.0
        Hs = 0.5 * (Hs + Hs.T)
        bh = b[h]
        Hb = Hs @ bh                                        # (H b)[h]
        q = yDy - float(bh @ Hb)
        ll = -0.5 * (logD + logdetA + logdetM + q + (n - p) * math.log(2 * math.pi))
        kf = len(free)
        g = np.zeros(kf)
        F = np.zeros((kf, kf)) if fisher else None
        if not kf:
            return ll, g, F, q, n - p
        S, c = self._S(op, values, free, gps, e_off)
        Jall = np.unique(np.concatenate([J for J, _ in S] + [np.zeros(0, dtype=int)]))
        loc = np.full(K, -1)
        loc[Jall] = np.arange(len(Jall))
        Ghh = G[np.ix_(h, h)]
        GhJ = G[np.ix_(h, Jall)]
        X = Hs @ GhJ                                        # (H G)[h, J]
        Phi = G[np.ix_(Jall, Jall)] - GhJ.T @ X             # (Z^T P Z)[J, J]
        Phi = 0.5 * (Phi + Phi.T)
        u = b[Jall] - GhJ.T @ Hb                            # (Z^T P y)[J]
        HGhh = Hs @ Ghh
        trHG = float(np.trace(HGhh))
        trPD = n - trHG
        yPDPy = yDy - 2.0 * float(bh @ Hb) + float(Hb @ Ghh @ Hb)
        S = [(loc[J], Sk) for J, Sk in S]
        for a, (J, Sk) in enumerate(S):
            g[a] = (-0.5 * (c[a] * trPD + float(np.sum(Sk * Phi[np.ix_(J, J)])))
                    + 0.5 * (c[a] * yPDPy + float(u[J] @ Sk @ u[J])))
        if fisher:
            trPDPD = n - 2.0 * trHG + float(np.sum(HGhh * HGhh.T))
            if any(c):
                # Psi = (Z^T P D P Z)[J, J] = G - G H G - (H G)^T G + (H G)^T G (H G) on J
                GX = GhJ.T @ X
                Psi = G[np.ix_(Jall, Jall)] - GX - GX.T + X.T @ Ghh @ X
                trSPsi = [float(np.sum(Sk * Psi[np.ix_(J, J)])) for J, Sk in S]
            else:
                trSPsi = [0.0] * kf
            for a in range(kf):
                Ja, Sa = S[a]
                for b_ in range(a + 1):
                    Jb, Sb = S[b_]
                    Xa = Sa @ Phi[np.ix_(Ja, Jb)]
                    Yb = Sb @ Phi[np.ix_(Jb, Ja)]
                    F[a, b_] = F[b_, a] = 0.5 * (c[a] * c[b_] * trPDPD + c[a] * trSPsi[b_] + c[b_] * trSPsi[a]
                                                 + float(np.sum(Xa * Yb.T)))
        return ll, g, F, q, n - p

    # -- GLS at given hyper-parameters (what the checks need) ---------------------------------
    def _solve(self, op, B: np.ndarray) -> np.ndarray:
        """C^-1 B (Woodbury through the operator)."""
        if isinstance(op, LengthCovariance):
            return op.solve(B)
        W = op.whitener(np.atleast_2d(B.T).T if B.ndim == 1 else B)
        return W.P if B.ndim > 1 else W.P[:, 0]

    def gls_fit(self, params: pc.Parameters, y: np.ndarray, X: np.ndarray):
        """(beta, cov(beta), chi2, dof) of ``y`` on ``X`` with the covariance of ``params``
        (:func:`xlfuncs.calibration_checks.gls_fit`: columns whose whitened part is below 1e-10 of
        the largest are dropped, in order)."""
        op = self.operator(_params({n: float(getattr(params, n)) for n in pc.Parameters.__dataclass_fields__}))
        B = np.column_stack([y, X])
        CiB = self._solve(op, B)
        Gm = B.T @ CiB
        Gm = 0.5 * (Gm + Gm.T)
        p_all = X.shape[1]
        keep = _independent(Gm[1:, 1:])
        beta = np.zeros(p_all)
        cov = np.zeros((p_all, p_all))
        yCy = float(Gm[0, 0])
        if keep.any():
            Gk = Gm[1:, 1:][np.ix_(keep, keep)]
            covk = np.linalg.inv(Gk)
            bk = covk @ Gm[1:, 0][keep]
            beta[keep] = bk
            cov[np.ix_(keep, keep)] = covk
            chi2 = yCy - float(Gm[1:, 0][keep] @ bk)
        else:
            chi2 = yCy
        return beta, cov, chi2, len(y) - int(keep.sum())

    def standardized_residuals(self, params: pc.Parameters, y: np.ndarray, Q: np.ndarray):
        """GLS residual, its u and z (:func:`xlfuncs.calibration_checks.standardized_residuals`)."""
        op = self.operator(_params({n: float(getattr(params, n)) for n in pc.Parameters.__dataclass_fields__}))
        dC = op.diagonal()
        if Q.shape[1]:
            CiQ = self._solve(op, np.column_stack([Q, y]))
            M = Q.T @ CiQ[:, :-1]
            covb = np.linalg.inv(0.5 * (M + M.T))
            bb = covb @ (Q.T @ CiQ[:, -1])
            e = y - Q @ bb
            var = dC - np.einsum("ij,jk,ik->i", Q, covb, Q)
        else:
            e, var = y.copy(), dC
        u = np.sqrt(np.maximum(var, 1e-30))
        return e, u, e / u


#: a fixed-effect column is dependent on those before it when its part orthogonal to them (in the
#: metric C^-1) is below this share of its norm (the resolution of a Gram matrix, ~ sqrt(eps))
RESOLVED = 1e-7


def _independent(G: np.ndarray) -> np.ndarray:
    """Which columns stay, as in the QR of the whitened columns without pivoting of the dense path:
    |R_jj| > 1e-10 max |R_jj|, R_jj^2 from the Gram matrix by a Cholesky that skips the dependent
    columns (from the Gram matrix R_jj is resolved to about sqrt(eps) ~ 1e-8 of the column's norm: a
    column whose |R_jj| is below RESOLVED of its norm is dropped as dependent)."""
    p = G.shape[0]
    rjj = np.zeros(p)
    L = np.zeros((p, p))
    for j in range(p):
        v = G[j, j] - L[j, :j] @ L[j, :j]
        if v <= RESOLVED ** 2 * G[j, j]:
            continue                      # dependent to the Gram matrix's resolution: dropped
        rjj[j] = math.sqrt(v)
        if rjj[j] > 0:
            L[j + 1:, j] = (G[j + 1:, j] - L[j + 1:, :j] @ L[j, :j]) / rjj[j]
            L[j, j] = rjj[j]
    top = max(float(np.max(rjj)) if p else 0.0, 1e-300)
    return rjj > 1e-10 * top


def check_structure(prep: Prepared) -> None:
    """Refuse (ModelError) records the structured operator cannot take (see
    :func:`xlfuncs.locator.structured_lengths.structure_check`)."""
    if prep.ends is not None:
        from .locator.structured_lengths import structure_check

        why = structure_check(*prep.ends, prep.cloud.m)
        if why:
            raise ModelError(why)
