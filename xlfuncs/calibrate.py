"""The user's own machine: the hyper-parameters of the six influence factors (Forbes 2025,
Tables 1 and 3) estimated from its verification recordings by restricted maximum likelihood.

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

Identifiability (per hyper-parameter) is judged on the design first: from the expected
information at the starting values, a parameter whose covariance has no sensitivity in these
records after the fixed effects (F_kk = 0: sigma_PQ with one probe, sigma_ER with zero probe
offsets, ...) or whose u(log) with the others free exceeds :data:`U_LOG_MAX` (the records
determine it to no better than a factor of e^0.5 ~ 1.65: sigma_ER with one probe offset, a lambda
beyond the travel, a scale factor of which one machine shows one draw) is held at its starting
value and reported with the measurement that would identify it; after the fit, one whose u(log)
from the observed information exceeds twice that is held too.  A standard deviation whose
likelihood is largest at zero is reported ``zero`` with the upper one-sided 95 % limit of its
REML profile (:func:`upper_limit`).

The dense operator (:class:`DenseRecordCovariance`) keeps C and its derivatives as n x n
matrices; :func:`record_covariance` is where a structured operator plugs in (it must give
``reml(y, Q, values, free, fisher)``, the REML terms of its records, and ``evaluate(values, [])``).

numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import pointcloud as pc
from .errors import ModelError
from .locator.model import Prepared, is_structured, length_covariance
from .model import sq_dists

#: the hyper-parameters: (task-file name, factor, kind, unit)
HYPERS: tuple[tuple[str, str, str, str], ...] = (
    ("sigma_R_um", "R", "sigma", "µm"),
    ("sigma_S_ppm", "S", "sigma", "ppm"),
    ("sigma_Sa_ppm", "S", "sigma", "ppm"),
    ("sigma_Q_ppm", "S", "sigma", "ppm"),
    ("sigma_PQ_um", "PQ", "sigma", "µm"),
    ("sigma_ET_um", "ET", "sigma", "µm"),
    ("lambda_ET_mm", "ET", "lambda", "mm"),
    ("sigma_ER_urad", "ER", "sigma", "µrad"),
    ("lambda_ER_mm", "ER", "lambda", "mm"),
    ("sigma_P0_um", "P", "sigma", "µm"),
    ("sigma_P_um", "P", "sigma", "µm"),
    ("lambda_P", "P", "lambda", "1"),
)
NAMES = tuple(h[0] for h in HYPERS)
UNIT = {h[0]: h[3] for h in HYPERS}
#: the standard deviation whose kernel a length scale shapes
PARTNER = {"lambda_ET_mm": "sigma_ET_um", "lambda_ER_mm": "sigma_ER_urad", "lambda_P": "sigma_P_um"}
#: standard deviations entering C linearly in sigma^2 (their B is fixed)
LINEAR = ("sigma_R_um", "sigma_S_ppm", "sigma_Sa_ppm", "sigma_Q_ppm", "sigma_PQ_um", "sigma_P0_um")
#: factor of the record covariance each linear standard deviation is found in
FACTOR = {h[0]: h[1] for h in HYPERS}

#: a hyper-parameter is identified when u(log value) from the observed information is below this
U_LOG_MAX = 0.5
#: a sigma below this share of its start is at zero (the records show none of the factor)
ZERO_SHARE = 1e-3
#: a parameter with an expected information below this (per unit log) has no sensitivity
NO_SENSITIVITY = 1e-6
#: drop of the REML log-likelihood that bounds a standard deviation estimated at zero: the upper
#: one-sided 95 % limit for a parameter on the boundary (Self & Liang 1987: the likelihood-ratio
#: statistic is 1/2 chi2_0 + 1/2 chi2_1, its 95 % point chi2_1(0.90) = 2.706, half of it)
UPPER_DROP = 1.353
#: the dense path: at most this many observations (memory n^2 per derivative)
DENSE_MAX_OBS = 4000

#: what measurement identifies each hyper-parameter (reported with a non-identifiable one)
ADVICE = {
    "sigma_R_um": "repeated records (each length or point measured several times)",
    "sigma_S_ppm": "one machine shows one draw of its scale error: lengths in many directions and "
                   "positions give its value (fit 'scale' as an effect and compensate it) rather than "
                   "its spread; the spread needs several machines or re-verifications",
    "sigma_Sa_ppm": "lengths along x, y and z (the per-axis scale errors are one draw each per machine: "
                    "their spread needs several machines or re-verifications)",
    "sigma_Q_ppm": "lengths along the face and space diagonals (the squareness errors are one draw each per "
                   "machine: their spread needs several machines or re-verifications)",
    "sigma_PQ_um": "records with two or more probes (probe changes) measuring the same artefact",
    "sigma_ET_um": "positions spread over several correlation lengths along each axis (step gauge or "
                   "ball plate in several places)",
    "lambda_ET_mm": "positions spread over several correlation lengths lambda_ET along each axis, and "
                    "closely spaced ones (a step gauge) to see the correlation decay",
    "sigma_ER_urad": "two or more probe offsets of different direction and length (ISO 10360-2 with "
                     "offset styli): with one offset a rotation is indistinguishable from a translation",
    "lambda_ER_mm": "two or more probe offsets, and positions spread over several lambda_ER",
    "sigma_P0_um": "points probed along many directions with one probe (a sphere, holes; bidirectional "
                   "lengths)",
    "sigma_P_um": "many probing directions with one probe (a reference sphere probed at 25 or more points)",
    "lambda_P": "many probing directions with one probe, some close together (a densely probed sphere)",
}


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
            raise ModelError("calibrate uses the dense record covariance: give at most "
                             f"{DENSE_MAX_OBS} observations per file (or use diagnose for larger files)")
        self.prep = prep
        self.cloud = _plain_probes(prep.cloud)
        self.n = prep.r_um.shape[0]
        if self.n > DENSE_MAX_OBS:
            raise ModelError(f"calibrate uses the dense record covariance: {self.n} observations, at most "
                             f"{DENSE_MAX_OBS} per file")
        if prep.ends is None:
            dims = 2 if prep.design.dims == 2 else 3
            self.keep = np.array([3 * i + a for i in range(prep.rec.n) for a in range(dims)])
        self.basis = {}
        for name in LINEAR:
            comps = self.components(pc.Parameters(**{name: 1.0}))
            self.basis[name] = comps[FACTOR[name]]

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
        C = np.zeros((self.n, self.n))
        d: dict[str, np.ndarray] = {}
        for name in LINEAR:
            v = values[name]
            if v > 0:
                term = v * v * self.basis[name]
                C += term
                d[name] = 2.0 * term
        gp = {s: values[s] for s in ("sigma_ET_um", "sigma_ER_urad", "sigma_P_um")}
        if any(v > 0 for v in gp.values()):
            lam = {lm: values[lm] if values[PARTNER[lm]] > 0 else 0.0 for lm in PARTNER}
            params = pc.Parameters(**gp, **lam)
            comps = self.components(params)
            dl = None
            for s, f, lm in (("sigma_ET_um", "ET", "lambda_ET_mm"), ("sigma_ER_urad", "ER", "lambda_ER_mm"),
                             ("sigma_P_um", "P", "lambda_P")):
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


def record_covariance(prep: Prepared) -> DenseRecordCovariance:
    """The operator C(theta) of one record set (dense).  A structured operator plugs in here: it
    gives ``cloud`` (the probings), ``n`` (observations), ``reml(y, Q, values, free, fisher) ->
    RemlTerms`` (the fit) and ``evaluate(values, []) -> (C, [])`` (GLS of the effects and the
    standardized residuals; dense there)."""
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
    op: DenseRecordCovariance
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


def record_set(prep: Prepared, name: str = "records", effect_X: np.ndarray | None = None,
               effect_labels: list[str] | None = None) -> RecordSet:
    """The records with their fixed effects: the alignment (point records) and ``effect_X``."""
    X, labels = prep.A, list(prep.A_labels)
    if effect_X is not None and effect_X.shape[1]:
        X = np.column_stack([X, effect_X])
        labels += list(effect_labels or [f"effect {j + 1}" for j in range(effect_X.shape[1])])
    return RecordSet(name, prep, X, labels, record_covariance(prep))


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
    for s in sets:
        try:
            t = s.op.reml(s.y, s.Q, values, free, fisher)
        except np.linalg.LinAlgError:
            raise ModelError(f"{s.name}: the record covariance is not positive definite at "
                             + ", ".join(f"{n} = {values[n]:.4g}" for n in free)) from None
        total.loglik += t.loglik
        total.grad += t.grad
        if fisher:
            total.fisher += t.fisher
        total.chi2 += t.chi2
        total.dof += t.dof
    return total


def _values(start: dict[str, float], free: list[str], phi: np.ndarray) -> dict[str, float]:
    v = dict(start)
    for name, x in zip(free, phi):
        v[name] = math.exp(x)
    return v


@dataclass
class Bounds:
    lo: np.ndarray
    hi: np.ndarray


def bounds(sets: list[RecordSet], start: dict[str, float], free: list[str]) -> Bounds:
    """Search box in phi: sigmas from ZERO_SHARE x start to 1e3 x start, length scales from a
    tenth of the closest spacing to a hundred times the travel seen."""
    lo, hi = [], []
    travel, spacing = 0.0, math.inf
    for s in sets:
        U = s.op.cloud.ram_mm
        travel = max(travel, float(np.max(np.ptp(U, axis=0))))
        if len(U) > 1:
            D = np.sqrt(sq_dists(U, U))
            D[D < 1e-9] = np.inf
            spacing = min(spacing, float(np.min(D)))
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
    t = reml_terms(sets, _values(start, free, phi), free)
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
            tt = reml_terms(sets, _values(start, free, trial), free)
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
        gp = reml_terms(sets, _values(values, free, phi + e), free, fisher=False).grad
        gm = reml_terms(sets, _values(values, free, phi - e), free, fisher=False).grad
        H[:, a] = -(gp - gm) / (2 * h)
    return 0.5 * (H + H.T)


# ---------------------------------------------------------------------------------------------
# the fit with identifiability
# ---------------------------------------------------------------------------------------------

@dataclass
class Estimate:
    name: str
    unit: str
    start: float
    value: float
    u: float | None          # standard uncertainty in ``unit`` (delta method from u(log))
    u_log: float | None      # standard uncertainty of log(value)
    status: str              # "estimated", "zero", "not identifiable", "off"
    reason: str = ""
    advice: str = ""
    upper: float | None = None   # "zero": upper one-sided 95 % limit from the REML profile


@dataclass
class Calibration:
    estimates: dict[str, Estimate]
    params: pc.Parameters          # fitted (non-identified ones at their start)
    start: pc.Parameters
    free: list[str]                # estimated
    cov_log: np.ndarray            # covariance of log(value) of ``free``
    loglik: float
    loglik_start: float
    chi2: float                    # r^T P r at the fit (sum over the sets)
    dof: int
    iterations: int
    sets: list[RecordSet]

    def to_json(self) -> dict:
        return {
            "loglik": self.loglik, "loglik_start": self.loglik_start, "reml_chi2": self.chi2, "reml_dof": self.dof,
            "iterations": self.iterations,
            "estimated": list(self.free),
            "hyper_parameters": [
                {"name": e.name, "unit": e.unit, "start": e.start, "estimate": e.value, "u": e.u,
                 "u_log": e.u_log, "status": e.status, "reason": e.reason, "advice": e.advice,
                 "upper_95": e.upper}
                for e in self.estimates.values()],
            "correlation": _corr(self.cov_log).tolist() if len(self.free) else [],
        }


def _corr(cov: np.ndarray) -> np.ndarray:
    s = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    return cov / np.outer(s, s)


def _beyond_travel(name: str, sets: list[RecordSet], values: dict[str, float]) -> str | None:
    """The sentence for a GP factor whose length scale exceeds the travel the records span."""
    lam = {"sigma_ET_um": "lambda_ET_mm", "lambda_ET_mm": "lambda_ET_mm", "sigma_ER_urad": "lambda_ER_mm",
           "lambda_ER_mm": "lambda_ER_mm"}.get(name)
    if lam is None:
        return None
    travel = max(float(np.max(np.ptp(s.op.cloud.ram_mm, axis=0))) for s in sets)
    if values[lam] > travel:
        return (f"{lam} = {values[lam]:.4g} mm reaches beyond the travel seen ({travel:.4g} mm): the records see "
                "only the start of the correlation's decay (within the travel the factor moves the records "
                "almost rigidly, which the lengths cancel or the alignment absorbs)")
    return None


def _why_insensitive(name: str, sets: list[RecordSet], values: dict[str, float] | None = None) -> str:
    probes = {p.offset_mm for s in sets for p in s.op.cloud.probes}
    ids = {p.id for s in sets for p in s.op.cloud.probes}
    kinds = {s.prep.design.kind for s in sets}
    if name == "sigma_PQ_um" and len(ids) < 2:
        return ("one probe: its qualification error is common to every probing and "
                + ("cancels in every length" if kinds == {"length"} else "is absorbed by the alignment"))
    if name in ("sigma_ER_urad", "lambda_ER_mm") and all(np.allclose(p, 0.0) for p in probes):
        return "every probe offset is zero: a rotation of the ram moves no stylus tip"
    if name in ("sigma_P0_um", "sigma_P_um", "lambda_P"):
        return "no normals in the records, or every point probed along one direction per probe"
    far = _beyond_travel(name, sets, values) if values else None
    return far or "the records carry no information on it after the fixed effects"


def _why_weak(name: str, sets: list[RecordSet], corr_row: np.ndarray | None, free: list[str],
              values: dict[str, float]) -> str:
    parts = []
    far = _beyond_travel(name, sets, values)
    if far:
        parts.append(far)
    if name in ("sigma_ER_urad", "lambda_ER_mm"):
        offs = {p.offset_mm for s in sets for p in s.op.cloud.probes}
        if len(offs) == 1:
            parts.append("one probe offset: a rotation moves every tip like a translation of the ram")
    if name in ("sigma_S_ppm", "sigma_Sa_ppm", "sigma_Q_ppm"):
        parts.append("one machine shows one draw of each scale/squareness parameter")
    if corr_row is not None:
        j = int(np.argmax(np.abs(corr_row)))
        if abs(corr_row[j]) > 0.7:
            parts.append(f"correlated with {free[j]} (rho = {corr_row[j]:+.2f})")
    return "; ".join(parts) or "the likelihood is flat in it"


def calibrate(sets: list[RecordSet], start: pc.Parameters, *, fixed: tuple[str, ...] = (),
              u_log_max: float = U_LOG_MAX) -> Calibration:
    """REML estimates of the hyper-parameters, starting from ``start`` (the task's values).

    1. A parameter that is zero in ``start`` (or whose standard deviation is) is off: held at
       zero; names in ``fixed`` are held at their start.
    2. Identifiability is a property of the measurement: from the expected information at the
       start, a parameter without sensitivity (F_kk ~ 0), or whose u(log) with the others free
       exceeds ``u_log_max``, is held at its start value (the worst first, then again without it).
    3. The others are estimated (Fisher scoring); a standard deviation whose likelihood is
       largest at zero is reported ``zero`` and the rest refitted.
    4. The covariance of the log estimates is the inverse observed information; a parameter whose
       u(log) there exceeds twice ``u_log_max`` (these records, not the design, leave it open) is
       held at its start too and the rest refitted."""
    if not sets:
        raise ModelError("no records to calibrate from")
    sv = {n: float(getattr(start, n)) for n in NAMES}
    if sv["sigma_R_um"] <= 0:
        raise ModelError("calibrate needs sigma_R_um > 0 in the task (the starting value of the repeatability)")
    est: dict[str, Estimate] = {}
    free: list[str] = []
    for name in NAMES:
        e = Estimate(name, UNIT[name], sv[name], sv[name], None, None, "estimated")
        partner = PARTNER.get(name)
        if sv[name] <= 0 or (partner and sv[partner] <= 0):
            e.status, e.reason = "off", "zero in the task: the factor is left out (held at zero)"
            if partner and sv[partner] <= 0:
                e.reason = f"{partner} is zero in the task: its length scale plays no part"
            sv[name] = 0.0
        elif name in fixed:
            e.status, e.reason = "fixed", "held at the task's value (asked)"
        else:
            free.append(name)
        est[name] = e

    def hold(name: str, status: str, reason: str) -> None:
        e = est[name]
        e.status, e.reason, e.advice = status, reason, ADVICE[name]
        free.remove(name)
        lm = next((lm for lm, s_ in PARTNER.items() if s_ == name), None)
        if lm is not None and lm in free and status == "not identifiable":
            far = _beyond_travel(lm, sets, sv)
            hold(lm, "not identifiable", f"{name} is not identifiable: its length scale neither"
                 + (f" ({far})" if far else ""))

    # -- 2. identifiability from the expected information at the start (the design) ---------
    t0 = reml_terms(sets, sv, free)
    loglik_start = t0.loglik
    F0 = dict(zip(free, np.diag(t0.fisher)))
    ref = max(max(F0.values(), default=1.0), 1.0)
    full = list(free)
    for name in list(free):
        if F0[name] < NO_SENSITIVITY * ref and name in free:
            hold(name, "not identifiable", _why_insensitive(name, sets, sv))
    while free:
        idx = [full.index(n) for n in free]
        F = t0.fisher[np.ix_(idx, idx)]
        w, V = np.linalg.eigh(F)
        if w[0] <= 1e-10 * max(w[-1], 1e-300):
            j = int(np.argmax(np.abs(V[:, 0])))
            hold(free[j], "not identifiable", "a flat direction of the likelihood at the task's values: "
                 + _why_weak(free[j], sets, None, free, sv))
            continue
        cov = np.linalg.inv(F)
        u_log = np.sqrt(np.diag(cov))
        j = int(np.argmax(u_log))
        if u_log[j] <= u_log_max:
            break
        row = _corr(cov)[j].copy()
        row[j] = 0.0
        name = free[j]
        hold(name, "not identifiable",
             f"u(log) = {u_log[j]:.2f} expected from these records at the task's values (above {u_log_max:g}): "
             + _why_weak(name, sets, row, free, sv))

    # -- 3./4. the fit -------------------------------------------------------------------------
    iterations = 0
    values = dict(sv)
    cov = np.zeros((0, 0))
    while free:
        box = bounds(sets, sv, free)
        phi, t, it = maximize(sets, sv, free, box)
        iterations += it
        values = _values(sv, free, phi)
        zero = [n for n, x, lo in zip(free, phi, box.lo) if not n.startswith("lambda") and x <= lo + 1e-6]
        if zero:
            for n in zero:
                hold(n, "zero", f"the likelihood is largest at {n} -> 0: these records show none of this factor "
                                f"(below {ZERO_SHARE:g} x the task's value)")
                sv[n] = values[n] = 0.0
                lm = next((lm for lm, s_ in PARTNER.items() if s_ == n), None)
                if lm is not None:
                    if lm in free:
                        free.remove(lm)
                    est[lm].status, est[lm].reason = "off", f"{n} is zero: its length scale plays no part"
                    sv[lm] = values[lm] = 0.0
            for n in free:
                sv[n] = values[n]
            continue
        H = observed_information(sets, values, free)
        w, V = np.linalg.eigh(H)
        if w[0] <= 1e-10 * max(w[-1], 1e-300):
            j = int(np.argmax(np.abs(V[:, 0])))
            bad, u_txt, row = j, "a flat direction of the likelihood at the estimate", None
        else:
            cov = np.linalg.inv(H)
            u_log = np.sqrt(np.diag(cov))
            bad = int(np.argmax(u_log))
            if u_log[bad] <= 2 * u_log_max:
                break
            row = _corr(cov)[bad].copy()
            row[bad] = 0.0
            u_txt = f"u(log) = {u_log[bad]:.2f} from the observed information at the estimate (above {2 * u_log_max:g})"
        name = free[bad]
        hold(name, "not identifiable", u_txt + ": " + _why_weak(name, sets, row, free, values))
        for n in free:
            sv[n] = values[n]          # warm start for the refit without it
        sv[name] = values[name] = est[name].start
    for k, name in enumerate(free):
        e = est[name]
        e.value = values[name]
        e.u_log = float(math.sqrt(cov[k, k]))
        e.u = e.value * e.u_log
    fitted = {}
    for n, e in est.items():
        if e.status == "estimated":
            fitted[n] = e.value
        elif e.status in ("zero", "off"):
            fitted[n] = e.value = 0.0 if e.status == "zero" or sv[n] == 0.0 else e.start
        else:
            fitted[n] = e.value = e.start
    params = pc.Parameters(**fitted)
    tf = reml_terms(sets, fitted, [], fisher=False)
    for n, e in est.items():
        if e.status == "zero":
            e.upper = upper_limit(sets, fitted, list(free), n, e.start, tf.loglik,
                                  {lm: est[lm].start for lm, s_ in PARTNER.items() if s_ == n})
            e.reason += f"; upper 95 % limit {e.upper:.3g} {e.unit} (REML profile)"
    return Calibration(est, params, start, list(free), cov if free else np.zeros((0, 0)), tf.loglik,
                       loglik_start, tf.chi2, tf.dof, iterations, sets)


def upper_limit(sets: list[RecordSet], values: dict[str, float], free: list[str], name: str, start: float,
                loglik_max: float, lam: dict[str, float], drop: float = UPPER_DROP, steps: int = 14) -> float:
    """Upper one-sided 95 % limit of a standard deviation whose REML estimate is zero: where its
    profile log-likelihood (the estimated parameters re-optimized, its length scale at ``lam``) has
    fallen by ``drop`` from the maximum at zero; bisection in log between ZERO_SHARE x start and
    1e3 x start (the upper end when the profile stays above)."""
    base = dict(values)
    base.update(lam)

    def prof(x: float) -> float:
        v = dict(base)
        v[name] = math.exp(x)
        if not free:
            return reml_terms(sets, v, [], fisher=False).loglik
        box = bounds(sets, v, free)
        box.lo = np.minimum(box.lo, np.log([v[n] for n in free]) - 3)
        _, t, _ = maximize(sets, v, free, box, max_iter=15, tol=1e-4)
        return t.loglik

    lo, hi = math.log(start * ZERO_SHARE), math.log(start * 1e3)
    target = loglik_max - drop
    if prof(hi) >= target:
        return math.exp(hi)
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if prof(mid) >= target:
            lo = mid
        else:
            hi = mid
    return math.exp(hi)


# ---------------------------------------------------------------------------------------------
# what the fit gives: residuals, profile, MPE check
# ---------------------------------------------------------------------------------------------

def standardized_residuals(s: RecordSet, params: pc.Parameters) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """GLS residual e = r - X beta (µm), its standard uncertainty sqrt(diag(C - X cov(beta) X^T))
    and z = e/u, with C the fitted model's covariance."""
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
    if name not in cal.free:
        raise ModelError(f"{name} was not estimated")
    k = cal.free.index(name)
    centre = math.log(cal.estimates[name].value)
    u = math.sqrt(cal.cov_log[k, k])
    others = [n for n in cal.free if n != name]
    base = {n: float(getattr(cal.params, n)) for n in NAMES}
    grid = centre + np.linspace(-width, width, points) * u
    out = []
    for x in grid:
        v = dict(base)
        v[name] = math.exp(x)
        if others:
            box = bounds(cal.sets, v, others)
            box.lo = np.minimum(box.lo, np.log([v[n] for n in others]) - 3)
            _, t, _ = maximize(cal.sets, v, others, box, max_iter=20, tol=1e-5)
            ll = t.loglik
        else:
            ll = reml_terms(cal.sets, v, [], fisher=False).loglik
        out.append(ll)
    return {"name": name, "unit": UNIT[name], "value": np.exp(grid).tolist(),
            "delta_loglik": (np.array(out) - cal.loglik).tolist()}


def mpe_consistency(params: pc.Parameters, A_um: float, B_mm: float, K: float, P_mm: float,
                    L_max_mm: float, cal: Calibration | None = None, n_grid: int = 201) -> dict:
    """E_L,MPE = A + L/B against the fitted model's C(d) = K u(d)/(A + d/B) (Forbes 2025 eq. 36,
    u(d) of eq. 33): C_max, where, the margin 1 - C_max and, with ``cal``, u(C_max) from the
    covariance of the estimates (delta method in log)."""
    chk = pc.mpe_check(params, A_um, B_mm, K, P_mm, L_max_mm, n_grid)
    d = L_max_mm * np.arange(n_grid) / (n_grid - 1)
    c = pc.C_of_d(d, params, A_um, B_mm, K, P_mm)
    u_c = None
    if cal is not None and cal.free:
        g = np.zeros(len(cal.free))
        h = 1e-5
        for a, name in enumerate(cal.free):
            vals = {n: float(getattr(params, n)) for n in NAMES}
            hi, lo = dict(vals), dict(vals)
            hi[name] *= math.exp(h)
            lo[name] *= math.exp(-h)
            g[a] = (pc.C_of_d(chk.d_at_max_mm, pc.Parameters(**hi), A_um, B_mm, K, P_mm)
                    - pc.C_of_d(chk.d_at_max_mm, pc.Parameters(**lo), A_um, B_mm, K, P_mm)) / (2 * h)
        u_c = float(math.sqrt(max(g @ cal.cov_log @ g, 0.0)))
    return {"A_um": A_um, "B_mm": B_mm, "K": K, "P_mm": P_mm, "L_max_mm": L_max_mm,
            "C_max": chk.C_max, "u_C_max": u_c, "d_at_max_mm": chk.d_at_max_mm,
            "margin": 1.0 - chk.C_max, "conforms": chk.conforms,
            "d_mm": d.tolist(), "C": c.tolist()}


def gls_fit(s: RecordSet, params: pc.Parameters, y: np.ndarray | None = None,
            X: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float, int]:
    """GLS of ``y`` (default: the records' residual) on ``X`` (default: the set's fixed effects)
    with the covariance of ``params``: (beta, cov(beta), chi2, dof).  The fixed-effect estimates
    at the fitted hyper-parameters and the chi-square of the records against a model."""
    values = {n: float(getattr(params, n)) for n in NAMES}
    C, _ = s.op.evaluate(values, [])
    y = s.y if y is None else y
    X = s.X if X is None else X
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
