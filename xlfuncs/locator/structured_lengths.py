"""The covariance of length records as a structured operator, C = D + U U^T, never n x n.

A length record d_a = ||x_J[a] - x_I[a]|| of two probings has the sensitivity g_a = -n_a at its
first and +n_a at its second probing, so Cov(d_a, d_b) = g_a^T V_X g_b (Forbes 2025 eqs. 28-29;
:func:`xlfuncs.locator.model.length_covariance` forms the same matrix densely).  Each factor of
V_X is diagonal or low rank in the coordinates, and G = [g_a] maps that structure to the records:

=========  ===============================================================  ====================
R          a probing used by one record only: sigma_R^2 on D (diagonal);     eq. (8)
           a probing shared by several records (the first face of a step
           gauge): 3 columns sigma_R g_a restricted to it
PQ         per probe q, 3 columns  sum_ends sign sigma_PQ,q [k = q] n_a        eq. (9)
S          7 columns  g7_a V_B^1/2 (ram positions)                             eqs. (11)-(14)
ET         sigma_ET (l_J - l_I) (x) n_a: 3 r_ET columns                        eq. (21)
ER         sigma_ER (l_J (x) n_a x p_J - l_I (x) n_a x p_I): 3 r_ER columns    eqs. (24)-(25)
P          per probe: sigma_P0 o (1 column), sigma_P l(N) o (r_P), o = n_a.N   eqs. (26)-(27)
=========  ===============================================================  ====================

with l the rows of the controlled Nyström factors of :mod:`xlfuncs.lowrank` (the same factors
as the point records of :mod:`xlfuncs.locator.structured`).  D > 0 needs every record to have at least
one probing of its own; records whose two probings are both shared are refused (dense path).

Error bound.  The neglected kernel part R_K of a GP factor is positive semidefinite with
||R_K||_2 <= trace(R_K); for a record vector a, a^T Delta_f a <= s_f ||R_K|| a^T H H^T a with
H the rows w_a (n_a, n_a x p or n_a.N) at the two ends, and ||H H^T||_2 <= 2 c_max max |w|^2
(row sums; c_max the most records sharing one probing), so

    ||C - C_lowrank||_2 <= eps_C = 2 c_max sum_f s_f trace(R_K,f) max |w_f|^2,

and since C >= D >= min(D) I, |chi2 - chi2_lowrank| <= chi2 eps_C / min(D) to first order.

The operator is public for other users of the record covariance (REML calibration):
:meth:`LengthCovariance.matvec` (C v), :meth:`solve` (C^-1 v, Woodbury),
:meth:`logdet` (log det C = log det D + log det(I + U^T D^-1 U)), :meth:`diagonal`,
:meth:`dense` (small n, tests), and :meth:`whitener` for the mismatch locator.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.linalg.blas import dsyrk

from .. import lowrank as lr
from .. import pointcloud as pc
from ..errors import ModelError
from ..execution import ThreadBackend
from ..memory import ResourceError, available_bytes
from ..model import scale_rows
from .structured import GramWhitener, refuse_workpiece

#: records per block of the passes over U
BLOCK_RECORDS = 4096
#: records per task of the passes (a task's result is k x k: few tasks, streamed in order)
TASK_RECORDS = 8 * BLOCK_RECORDS
#: most columns of U (k); beyond, the structured path is refused with what fits
MAX_COLUMNS = 4000


def probing_usage(I: np.ndarray, J: np.ndarray, m: int) -> np.ndarray:
    """How many records use each of the m probings."""
    return np.bincount(I, minlength=m) + np.bincount(J, minlength=m)


def structure_check(I: np.ndarray, J: np.ndarray, m: int) -> str | None:
    """None when the structured operator applies to records with ends I, J, else why not."""
    use = probing_usage(I, J, m)
    both = np.flatnonzero((use[I] > 1) & (use[J] > 1))
    if both.size:
        return (f"{both.size:,} records have both probings shared with other records (no probing of "
                "their own): the structured length covariance needs one per record")
    shared = int(np.count_nonzero(use > 1))
    if 3 * shared > MAX_COLUMNS // 2:
        return (f"{shared:,} probings are shared by several records (3 columns each; at most "
                f"{MAX_COLUMNS // 6:,} fit the structured length covariance)")
    return None


@dataclass
class LengthCovariance:
    """C = D + U U^T (µm²) of the lengths between the unique probings I[a], J[a] of ``cloud``."""

    cloud: pc.PointCloud
    params: pc.Parameters
    I: np.ndarray
    J: np.ndarray
    pivot_tol: float = lr.PIVOT_TOL
    ranks: dict = field(default_factory=dict)
    eps_C: float = 0.0
    #: where :meth:`whitener` runs its passes (None: local threads; a Dask backend)
    backend: object = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        p, cloud = self.params, self.cloud
        if p.sigma_R_um <= 0:
            raise ModelError("the structured record covariance needs sigma_R_um > 0")
        refuse_workpiece(cloud)
        self.I = np.asarray(self.I, dtype=int)
        self.J = np.asarray(self.J, dtype=int)
        why = structure_check(self.I, self.J, cloud.m)
        if why:
            raise ModelError(why)
        n, m = len(self.I), cloud.m
        self.n = n
        X = cloud.X_mm
        d = X[self.J] - X[self.I]
        self.na = d / np.linalg.norm(d, axis=1)[:, None]
        use = probing_usage(self.I, self.J, m)
        self.c_max = int(use.max())
        own = (use[self.I] == 1).astype(float) + (use[self.J] == 1)
        self.D = p.sigma_R_um ** 2 * own
        shared = np.flatnonzero(use > 1)
        self.shared_col = np.full(m, -1)
        self.shared_col[shared] = np.arange(shared.size)
        self.pa = pc.probe_arrays(cloud, p)
        self.nP = len(cloud.probes)
        self.w_S = np.sqrt(pc.V_S_diag_um_per_mm2(p))
        self.facs: dict = {}
        terms = []
        if p.sigma_ET_um > 0:
            terms.append(("ET", cloud.ram_mm, 1 / p.lambda_ET_mm ** 2, p.sigma_ET_um ** 2, 1.0))
        if p.sigma_ER_urad > 0:
            w2 = float(np.max(np.sum(cloud.offsets_mm ** 2, axis=1)))     # |n x p|^2 <= |p|^2
            terms.append(("ER", cloud.ram_mm, 1 / p.lambda_ER_mm ** 2, (p.sigma_ER_urad * pc.MILLI) ** 2, w2))
        k = cloud.probe_index
        sp, lam = self.pa["sigma_P_um"], self.pa["lambda_P"]
        for q in range(self.nP):
            idx = np.flatnonzero(k == q)
            if idx.size and sp[idx[0]] > 0:
                terms.append((f"P{q}", cloud.N[idx], 1 / lam[idx[0]] ** 2, sp[idx[0]] ** 2, 1.0))
        for name, Z, il2, s, w2 in terms:
            fac, tr = lr.controlled_factor(Z, il2, self.pivot_tol, name=name)
            self.facs[name] = fac
            self.ranks[name] = fac.rank
            self.eps_C += 2.0 * self.c_max * s * tr * w2
        # column layout: PQ | S | ET | ER | P radius | P_q GP | R shared
        o = 3 * self.nP
        self.off_S = o
        o += 7
        self.off_ET = o
        o += 3 * self.facs["ET"].rank if "ET" in self.facs else 0
        self.off_ER = o
        o += 3 * self.facs["ER"].rank if "ER" in self.facs else 0
        self.off_rad = o
        o += self.nP
        self.off_P = {}
        for q in range(self.nP):
            if f"P{q}" in self.facs:
                self.off_P[q] = o
                o += self.facs[f"P{q}"].rank
        self.off_R = o
        o += 3 * shared.size
        self.k = o
        if self.k > MAX_COLUMNS:
            raise ModelError(
                f"the structured length covariance would need {self.k:,} columns (ranks "
                + ", ".join(f"{f} {r}" for f, r in self.ranks.items())
                + f"; at most {MAX_COLUMNS:,} fit): the correlation lengths are short against the "
                "extent of the probings; take a section of the recordings, or fewer records with the dense "
                "covariance (diagnose --exact, calibrate --covariance dense)")
        self._core = None

    @property
    def shape(self) -> tuple[int, int]:
        """(n, n): the size of the matrix it stands for (never formed)."""
        return (self.n, self.n)

    def __getstate__(self):
        """What a worker process needs (the backend and the cached core factor stay here)."""
        state = dict(self.__dict__)
        state["backend"] = None
        state["_core"] = None
        state["_diag"] = None
        return state

    # -- U in row blocks ---------------------------------------------------------------------
    def U_rows(self, sel) -> np.ndarray:
        """The rows of U (one per record) of the records ``sel`` (a slice or indices): b x k."""
        p, cloud = self.params, self.cloud
        I, J = self.I[sel], self.J[sel]
        na = self.na[sel]
        b = len(I)
        rows = np.arange(b)
        U = np.zeros((b, self.k))
        kp, ram, N = cloud.probe_index, cloud.ram_mm, cloud.N
        ends = ((I, -1.0), (J, 1.0))
        for e, sgn in ends:                                            # PQ
            s = sgn * self.pa["sigma_PQ_um"][e]
            for c in range(3):
                U[rows, 3 * kp[e] + c] += s * na[:, c]
        U[:, self.off_S:self.off_S + 7] = scale_rows(na, ram[J] - ram[I]) * self.w_S
        if "ET" in self.facs:
            fac = self.facs["ET"]
            # l_J - l_I = C^-1 (k_P(u_J) - k_P(u_I)): one triangular solve
            kd = lr.unit_kernel(fac.Zp, ram[J], fac.inv_lam2) - lr.unit_kernel(fac.Zp, ram[I], fac.inv_lam2)
            dL = solve_triangular(fac.C, kd, lower=True, check_finite=False).T * p.sigma_ET_um   # b x r
            U[:, self.off_ET:self.off_ET + 3 * fac.rank] = (dL[:, :, None] * na[:, None, :]).reshape(b, -1)
        if "ER" in self.facs:
            fac = self.facs["ER"]
            s = p.sigma_ER_urad * pc.MILLI
            off = cloud.offsets_mm
            blk = np.zeros((b, fac.rank, 3))
            for e, sgn in ends:
                w = np.cross(na, off[e])
                blk += (sgn * s) * fac.rows(ram[e]).T[:, :, None] * w[:, None, :]
            U[:, self.off_ER:self.off_ER + 3 * fac.rank] = blk.reshape(b, -1)
        s0, sp = self.pa["sigma_P0_um"], self.pa["sigma_P_um"]
        for e, sgn in ends:
            o = np.einsum("ij,ij->i", na, N[e])
            U[rows, self.off_rad + kp[e]] += sgn * s0[e] * o
            for q, col in self.off_P.items():
                here = np.flatnonzero(kp[e] == q)
                if here.size:
                    fac = self.facs[f"P{q}"]
                    L = fac.rows(N[e[here]]).T * (sgn * sp[e[here]] * o[here])[:, None]
                    U[here, col:col + fac.rank] += L
            sc = self.shared_col[e]
            here = np.flatnonzero(sc >= 0)
            if here.size:
                for c in range(3):
                    U[here, self.off_R + 3 * sc[here] + c] += sgn * p.sigma_R_um * na[here, c]
        return U

    def blocks(self):
        for a0 in range(0, self.n, BLOCK_RECORDS):
            a1 = min(a0 + BLOCK_RECORDS, self.n)
            yield a0, a1, self.U_rows(slice(a0, a1))

    # -- the operator --------------------------------------------------------------------------
    def diagonal(self) -> np.ndarray:
        """The variances of the records (µm²), diag(C) (kept from the whitener's pass)."""
        if getattr(self, "_diag", None) is not None:
            return self._diag.copy()
        out = np.empty(self.n)
        for a0, a1, U in self.blocks():
            out[a0:a1] = self.D[a0:a1] + np.einsum("ik,ik->i", U, U)
        return out

    def dense(self) -> np.ndarray:
        """C as an n x n matrix (small n: tests and checks)."""
        U = np.vstack([U for _a0, _a1, U in self.blocks()]) if self.n else np.zeros((0, self.k))
        return np.diag(self.D) + U @ U.T

    def matvec(self, V: np.ndarray) -> np.ndarray:
        """C V for V of n rows (a vector or n x c)."""
        V = np.asarray(V, dtype=float)
        UtV = np.zeros((self.k,) + V.shape[1:])
        for a0, a1, U in self.blocks():
            UtV += U.T @ V[a0:a1]
        out = (self.D.reshape((-1,) + (1,) * (V.ndim - 1))) * V
        for a0, a1, U in self.blocks():
            out[a0:a1] += U @ UtV
        return out

    def _core_factor(self):
        """Cholesky factor of I + U^T D^-1 U (one pass, cached)."""
        if self._core is None:
            UtU = np.zeros((self.k, self.k))
            for a0, a1, U in self.blocks():
                UtU += U.T @ (U / self.D[a0:a1, None])
            self._core = cho_factor(np.eye(self.k) + UtU, lower=True)
        return self._core

    def solve(self, V: np.ndarray) -> np.ndarray:
        """C^-1 V by the Woodbury identity (V: a vector or n x c)."""
        V = np.asarray(V, dtype=float)
        Dm = self.D.reshape((-1,) + (1,) * (V.ndim - 1))
        DV = V / Dm
        UtDV = np.zeros((self.k,) + V.shape[1:])
        for a0, a1, U in self.blocks():
            UtDV += U.T @ DV[a0:a1]
        Z = cho_solve(self._core_factor(), UtDV)
        out = DV.copy()
        for a0, a1, U in self.blocks():
            out[a0:a1] -= (U @ Z) / Dm[a0:a1]
        return out

    def logdet(self) -> float:
        """log det C = sum log D + log det(I + U^T D^-1 U) (matrix determinant lemma)."""
        c, _lower = self._core_factor()
        return float(np.sum(np.log(self.D)) + 2.0 * np.sum(np.log(np.diag(c))))

    def chi2_bound(self) -> float:
        """First-order relative bound of chi-square from the low-rank GP factors, eps_C / min(D)."""
        return self.eps_C / float(np.min(self.D))

    # -- what the diagnosis needs ------------------------------------------------------------
    def whitener(self, B: np.ndarray, group_rows: dict | None = None, *, backend=None) -> GramWhitener:
        """The whitener on the span of the columns of B (n x c) (see
        :meth:`xlfuncs.locator.structured.StructuredCovariance.whitener`); ``group_rows``: {key: record
        indices} whose Woodbury Grams are accumulated in the same pass, by cells (records with
        the same label in every grouping) summed into groups.  ``backend``: where the passes
        over U run (:mod:`xlfuncs.execution`, :mod:`xlfuncs.distributed`; default
        ``self.backend``, else local threads); the numbers do not depend on it."""
        backend = self.backend if backend is None else backend
        n, c = B.shape
        D = self.D
        keys = list(group_rows or {})
        cell = np.zeros(n, dtype=int)
        members: list[list] = [[None]]
        if keys:
            labels = np.full((len(dict.fromkeys(g[0] for g in keys)), n), -1)
            by_row = {by: r for r, by in enumerate(dict.fromkeys(g[0] for g in keys))}
            for j, g in enumerate(keys):
                labels[by_row[g[0]], group_rows[g]] = j
            code = np.zeros(n, dtype=np.int64)                 # one integer per label combination
            for r in labels:
                loc = np.unique(r, return_inverse=True)[1].reshape(-1)
                code = np.unique(code * (int(loc.max()) + 1) + loc, return_inverse=True)[1].reshape(-1)
            _u, first, cell = np.unique(code, return_index=True, return_inverse=True)
            cell = cell.reshape(-1)
            members = [[None] + [keys[j] for j in labels[:, a] if j >= 0] for a in first]
        need = (len(keys) + 4) * 8 * self.k * (self.k + c)     # a Gram per group, the total, a cell, a task
        have = available_bytes()
        if need > have:
            raise ResourceError(
                f"the group statistics of {n:,} length records need about {need / 2**30:,.1f} GiB "
                f"({len(keys)} groups x {self.k:,}^2 numbers), {have / 2**30:,.1f} GiB are available: "
                "diagnose fewer groupings (drop the group, time or temperature columns) or a section")
        grams = {None: [np.zeros((self.k, self.k)), np.zeros((self.k, c))]}
        for g in keys:
            grams[g] = [np.zeros((self.k, self.k)), np.zeros((self.k, c))]
        # records cell by cell (a stable order): each cell's Gram is added once to its groups;
        # the blocks run on ``backend`` (local threads or Dask) and are summed in block order
        order = np.argsort(cell, kind="stable")
        items = []
        for rows in np.split(order, np.flatnonzero(np.diff(cell[order])) + 1):
            for b0 in range(0, len(rows), TASK_RECORDS):
                items.append(rows[b0:b0 + TASK_RECORDS])
        shared = {"C": self, "B": B}
        runner = backend or ThreadBackend()
        UU = UB = None
        for q, (UUb, UBb) in enumerate(runner.map(_gram_block, items, shared)):
            UU, UB = (UUb, UBb) if UU is None else (UU + UUb, UB + UBb)
            last = q + 1 == len(items) or cell[items[q + 1][0]] != cell[items[q][0]]
            if last:
                for t in members[int(cell[items[q][0]])]:
                    grams[t][0] += UU
                    grams[t][1] += UB
                UU = UB = None
        UtU, UtB = grams[None]
        self._core = cho_factor(np.eye(self.k) + UtU, lower=True)
        Z = cho_solve(self._core, UtB)                       # (I + U^T D^-1 U)^-1 U^T D^-1 B
        Gamma = B.T @ (B / D[:, None]) - UtB.T @ Z
        P = B / D[:, None]
        items = [(a0, min(a0 + TASK_RECORDS, n)) for a0 in range(0, n, TASK_RECORDS)]
        diag = np.empty(n)
        for (a0, a1), (UZ, dg) in zip(items, runner.map(_solve_block, items, {"C": self, "Z": Z})):
            P[a0:a1] -= UZ / D[a0:a1, None]
            diag[a0:a1] = D[a0:a1] + dg
        self._diag = diag
        groups = {g: (grams[g][0], grams[g][1], np.asarray(group_rows[g])) for g in keys}
        return GramWhitener(0.5 * (Gamma + Gamma.T), P, n, B, D, groups)


def _gram_block(rows: np.ndarray, shared) -> tuple[np.ndarray, np.ndarray]:
    """U_r^T D_r^-1 U_r and U_r^T D_r^-1 B_r for the records ``rows`` (one task; sub-blocks of
    BLOCK_RECORDS summed in order)."""
    C, B = shared["C"], shared["B"]
    UU, UB = np.zeros((C.k, C.k)), np.zeros((C.k, B.shape[1]))
    for b0 in range(0, len(rows), BLOCK_RECORDS):
        r = rows[b0:b0 + BLOCK_RECORDS]
        W = C.U_rows(r) / np.sqrt(C.D[r])[:, None]                  # D^-1/2 U
        UU = dsyrk(1.0, W, beta=1.0, c=UU, trans=1, lower=1, overwrite_c=1)    # += W^T W (lower)
        UB += W.T @ (B[r] / np.sqrt(C.D[r])[:, None])
    il = np.triu_indices(C.k, 1)
    UU[il] = UU.T[il]
    return UU, UB


def _solve_block(item, shared) -> tuple[np.ndarray, np.ndarray]:
    """U_r Z and the diagonal of U_r U_r^T for the records a0 .. a1-1 (one task of the second
    pass)."""
    a0, a1 = item
    C, Z = shared["C"], shared["Z"]
    UZ, dg = [], []
    for b0 in range(a0, a1, BLOCK_RECORDS):
        U = C.U_rows(slice(b0, min(b0 + BLOCK_RECORDS, a1)))
        UZ.append(U @ Z)
        dg.append(np.einsum("ik,ik->i", U, U))
    return np.vstack(UZ), np.concatenate(dg)
