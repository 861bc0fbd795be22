"""The REML log-likelihood of verification recordings as a function of the six influence factors'
hyper-parameters (Forbes 2025, Tables 1 and 3), its closed-form gradient, expected and observed
information, and the Fisher-scoring maximizer: the likelihood behind ``cmmwb calibrate``
(:mod:`xlfuncs.calibrate` judges identifiability and holds what the records cannot determine).

The recordings (``docs/recordings.md``: lengths or points) are the linear model of the locator
(:func:`xlfuncs.locator.model.prepare`),

    r = X beta + e,   e ~ N(0, C(theta)),

with X the fixed effects -- the rigid alignment of point records and the systematic effects the
locator names (:mod:`xlfuncs.locator.effects` columns), profiled out by REML -- and C(theta) the SAME
record covariance ``diagnose`` uses (:func:`xlfuncs.locator.model.length_covariance` for lengths,
:func:`xlfuncs.pointcloud.V_X_components` for points), a sum over the factors

    R (eq. 8), PQ (eq. 9), S (eqs. 11-14: sigma_S, sigma_Sa, sigma_Q), ET (eq. 21),
    ER (eqs. 24-25), P (eqs. 26-27: sigma_P0, sigma_P, lambda_P).

Every standard deviation enters C quadratically, sigma^2 B (B the factor's covariance at
sigma = 1), every length scale through its squared-exponential kernel.  The fit works in
phi = log sigma, log lambda (positive, and the likelihood is closer to quadratic there).

REML log-likelihood (Patterson & Thompson 1971; Harville 1977), Q an orthonormal basis of X:

    l(phi) = -1/2 [ log|C| + log|Q^T C^-1 Q| + r^T P r + (n - p) log 2 pi ],
    P = C^-1 - C^-1 Q (Q^T C^-1 Q)^-1 Q^T C^-1,

its gradient in closed form, dl/dphi_k = -1/2 tr(P dC_k) + 1/2 r^T P dC_k P r, with
dC/d(log sigma) = 2 sigma^2 B and dC/d(log lambda) the kernel's derivative
(:func:`xlfuncs.pointcloud.gauss_kernel`), and the expected information
F_kl = 1/2 tr(P dC_k P dC_l) for Fisher scoring.  The covariance of the estimates is the inverse
of the observed information (the Hessian of -l, central differences of the closed-form gradient).

The dense operator (:class:`DenseRecordCovariance`) keeps C and its derivatives as n x n
matrices (at most DENSE_MAX_OBS observations); the structured one
(:class:`xlfuncs.reml_structured.StructuredRecordCovariance`) computes the same terms through the
operator C = D + U U^T of ``diagnose`` (Woodbury, the Nyström factors' derivatives), never n x n;
:func:`record_covariance` chooses (dense up to DENSE_MAX_OBS observations, structured above).

numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import pointcloud as pc
from .errors import ModelError, about
from .locator.model import Prepared, is_structured, length_covariance
from .model import sq_dists
from .model.hyperparameters import GP, HYPERPARAMETERS, LINEAR, NAMES, PARTNER, UNITS  # noqa: F401

#: the hyper-parameters' tables, derived from their records (xlfuncs.model.hyperparameters):
#: NAMES, UNIT (name -> unit), PARTNER (length scale -> its standard deviation), LINEAR (standard
#: deviations entering C as sigma^2 B, B fixed), GP ((sigma, lambda, factor) of the kernels),
#: FACTOR (name -> the factor of the record covariance it is found in)
UNIT = UNITS
FACTOR = {h.name: h.factor for h in HYPERPARAMETERS}

#: a sigma below this share of its start is at zero (the records show none of the factor)
ZERO_SHARE = 1e-3
#: the dense path: at most this many observations (memory n^2 per derivative)
DENSE_MAX_OBS = 4000



# ---------------------------------------------------------------------------------------------
# the record covariance as a function of the hyper-parameters
# ---------------------------------------------------------------------------------------------

def _plain_probes(cloud: pc.PointCloud) -> pc.PointCloud:
    """The cloud with every probe on the task-wide parameters (per-probe overrides dropped: the fit
    estimates one sigma_PQ, sigma_P0, sigma_P, lambda_P for all probes)."""
    return replace(cloud, probes=tuple(pc.Probe(p.id, tuple(p.offset_mm)) for p in cloud.probes))


class DenseRecordCovariance:
    """C(theta) (µm²) and its derivatives in the log hyper-parameters for one prepared record set,
    as dense n x n matrices, from the covariance operators of ``diagnose``: length records
    :func:`length_covariance` (kernel form of G V_X G^T), point records
    :func:`pointcloud.V_X_components` restricted to the observed coordinates."""

    def __init__(self, prep: Prepared):
        if is_structured(prep):
            raise ModelError("the dense record covariance holds at most "
                             f"{DENSE_MAX_OBS} observations per file: use --covariance structured (or auto)")
        self.prep = prep
        self.cloud = _plain_probes(prep.cloud)
        self.n = prep.r_um.shape[0]
        if self.n > DENSE_MAX_OBS:
            raise ModelError(f"the dense record covariance holds at most {DENSE_MAX_OBS} observations per "
                             f"file, this one has {self.n}: use --covariance structured (or auto)")
        if prep.ends is None:
            dims = 2 if prep.design.dims == 2 else 3
            self.keep = np.array([3 * i + a for i in range(prep.rec.n) for a in range(dims)])
        self.basis = {}
        # what C holds at every hyper-parameter zero: nothing but the part's temperature difference and
        # uncorrected expansion (the factor W, docs/workpiece.md), known, not fitted
        zero = self.components(pc.Parameters())
        self.const = sum(zero.values())
        for name in LINEAR:
            comps = self.components(pc.Parameters(**{name: 1.0}))
            self.basis[name] = comps[FACTOR[name]] - zero[FACTOR[name]]

    def components(self, params: pc.Parameters, d_log_lambda: bool = False) -> dict[str, np.ndarray]:
        """The factors' record covariances (the same functions as ``diagnose``)."""
        prep = self.prep
        if prep.ends is not None:
            I, J = prep.ends
            return length_covariance(self.cloud, params, I, J, components=True, d_log_lambda=d_log_lambda)
        V = pc.V_X_components(self.cloud, params, d_log_lambda=d_log_lambda)
        k = self.keep
        return {f: M[np.ix_(k, k)] for f, M in V.items()}

    def evaluate(self, values: dict[str, float], free: list[str]) -> tuple[np.ndarray, list[np.ndarray]]:
        """C at ``values`` and dC/dphi_k for every name in ``free`` (phi = log value)."""
        C = np.array(self.const, dtype=float) if np.ndim(self.const) else np.zeros((self.n, self.n))
        d: dict[str, np.ndarray] = {}
        for name in LINEAR:
            v = values[name]
            if v > 0:
                term = v * v * self.basis[name]
                C += term
                d[name] = 2.0 * term
        gp = {s: values[s] for s, _lm, _f in GP}
        if any(v > 0 for v in gp.values()):
            lam = {lm: values[lm] if values[PARTNER[lm]] > 0 else 0.0 for lm in PARTNER}
            params = pc.Parameters(**gp, **lam)
            comps = self.components(params)
            dl = None
            for s, lm, f in GP:
                if gp[s] > 0:
                    C += comps[f]
                    d[s] = 2.0 * comps[f]
                    if lm in free:
                        if dl is None:
                            dl = self.components(params, d_log_lambda=True)
                        d[lm] = dl[f]
        C = 0.5 * (C + C.T)
        return C, [d.get(k, np.zeros_like(C)) for k in free]


    def reml(self, y: np.ndarray, Q: np.ndarray, values: dict[str, float], free: list[str],
             fisher: bool = True) -> "RemlTerms":
        """The REML terms of this record set (module docstring): one Cholesky factorization of C,
        P formed once, tr(P dC_k) and r^T P dC_k P r for the gradient, 1/2 tr(P dC_k P dC_l) for the
        expected information."""
        C, dCs = self.evaluate(values, free)
        L = np.linalg.cholesky(C)
        Li = np.linalg.inv(L)
        Ci = Li.T @ Li
        CiQ = Ci @ Q
        if Q.shape[1]:
            M = Q.T @ CiQ
            logdetM = 2.0 * float(np.sum(np.log(np.diag(np.linalg.cholesky(M)))))
            P = Ci - CiQ @ np.linalg.solve(M, CiQ.T)
        else:
            logdetM, P = 0.0, Ci
        P = 0.5 * (P + P.T)
        Py = P @ y
        n, p = len(y), Q.shape[1]
        q = float(y @ Py)
        ll = -0.5 * (2.0 * float(np.sum(np.log(np.diag(L)))) + logdetM + q + (n - p) * math.log(2 * math.pi))
        k = len(free)
        g, F = np.zeros(k), np.zeros((k, k)) if fisher else None
        PdC = [P @ dC for dC in dCs]
        for a in range(k):
            g[a] = -0.5 * float(np.trace(PdC[a])) + 0.5 * float(Py @ dCs[a] @ Py)
            if fisher:
                for b in range(a + 1):
                    F[a, b] = F[b, a] = 0.5 * float(np.sum(PdC[a] * PdC[b].T))
        return RemlTerms(ll, g, F, q, n - p)


def use_structured(rec, covariance: str = "auto") -> bool:
    """Whether the fit takes the structured record covariance for these records: ``covariance``
    ``structured``, ``dense``, or ``auto`` (above DENSE_MAX_OBS observations)."""
    if covariance not in ("auto", "dense", "structured"):
        raise ModelError(f"--covariance must be auto, dense or structured, got {covariance!r}")
    if covariance != "auto":
        return covariance == "structured"
    from .locator.recordings import LengthRecords

    dims = 1 if isinstance(rec, LengthRecords) else 2 if rec.planar else 3
    return rec.n * dims > DENSE_MAX_OBS


def record_covariance(prep: Prepared, structured: bool | None = None):
    """The operator C(theta) of one record set: dense (:class:`DenseRecordCovariance`) up to
    DENSE_MAX_OBS observations, else (or with ``structured`` True, or when ``prep`` already holds
    the structured operator of ``diagnose``) the structured operator
    (:class:`xlfuncs.reml_structured.StructuredRecordCovariance`, C = D + U U^T never formed).
    Either gives ``cloud`` (the probings), ``n`` (observations), ``reml(y, Q, values, free,
    fisher) -> RemlTerms`` (the fit); the dense one ``evaluate(values, []) -> (C, [])``, the
    structured one ``gls_fit`` and ``standardized_residuals`` (the checks)."""
    if structured is None:
        structured = is_structured(prep) or prep.r_um.shape[0] > DENSE_MAX_OBS
    if structured:
        from .reml_structured import StructuredRecordCovariance, check_structure

        check_structure(prep)
        return StructuredRecordCovariance(prep, _plain_probes(prep.cloud))
    return DenseRecordCovariance(prep)


# ---------------------------------------------------------------------------------------------
# REML
# ---------------------------------------------------------------------------------------------

@dataclass
class RecordSet:
    """One file's records: the residual r (µm), the fixed-effect columns X and the operator C(theta)."""

    name: str
    prep: Prepared
    X: np.ndarray
    X_labels: list[str]
    op: object           # DenseRecordCovariance or reml_structured.StructuredRecordCovariance
    Q: np.ndarray = field(init=False)

    def __post_init__(self):
        X = self.X
        if X.shape[1]:
            U, s, _ = np.linalg.svd(X / np.maximum(np.linalg.norm(X, axis=0), 1e-300), full_matrices=False)
            self.Q = U[:, s > 1e-8 * s[0]]
        else:
            self.Q = np.zeros((X.shape[0], 0))
        if self.Q.shape[1] >= X.shape[0]:
            raise ModelError(f"{self.name}: no degrees of freedom left after the fixed effects")

    @property
    def y(self) -> np.ndarray:
        return self.prep.r_um

    @property
    def structured(self) -> bool:
        """True when C(theta) is the structured operator (never n x n), False when dense."""
        return not isinstance(self.op, DenseRecordCovariance)


def record_set(prep: Prepared, name: str = "records", effect_X: np.ndarray | None = None,
               effect_labels: list[str] | None = None, structured: bool | None = None) -> RecordSet:
    """The records with their fixed effects: the alignment (point records) and ``effect_X``;
    ``structured``: the operator (:func:`record_covariance`)."""
    X, labels = prep.A, list(prep.A_labels)
    if effect_X is not None and effect_X.shape[1]:
        X = np.column_stack([X, effect_X])
        labels += list(effect_labels or [f"effect {j + 1}" for j in range(effect_X.shape[1])])
    return RecordSet(name, prep, X, labels, record_covariance(prep, structured))


@dataclass
class RemlTerms:
    loglik: float
    grad: np.ndarray
    fisher: np.ndarray | None
    chi2: float          # r^T P r
    dof: int             # n - p


def reml_terms(sets: list[RecordSet], values: dict[str, float], free: list[str], fisher: bool = True) -> RemlTerms:
    """REML log-likelihood, its gradient in phi = log(value) of ``free`` and the expected
    information, summed over independent record sets (each set's operator computes its own:
    :meth:`DenseRecordCovariance.reml`)."""
    k = len(free)
    total = RemlTerms(0.0, np.zeros(k), np.zeros((k, k)) if fisher else None, 0.0, 0)
    for i, s in enumerate(sets):
        try:
            t = s.op.reml(s.y, s.Q, values, free, fisher)
            if isinstance(t, tuple):          # the structured operator's terms
                t = RemlTerms(*t)
        except np.linalg.LinAlgError:
            raise about(ModelError(f"{s.name}: the record covariance is not positive definite at "
                                   + ", ".join(f"{n} = {values[n]:.4g}" for n in free)), "sets", i) from None
        total.loglik += t.loglik
        total.grad += t.grad
        if fisher:
            total.fisher += t.fisher
        total.chi2 += t.chi2
        total.dof += t.dof
    return total


def values_from_log(start: dict[str, float], free: list[str], phi: np.ndarray) -> dict[str, float]:
    v = dict(start)
    for name, x in zip(free, phi):
        v[name] = math.exp(x)
    return v


@dataclass
class Bounds:
    lo: np.ndarray
    hi: np.ndarray


def closest_spacing(U: np.ndarray, below: float = 1e-9) -> float:
    """The smallest distance (mm) between two of the positions U farther apart than ``below``
    (inf if none): dense for a few thousand positions, a k-d tree beyond (never m x m)."""
    if len(U) <= 2000:
        D = np.sqrt(sq_dists(U, U))
        D[D < below] = np.inf
        return float(np.min(D))
    from scipy.spatial import cKDTree

    U = np.unique(U, axis=0)
    tree = cKDTree(U)
    k = 2
    while True:
        d, _ = tree.query(U, k=min(k, len(U)))
        d = np.where(d < below, np.inf, d)
        best = float(np.min(d))
        # every position whose k-1 neighbours all lie within ``below`` needs more neighbours
        if k >= len(U) or np.all(np.isfinite(d[:, -1]) | np.isfinite(np.min(d, axis=1))):
            return best
        k *= 2


def bounds(sets: list[RecordSet], start: dict[str, float], free: list[str]) -> Bounds:
    """Search box in phi: sigmas from ZERO_SHARE x start to 1e3 x start, length scales from a
    tenth of the closest spacing to a hundred times the travel seen."""
    lo, hi = [], []
    travel, spacing = 0.0, math.inf
    for s in sets:
        U = s.op.cloud.ram_mm
        travel = max(travel, float(np.max(np.ptp(U, axis=0))))
        if len(U) > 1:
            spacing = min(spacing, closest_spacing(U))
    travel = travel or 1.0
    spacing = spacing if math.isfinite(spacing) else travel
    for name in free:
        v = start[name]
        if name == "lambda_P":
            lo.append(math.log(0.05)), hi.append(math.log(20.0))
        elif name.startswith("lambda"):
            lo.append(math.log(max(spacing / 10, 1e-3))), hi.append(math.log(100 * travel))
        else:
            lo.append(math.log(v * ZERO_SHARE)), hi.append(math.log(v * 1e3))
    return Bounds(np.array(lo), np.array(hi))


def maximize(sets: list[RecordSet], start: dict[str, float], free: list[str], box: Bounds,
             max_iter: int = 100, tol: float = 1e-7, tol_decrement: float = 1e-6
             ) -> tuple[np.ndarray, RemlTerms, int]:
    """Fisher scoring in phi with step halving, projected on the box; returns (phi, terms, iterations)."""
    phi = np.clip(np.log([start[n] for n in free]), box.lo, box.hi)
    t = reml_terms(sets, values_from_log(start, free, phi), free)
    it = 0
    for it in range(1, max_iter + 1):
        F = t.fisher
        scale = np.sqrt(np.maximum(np.diag(F), 1e-12))
        Fn = F / np.outer(scale, scale) + 1e-8 * np.eye(len(free))
        step = np.linalg.solve(Fn, t.grad / scale) / scale
        big = np.max(np.abs(step))
        if big > 2.0:
            step *= 2.0 / big
        # a parameter at its lower bound whose step points further down stays there
        at_lo = (phi <= box.lo + 1e-12) & (step < 0)
        at_hi = (phi >= box.hi - 1e-12) & (step > 0)
        step[at_lo | at_hi] = 0.0
        if float(t.grad @ step) < tol_decrement:
            break       # Newton decrement: the expected gain is below the tolerance
        improved = False
        for _ in range(30):
            trial = np.clip(phi + step, box.lo, box.hi)
            tt = reml_terms(sets, values_from_log(start, free, trial), free)
            if tt.loglik >= t.loglik - 1e-10:
                improved = True
                break
            step *= 0.5
        if not improved:
            break
        dphi = trial - phi
        phi, gain = trial, tt.loglik - t.loglik
        t = tt
        if np.max(np.abs(dphi)) < tol or gain < 0.1 * tol_decrement:
            break
    return phi, t, it


def observed_information(sets: list[RecordSet], values: dict[str, float], free: list[str], h: float = 1e-4) -> np.ndarray:
    """-d2 l/dphi2 by central differences of the closed-form gradient (symmetrized)."""
    k = len(free)
    H = np.zeros((k, k))
    phi = np.log([values[n] for n in free])
    for a in range(k):
        e = np.zeros(k)
        e[a] = h
        gp = reml_terms(sets, values_from_log(values, free, phi + e), free, fisher=False).grad
        gm = reml_terms(sets, values_from_log(values, free, phi - e), free, fisher=False).grad
        H[:, a] = -(gp - gm) / (2 * h)
    return 0.5 * (H + H.T)
