"""The covariance of point records as a structured operator, C = D + U U^T, never n x n.

For point records the mismatch locator (:mod:`xlfuncs.locator.diagnose`) needs C = V_X of the measured
points (Forbes 2025 eq. 28, restricted to x, y for 2-D data).  Its factors are

====  ===================================================================  =====================
R     D = sigma_R^2 I                                                      eq. (8), diagonal
PQ    per probe q, dims columns  sigma_PQ,k(i) [k(i) = q] e_a               eq. (9)
S     7 columns  G(x_i - p_k(i)) V_B^1/2                                   eqs. (11)-(14)
ET    sigma_ET l_i (x) I: dims r_ET columns                                eq. (21)
ER    sigma_ER l_i (x) G_k(i): 3 r_ER columns                              eqs. (24)-(25)
P     per probe: sigma_P0 n_i (1 column), sigma_P l_i (x) n_i (r_P)        eqs. (26)-(27)
====  ===================================================================  =====================

with l_i the rows of the controlled Nyström factors of :mod:`xlfuncs.lowrank` (kernel
K ~ L L^T, residual R_K positive semidefinite with ||R_K||_2 <= trace(R_K)).  U (n x k) is
generated in row blocks of points and never stored.  One pass accumulates the small core
``I + U^T D^-1 U`` (Woodbury) and ``U^T D^-1 B`` for the columns B the diagnosis needs (residual,
alignment, every candidate effect); from these the Gram matrix ``Gamma = B^T C^-1 B`` and a second
pass ``P = C^-1 B``.  The :class:`GramWhitener` then maps any M in the span of B to coordinates
whose inner products are ``a^T C^-1 b``, so every statistic of the diagnosis (GLS, chi-square,
candidate likelihood ratios, aliasing) is computed exactly as with the dense W = L^-1, to
rounding and to the stated approximation bound of the GP factors:

    ||C - C_lowrank||_2 <= eps_C = sum_f s_f trace(R_K,f) max_i |w_i|^2

and, first order, ``|chi2 - chi2_lowrank| <= chi2 * eps_C / sigma_R^2`` (C >= sigma_R^2 I).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from .. import lowrank as lr
from .. import pointcloud as pc
from ..errors import ModelError
from ..model import G_S, skew
from ..model.hyperparameters import PROBE_OVERRIDES

#: points per block of the passes over U
BLOCK_POINTS = 4096

#: the factor W is not (yet) a block of U: what the structured operators answer a task with it
NO_WORKPIECE = ("the factor W (the workpiece's temperature, [workpiece]) is not in the structured record "
                "covariance of large recordings: use the dense covariance (--exact; diagnose: at most "
                "6,000 point observations by default, calibrate: --covariance dense) or leave [workpiece] "
                "out of the task (or set [workpiece] enabled = false)")


def refuse_workpiece(cloud: pc.PointCloud) -> None:
    """:data:`NO_WORKPIECE` as a ModelError when the cloud carries the factor W, switched on."""
    if cloud.W_on:
        raise ModelError(NO_WORKPIECE)


@dataclass
class StructuredCovariance:
    """C = sigma_R^2 I + U U^T for the point records of ``cloud`` (µm²), ``dims`` coordinates."""

    cloud: pc.PointCloud
    params: pc.Parameters
    dims: int
    pivot_tol: float = lr.PIVOT_TOL
    ranks: dict = field(default_factory=dict)
    eps_C: float = 0.0

    def __post_init__(self):
        p = self.params
        if p.sigma_R_um <= 0:
            raise ModelError("the structured record covariance needs sigma_R_um > 0")
        refuse_workpiece(self.cloud)
        self.d = p.sigma_R_um ** 2
        cloud = self.cloud
        self.pa = pc.probe_arrays(cloud, p)
        self.U_ram = cloud.ram_mm
        self.GR = None
        self.facs = {}
        terms = []
        if p.sigma_ET_um > 0:
            terms.append(("ET", self.U_ram, 1 / p.lambda_ET_mm ** 2, p.sigma_ET_um ** 2, 1.0, None))
        if p.sigma_ER_urad > 0:
            off = cloud.offsets_mm
            w2 = float(np.max(np.sum(off ** 2, axis=1)))      # ||G_k||_2^2 <= |p_k|^2
            terms.append(("ER", self.U_ram, 1 / p.lambda_ER_mm ** 2, (p.sigma_ER_urad * pc.MILLI) ** 2, w2, None))
        k = cloud.probe_index
        sp, lam = self.pa["sigma_P_um"], self.pa["lambda_P"]
        for q in range(len(cloud.probes)):
            idx = np.flatnonzero(k == q)
            if idx.size and sp[idx[0]] > 0:
                terms.append((f"P{q}", cloud.N[idx], 1 / lam[idx[0]] ** 2, sp[idx[0]] ** 2, 1.0, idx))
        for name, Z, il2, s, w2, idx in terms:
            fac, tr = lr.controlled_factor(Z, il2, self.pivot_tol, name=name)
            self.facs[name] = (fac, idx)
            self.ranks[name] = fac.rank
            self.eps_C += s * tr * w2
        # column layout
        nP = len(cloud.probes)
        dims = self.dims
        self.k = nP * dims + 7
        for name, (fac, _idx) in self.facs.items():
            self.k += fac.rank * (dims if name == "ET" else 3 if name == "ER" else 1)
        self.k += nP                                         # P radius columns
        self.n = cloud.m * dims
        # column offsets of the layout of U_rows
        self.off_S = nP * dims
        self.off_ET = self.off_S + 7
        self.off_ER = self.off_ET + (self.facs["ET"][0].rank * dims if "ET" in self.facs else 0)
        self.off_rad = self.off_ER + (self.facs["ER"][0].rank * 3 if "ER" in self.facs else 0)
        self.off_P = {}
        o = self.off_rad + nP
        for q in range(nP):
            if f"P{q}" in self.facs:
                self.off_P[q] = o
                o += self.facs[f"P{q}"][0].rank
        assert o == self.k

    def expansion(self, q: int, a: int, width: int) -> np.ndarray:
        """E with V_full = V_compact E for the rows of probe q, coordinate a (see
        :meth:`compact` with ``er_compact``): identity but for the ER block, I_r (x) G_q[a]."""
        if "ER" not in self.facs:
            return np.eye(width)
        r = self.facs["ER"][0].rank
        off = 1 + 7 + (self.facs["ET"][0].rank if "ET" in self.facs else 0)
        offsets = np.array([pr.offset_mm for pr in self.cloud.probes], dtype=float).reshape(-1, 3)
        GRa = skew(offsets[q])[0][a]
        rest = width - off - 3 * r
        E = np.zeros((width - 2 * r, width))
        E[:off, :off] = np.eye(off)
        E[off:off + r, off:off + 3 * r] = np.kron(np.eye(r), GRa[None, :])
        E[off + r:, off + 3 * r:] = np.eye(rest)
        return E

    def _expand(self, VV, VB, q, a, width):
        """E^T VV E and E^T VB for :meth:`expansion` in O(width^2) (the ER block is
        M (x) g g^T, g = G_q[a])."""
        if "ER" not in self.facs:
            return VV, VB
        r = self.facs["ER"][0].rank
        off = 1 + 7 + (self.facs["ET"][0].rank if "ET" in self.facs else 0)
        offsets = np.array([pr.offset_mm for pr in self.cloud.probes], dtype=float).reshape(-1, 3)
        g = skew(offsets[q])[0][a]
        c_er = np.arange(off, off + r)
        c_ot = np.concatenate([np.arange(off), np.arange(off + r, VV.shape[0])])
        f_er = np.arange(off, off + 3 * r)
        f_ot = np.concatenate([np.arange(off), np.arange(off + 3 * r, width)])
        F = np.empty((width, width))
        F[np.ix_(f_ot, f_ot)] = VV[np.ix_(c_ot, c_ot)]
        X = np.kron(VV[np.ix_(c_ot, c_er)], g[None, :])
        F[np.ix_(f_ot, f_er)] = X
        F[np.ix_(f_er, f_ot)] = X.T
        F[np.ix_(f_er, f_er)] = np.kron(VV[np.ix_(c_er, c_er)], np.outer(g, g))
        FB = np.empty((width, VB.shape[1]))
        FB[f_ot] = VB[c_ot]
        FB[f_er] = np.kron(VB[c_er], g[:, None])
        return F, FB

    def compact(self, i0: int, i1: int, er_compact: bool = False):
        """The rows of U for points i0 .. i1-1 grouped by (probe q, coordinate a), without the
        columns that are zero there: ``(rows, columns, V)`` with U[rows][:, columns] = V and
        U[rows] zero elsewhere (rows local to the block: dims*(i - i0) + a)."""
        p, cloud, dims = self.params, self.cloud, self.dims
        sl = slice(i0, i1)
        kp = cloud.probe_index[sl]
        S = G_S(self.U_ram[sl]) * np.sqrt(pc.V_S_diag_um_per_mm2(p))       # b x 3 x 7
        LET = LER = None
        if "ET" in self.facs:
            LET = self.facs["ET"][0].rows(self.U_ram[sl]).T * p.sigma_ET_um
            cET = np.arange(LET.shape[1]) * dims
        if "ER" in self.facs:
            LER = self.facs["ER"][0].rows(self.U_ram[sl]).T * (p.sigma_ER_urad * pc.MILLI)
        N = cloud.N[sl]
        sPQ, s0, sp = (self.pa[n][sl] for n in PROBE_OVERRIDES[:3])   # sigma_PQ_um, sigma_P0_um, sigma_P_um
        offsets = np.array([pr.offset_mm for pr in cloud.probes], dtype=float).reshape(-1, 3)
        for q in range(len(cloud.probes)):
            here = np.flatnonzero(kp == q)
            if not here.size:
                continue
            GR = skew(offsets[q])[0]
            LP = None
            if q in self.off_P:
                LP = self.facs[f"P{q}"][0].rows(N[here]).T * sp[here][:, None]
            for a in range(dims):
                parts = [sPQ[here][:, None], S[here, a, :]]
                cols = [np.array([q * dims + a]), self.off_S + np.arange(7)]
                if LET is not None:
                    parts.append(LET[here])
                    cols.append(self.off_ET + cET + a)
                if LER is not None and er_compact:
                    parts.append(LER[here])
                    cols.append(self.off_ER + np.arange(3 * LER.shape[1]))
                elif LER is not None:
                    parts.append((LER[here][:, :, None] * GR[a][None, None, :]).reshape(len(here), -1))
                    cols.append(self.off_ER + np.arange(3 * LER.shape[1]))
                parts.append((s0[here] * N[here, a])[:, None])
                cols.append(np.array([self.off_rad + q]))
                if LP is not None:
                    parts.append(LP * N[here, a][:, None])
                    cols.append(self.off_P[q] + np.arange(LP.shape[1]))
                yield here * dims + a, np.concatenate(cols), np.concatenate(parts, axis=1)

    @property
    def shape(self) -> tuple[int, int]:
        """(n, n): the size of the matrix it stands for (never formed)."""
        return (self.n, self.n)

    # -- U in row blocks ---------------------------------------------------------------------
    def U_rows(self, i0: int, i1: int) -> np.ndarray:
        """Rows of U for points i0 .. i1-1 (observations dims*i0 .. dims*i1-1): (b dims) x k."""
        p, cloud, dims = self.params, self.cloud, self.dims
        b = i1 - i0
        sl = slice(i0, i1)
        kp = cloud.probe_index[sl]
        nP = len(cloud.probes)
        parts = []
        # PQ
        s = self.pa["sigma_PQ_um"][sl]
        pq = np.zeros((b, dims, nP, dims))
        for a in range(dims):
            pq[np.arange(b), a, kp, a] = s
        parts.append(pq.reshape(b, dims, -1))
        # S
        parts.append(G_S(self.U_ram[sl])[:, :dims, :] * np.sqrt(pc.V_S_diag_um_per_mm2(p)))
        if "ET" in self.facs:
            L = self.facs["ET"][0].rows(self.U_ram[sl]).T * p.sigma_ET_um       # b x r
            et = np.einsum("il,ab->ialb", L, np.eye(dims))
            parts.append(et.reshape(b, dims, -1))
        if "ER" in self.facs:
            L = self.facs["ER"][0].rows(self.U_ram[sl]).T * (p.sigma_ER_urad * pc.MILLI)
            GR = skew(cloud.offsets_mm[sl])[:, :dims, :]                         # b x dims x 3
            parts.append(np.einsum("il,iac->ialc", L, GR).reshape(b, dims, -1))
        N = cloud.N[sl][:, :dims]
        s0 = self.pa["sigma_P0_um"][sl]
        rad = np.zeros((b, dims, nP))
        rad[np.arange(b), :, kp] = (s0[:, None] * N)
        parts.append(rad)
        sp = self.pa["sigma_P_um"][sl]
        for q in range(nP):
            name = f"P{q}"
            if name not in self.facs:
                continue
            fac, _idx = self.facs[name]
            blk = np.zeros((b, dims, fac.rank))
            here = np.flatnonzero(kp == q)
            if here.size:
                L = fac.rows(cloud.N[i0 + here]).T * sp[here][:, None]          # h x r
                blk[here] = np.einsum("il,ia->ial", L, N[here])
            parts.append(blk)
        U = np.concatenate(parts, axis=2)
        assert U.shape[2] == self.k
        return U.reshape(b * dims, self.k)

    def blocks(self):
        m = self.cloud.m
        for i0 in range(0, m, BLOCK_POINTS):
            i1 = min(i0 + BLOCK_POINTS, m)
            yield i0, i1, self.U_rows(i0, i1)

    # -- what the diagnosis needs ------------------------------------------------------------
    def compact_blocks(self, er_compact: bool = False):
        m = self.cloud.m
        for i0 in range(0, m, BLOCK_POINTS):
            i1 = min(i0 + BLOCK_POINTS, m)
            yield i0, i1, list(self.compact(i0, i1, er_compact))

    def diagonal(self) -> np.ndarray:
        out = np.empty(self.n)
        for i0, i1, parts in self.compact_blocks():
            o = out[self.dims * i0:self.dims * i1]
            for sel, _nz, V in parts:
                o[sel] = self.d + np.einsum("ik,ik->i", V, V)
        return out

    def point_blocks(self) -> np.ndarray:
        """The dims x dims diagonal blocks of C, one per point."""
        dims = self.dims
        out = np.zeros((self.cloud.m, dims, dims))
        for i0, i1, parts in self.compact_blocks():
            for j, (sel_a, nz_a, Va) in enumerate(parts):
                a = sel_a[0] % dims
                pts = i0 + sel_a // dims
                for sel_b, nz_b, Vb in parts[j - a:j - a + dims]:
                    b = sel_b[0] % dims
                    _, ia, ib = np.intersect1d(nz_a, nz_b, assume_unique=True, return_indices=True)
                    out[pts, a, b] = np.einsum("ij,ij->i", Va[:, ia], Vb[:, ib])
        out += self.d * np.eye(dims)
        return out

    def whitener(self, B: np.ndarray, group_rows: dict | None = None) -> "GramWhitener":
        """The whitener on the span of the columns of B (n x c); ``group_rows``: {key: observation
        indices} whose Woodbury Grams are accumulated in the same pass (for group chi-squares)."""
        n, c = B.shape
        d = self.d
        UtU = np.zeros((self.k, self.k))
        UtB = np.zeros((self.k, c))
        gram = {}
        owner = None
        if group_rows:
            keys = list(group_rows)
            owner = {}
            for g in keys:
                gram[g] = [np.zeros((self.k, self.k)), np.zeros((self.k, c)), group_rows[g]]
            for by in dict.fromkeys(g[0] for g in keys):
                lab = np.full(n, -1)
                for j, g in enumerate(keys):
                    if g[0] == by:
                        lab[group_rows[g]] = j
                owner[by] = lab
        # one pass: Grams of the finest partition (cell = the record's label in every grouping,
        # probe q, coordinate a) in the compact columns; groups and the whole are sums of cells
        cell = np.zeros(n, dtype=int)
        if owner:
            _, cell = np.unique(np.stack(list(owner.values())), axis=1, return_inverse=True)
            cell = cell.reshape(-1)
        acc: dict = {}
        for i0, i1, parts in self.compact_blocks(er_compact=True):
            rows = slice(self.dims * i0, self.dims * i1)
            Bb, cb = B[rows], cell[rows]
            for sel, nz, V in parts:
                q, a = int(self.cloud.probe_index[i0 + sel[0] // self.dims]), int(sel[0] % self.dims)
                Bs, lb = Bb[sel], cb[sel]
                for j in np.unique(lb):
                    s2 = np.flatnonzero(lb == j)
                    V2 = V[s2] if s2.size < len(sel) else V
                    _acc(acc, (int(j), q, a), V2, Bs[s2], nz)
        sums: dict = {}
        first_obs = {}
        if owner:
            u, idx = np.unique(cell, return_index=True)
            first_obs = dict(zip(u.tolist(), idx.tolist()))
        for (j, q, a), (VV, VB, nz) in acc.items():
            targets = [None]
            if owner:
                obs = first_obs[j]
                targets += [keys[lab[obs]] for lab in owner.values() if lab[obs] >= 0]
            for t in targets:
                _acc(sums, (t, q, a), None, None, nz, VV, VB)
        for (g, q, a), (VV, VB, nz) in sums.items():
            full_VV, full_VB = self._expand(VV, VB, q, a, len(nz))
            tgt = (UtU, UtB) if g is None else gram[g][:2]
            tgt[0][np.ix_(nz, nz)] += full_VV
            tgt[1][nz] += full_VB
        UtU /= d
        UtB /= d
        cap = cho_factor(np.eye(self.k) + UtU, lower=True)
        Z = cho_solve(cap, UtB)                                  # (I + U^T D^-1 U)^-1 U^T D^-1 B
        Gamma = B.T @ B / d - UtB.T @ Z
        P = B / d
        for i0, i1, parts in self.compact_blocks():
            Pr = P[self.dims * i0:self.dims * i1]
            for sel, nz, V in parts:
                Pr[sel] -= (V @ Z[nz]) / d
        groups = {g: (a / d, b_ / d, idx) for g, (a, b_, idx) in gram.items()}
        return GramWhitener(0.5 * (Gamma + Gamma.T), P, n, B, d, groups)

    def chi2_bound(self) -> float:
        """First-order relative bound of chi-square from the low-rank GP factors, eps_C/sigma_R^2."""
        return self.eps_C / self.d


def _acc(acc, key, V, B, nz, VV=None, VB=None):
    if VV is None:
        VV, VB = V.T @ V, V.T @ B
    if key in acc:
        acc[key][0] += VV
        acc[key][1] += VB
    else:
        acc[key] = [VV.copy(), VB.copy(), nz]


class GramWhitener:
    """W with (W a)^T (W b) = a^T C^-1 b for a, b in the span of the columns B it was built on
    (:meth:`StructuredCovariance.whitener`): coordinates Lambda^-1/2 V^T S P^T M, with
    S Gamma S = V Lambda V^T (S: column scaling), P = C^-1 B.  ``d``: the diagonal part D of
    C = D + U U^T, a number (point records) or one value per observation (length records,
    :mod:`xlfuncs.locator.structured_lengths`)."""

    mode = "structured"
    L = None

    def __init__(self, Gamma, P, n, B, d, groups):
        g = np.sqrt(np.clip(np.diag(Gamma), 0, None))
        s = np.where(g > 0, 1.0 / np.where(g > 0, g, 1.0), 0.0)
        lam, V = np.linalg.eigh(Gamma * np.outer(s, s))
        keep = lam > 1e-15 * max(lam.max(), 1e-300)
        self._T = (V[:, keep] / np.sqrt(lam[keep])).T * s        # c' x c
        self.P = P
        self.rank = n
        self.B = B
        self.d = d
        self.groups = groups

    def __call__(self, M: np.ndarray) -> np.ndarray:
        M = np.asarray(M, dtype=float)
        return self._T @ (self.P.T @ M)

    def group_chi2(self, key, e_coef: np.ndarray, cov0: np.ndarray, A_coef: np.ndarray) -> float:
        """e_g^T (C_gg - A_g cov0 A_g^T)^-1 e_g for the group ``key``, with e = B e_coef and
        A = B A_coef (generalized Woodbury; the group is a strict subset of the records)."""
        UtU, UtB, idx = self.groups[key]
        Bg = self.B[idx]
        dg = self.d if np.ndim(self.d) == 0 else self.d[idx]      # D: scalar or diagonal
        e = Bg @ e_coef
        k = UtU.shape[0]
        Ag = Bg @ A_coef
        p0 = Ag.shape[1]
        Ut_e = UtB @ e_coef                                   # U_g^T D^-1 e_g
        Ut_A = UtB @ A_coef
        # M_g = D + [U, A] diag(I, -cov0) [U, A]^T
        core = np.zeros((k + p0, k + p0))
        core[:k, :k] = np.eye(k) + UtU
        if p0:
            core[:k, k:] = Ut_A
            core[k:, :k] = Ut_A.T
            core[k:, k:] = Ag.T @ (Ag / np.reshape(dg, (-1, 1))) - np.linalg.inv(cov0)
        rhs = np.concatenate([Ut_e, Ag.T @ (e / dg)]) if p0 else Ut_e
        # without alignment columns the core I + U_g^T D_g^-1 U_g is positive definite: Cholesky
        sol = cho_solve(cho_factor(core, lower=True), rhs) if not p0 else np.linalg.solve(core, rhs)
        return float(e @ (e / dg) - rhs @ sol)
