"""Mismatch locator: do the recordings agree with the simulation, where not, and which physics
was left out (``docs/recordings.md`` sections 2-6).

The simulation predicts ``measured = reference`` (length records) or ``measured = nominal`` after
a rigid alignment (point records), with the covariance C of the records built from the Forbes 2025
point-cloud model V_X (eq. 28) of the task's hyper-parameters:

* length records: C = G V_X G^T with G the distance sensitivities of eq. (29) (g = [-n; n]),
  evaluated factor by factor in kernel form (:func:`length_covariance`): every entry involves
  only the four point pairs of two records, so V_X (6n x 6n for n records) is never formed;
* point records: C = V_X of the measured points (:func:`xlfuncs.pointcloud.V_X`), restricted to
  x, y in 2-D data.

Then (docs/recordings.md section 3):

1. chi-square of the residuals against C (GLS, alignment projected out for points), p-value,
   ``mismatch = p < alpha``;
2. standardized residuals of the records; chi-square of groups of records (``group``, probe,
   uni/bidirectional probing, direction, temperature and time bands);
3. forward selection over the candidate effects of :mod:`xlfuncs.effects` by generalized least
   squares: the likelihood-ratio statistic of adding a candidate is the drop of chi-square
   (Δχ², C known), its p-value the chi-square tail with df = parameters added; the best candidate
   is added while its Bonferroni-adjusted p-value (times the number of candidates tested in that
   step) is below alpha.  Candidates without sensitivity, absorbed by the alignment, or aliased
   (largest canonical correlation above 0.98 after projecting out the alignment and the other
   chosen effects) are reported, never chosen; among exact aliases the first in the table wins;
4. the refit with the chosen effects: estimates, standard uncertainties (GLS covariance),
   chi-square and RMS before and after.

Second edition (docs/recordings.md section 7, docs/diagnose.md section 6): two gates (omnibus or
targeted, alpha/2 each), single-record outliers as candidates of the search (left out by their
own mean-shift columns), ``p_after``/``explained`` and where the rest concentrates, and the noise
level (the search repeated with F-tests when the refit is not explained).

numpy only; the chi-square tail is the regularized incomplete gamma function (series and
continued fraction), in logarithms so that p-values far below 1e-308 still rank.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import effects as fx
from . import pointcloud as pc
from .errors import ModelError
from .recordings import LengthRecords, PointRecords, RecordingsError

ALIAS_CORR = 0.98           # docs/recordings.md section 3.3
EXACT_ALIAS = 1.0 - 1e-5    # "exact" aliases: canonical correlation 1 up to the noise of indicated
                            # coordinates (µm in hundreds of mm) that the columns are built from
DEPENDENT = 1e-6            # a column whose projected norm is below this share is dependent
MAX_STEPS = 12


# ---------------------------------------------------------------------------------------------
# chi-square tail (numpy/math only)
# ---------------------------------------------------------------------------------------------

def _log_gammaincc(a: float, x: float) -> float:
    """log Q(a, x), the regularized upper incomplete gamma function (a > 0, x >= 0)."""
    if x <= 0.0:
        return 0.0
    log_pref = -x + a * math.log(x) - math.lgamma(a)
    eps = 1e-16
    if x < a + 1.0:
        ap, term, total = a, 1.0 / a, 1.0 / a
        for _ in range(100000):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * eps:
                break
        P = total * math.exp(log_pref)
        return math.log1p(-min(P, 1.0)) if P < 1.0 else -math.inf
    tiny = 1e-300
    b = x + 1.0 - a
    c = 1.0 / tiny
    d = 1.0 / b
    h = d
    for i in range(1, 100000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        if abs(d) < tiny:
            d = tiny
        c = b + an / c
        if abs(c) < tiny:
            c = tiny
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < eps:
            break
    return log_pref + math.log(h)


def chi2_logsf(x: float, df: float) -> float:
    """Natural log of the chi-square survival function P(X > x), X ~ chi2(df)."""
    if df <= 0:
        raise ModelError("chi-square needs a positive number of degrees of freedom")
    if not math.isfinite(x):
        return -math.inf
    return _log_gammaincc(0.5 * df, 0.5 * max(x, 0.0))


def chi2_sf(x: float, df: float) -> float:
    """P(X > x) for X ~ chi2(df) (0.0 below 1e-308)."""
    return math.exp(chi2_logsf(x, df))


def _betacf(a: float, b: float, x: float) -> float:
    """Continued fraction of the incomplete beta function (modified Lentz)."""
    tiny, eps = 1e-300, 1e-16
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > tiny else tiny)
    h = d
    for m in range(1, 100000):
        m2 = 2 * m
        aa = m * (b - m) * x / ((qam + m2) * (a + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        h *= d * c
        aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))
        d = 1.0 + aa * d
        d = 1.0 / (d if abs(d) > tiny else tiny)
        c = 1.0 + aa / c
        c = c if abs(c) > tiny else tiny
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < eps:
            break
    return h


def _log_betainc(a: float, b: float, x: float) -> float:
    """log I_x(a, b), the regularized incomplete beta function."""
    if x <= 0.0:
        return -math.inf
    if x >= 1.0:
        return 0.0
    log_front = a * math.log(x) + b * math.log1p(-x) - (math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b))
    if x < (a + 1.0) / (a + b + 2.0):
        return log_front + math.log(_betacf(a, b, x)) - math.log(a)
    v = math.exp(log_front + math.log(_betacf(b, a, 1.0 - x)) - math.log(b))
    return math.log1p(-v) if v < 1.0 else -math.inf


def f_logcdf(F: float, d1: float, d2: float) -> float:
    """Natural log of P(X <= F), X ~ F(d1, d2)."""
    if d1 <= 0 or d2 <= 0:
        raise ModelError("the F distribution needs positive degrees of freedom")
    if F <= 0.0:
        return -math.inf
    if not math.isfinite(F):
        return 0.0
    return _log_betainc(0.5 * d1, 0.5 * d2, d1 * F / (d1 * F + d2))


def f_logsf(F: float, d1: float, d2: float) -> float:
    """Natural log of P(X > F), X ~ F(d1, d2) (the test of an effect when the scale of the
    covariance is estimated from the residual: docs/recordings.md section 7, noise level)."""
    if d1 <= 0 or d2 <= 0:
        raise ModelError("the F distribution needs positive degrees of freedom")
    if not math.isfinite(F):
        return -math.inf
    if F <= 0.0:
        return 0.0
    return _log_betainc(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * F))


# ---------------------------------------------------------------------------------------------
# the model of the simulation, the probes, the design
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Model:
    """What the recordings are compared with: the task's ``[parameters]`` and ``[[probes]]``
    (``probes_given`` False when the task has no ``[[probes]]``: every probe then uses the
    task-wide parameters and the offsets of the records, or zero)."""

    params: pc.Parameters
    probes: tuple[pc.Probe, ...] = (pc.Probe("P1"),)
    probes_given: bool = False


def _probe_label(p: np.ndarray, model: Model) -> str:
    for pr in model.probes:
        if np.max(np.abs(np.asarray(pr.offset_mm) - p)) <= 1e-6 and model.probes_given:
            return pr.id
    return "p(" + ",".join(f"{v:g}" for v in p) + ")"


def resolve_probes(rec, model: Model):
    """Probe id of every probing (per end for lengths), probe ids in file order, the Probe
    objects (offset + per-probe sigmas) and whether offsets are known.

    Returns ``(ids_per_end, probe_ids, probes, offsets_given)`` where ``ids_per_end`` is a list
    of tuples (one per end for lengths, one for points)."""
    if isinstance(rec, LengthRecords):
        label_cols = (rec.probe1, rec.probe2) if rec.probe1 is not None else None
        P_cols = (rec.P1_mm, rec.P2_mm) if rec.P1_mm is not None else None
        colnames = ("probe1", "probe2")
    else:
        label_cols = (rec.probe,) if rec.probe is not None else None
        P_cols = (rec.P_mm,) if rec.P_mm is not None else None
        colnames = ("probe",)
    n = rec.n
    if label_cols is not None:
        ids_per_end = [tuple(c) for c in label_cols]
    elif P_cols is not None:
        ids_per_end = [tuple(_probe_label(P[a], model) for a in range(n)) for P in P_cols]
    else:
        if model.probes_given and len(model.probes) > 1:
            raise RecordingsError(
                "the task defines several probes but the records name none: add the column"
                + ("s probe1,probe2" if len(colnames) == 2 else " probe"), rec.lines[0])
        ids_per_end = [(model.probes[0].id,) * n for _ in colnames]
    order: list[str] = []
    for a in range(n):
        for ids in ids_per_end:
            if ids[a] not in order:
                order.append(ids[a])
    task = {p.id: p for p in model.probes}
    if model.probes_given and label_cols is not None:
        for a in range(n):
            for ids, col in zip(ids_per_end, colnames):
                if ids[a] not in task:
                    raise RecordingsError(f"unknown probe {ids[a]!r} (the task defines "
                                          f"{', '.join(p.id for p in model.probes)})", rec.lines[a], col)
    probes = []
    for pid in order:
        if P_cols is not None:
            a, e = next((a, e) for a in range(n) for e, ids in enumerate(ids_per_end) if ids[a] == pid)
            off = tuple(float(v) for v in P_cols[e][a])
        elif pid in task:
            off = tuple(task[pid].offset_mm)
        else:
            off = (0.0, 0.0, 0.0)
        base = task.get(pid, pc.Probe(pid))
        probes.append(pc.Probe(pid, off, base.sigma_PQ_um, base.sigma_P0_um, base.sigma_P_um, base.lambda_P))
    offsets_given = P_cols is not None or model.probes_given
    try:
        for p in probes:
            p.resolved(model.params)
    except ModelError as e:
        raise ModelError(f"[[probes]]: {e}") from None
    return ids_per_end, tuple(order), tuple(probes), offsets_given


@dataclass
class Prepared:
    """Records turned into the linear model r = A theta + X beta + e, e ~ N(0, C)."""

    rec: LengthRecords | PointRecords
    design: fx.Design
    cloud: pc.PointCloud
    r_um: np.ndarray                 # residual vector (n_obs)
    C: np.ndarray                    # covariance (µm²)
    A: np.ndarray                    # baseline columns (n_obs x p0), alignment of point records
    A_labels: list[str]
    obs_record: np.ndarray           # record index of every observation row
    obs_axis: np.ndarray             # axis of every row (points), -1 for lengths
    ends: tuple[np.ndarray, np.ndarray] | None = None   # unique-point index of the two ends
    R0: np.ndarray | None = None     # initial alignment (Kabsch): Y = R0 x_nom + t0
    t0: np.ndarray | None = None


def _unique_probings(rec: LengthRecords, k1: np.ndarray, k2: np.ndarray):
    """Ends with identical coordinates, normal and probe are one probing (docs/recordings.md section 6)."""
    N1 = rec.N1 if rec.N1 is not None else np.zeros_like(rec.X1_mm)
    N2 = rec.N2 if rec.N2 is not None else np.zeros_like(rec.X2_mm)
    keys: dict[tuple, int] = {}
    X, N, K = [], [], []
    idx = np.empty((2, rec.n), dtype=int)
    for e, (Xe, Ne, ke) in enumerate(((rec.X1_mm, N1, k1), (rec.X2_mm, N2, k2))):
        for a in range(rec.n):
            key = (*Xe[a].tolist(), *Ne[a].tolist(), int(ke[a]))
            q = keys.get(key)
            if q is None:
                q = keys[key] = len(X)
                X.append(Xe[a])
                N.append(Ne[a])
                K.append(int(ke[a]))
            idx[e, a] = q
    pairs: dict[tuple[int, int], int] = {}
    for a in range(rec.n):
        key = tuple(sorted((int(idx[0, a]), int(idx[1, a]))))
        if key in pairs:
            b = pairs[key]
            if abs(rec.measured_mm[a] - rec.measured_mm[b]) > 1e-9 or abs(rec.reference_mm[a] - rec.reference_mm[b]) > 1e-9:
                raise RecordingsError(
                    f"records {rec.ids[b]!r} (line {rec.lines[b]}) and {rec.ids[a]!r} have the same two "
                    "probings (identical coordinates, normals and probes: one probing each, spec "
                    "section 6) but different lengths; give the indicated coordinates of every repeat",
                    rec.lines[a], "x1")
        else:
            pairs[key] = a
    return np.array(X), np.array(N), np.array(K, dtype=int), idx[0], idx[1]


def kabsch(X_nom: np.ndarray, X: np.ndarray, planar: bool) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid transform with X ~ R X_nom + t (rotation about z only for 2-D data)."""
    a0, b0 = X_nom.mean(axis=0), X.mean(axis=0)
    A, B = X_nom - a0, X - b0
    if planar:
        s = np.sum(A[:, 0] * B[:, 1] - A[:, 1] * B[:, 0])
        c = np.sum(A[:, 0] * B[:, 0] + A[:, 1] * B[:, 1])
        th = math.atan2(s, c)
        R = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0.0, 0.0, 1.0]])
    else:
        H = A.T @ B
        U, _, Vt = np.linalg.svd(H)
        dsign = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
        R = Vt.T @ np.diag([1.0, 1.0, dsign]) @ U.T
    t = b0 - R @ a0
    return R, t


#: point records with more observations than this use the structured covariance
#: (:mod:`xlfuncs.structured`, C = D + U U^T never formed) unless asked otherwise
STRUCTURED_MIN_OBS = 6000


def uses_structured(rec: LengthRecords | PointRecords, model: Model, structured: bool | None = None) -> bool:
    """Whether :func:`prepare` takes the structured covariance for these records."""
    if isinstance(rec, LengthRecords):
        return False
    if structured is not None:
        return bool(structured)
    dims = 2 if rec.planar else 3
    return rec.n * dims > STRUCTURED_MIN_OBS and model.params.sigma_R_um > 0


def prepare(rec: LengthRecords | PointRecords, model: Model, structured: bool | None = None) -> Prepared:
    """The linear model of the records.  ``structured``: for point records, the covariance as the
    operator of :mod:`xlfuncs.structured` (True), dense (False), or dense up to
    ``STRUCTURED_MIN_OBS`` observations (None)."""
    ids_per_end, probe_ids, probes, offsets_given = resolve_probes(rec, model)
    index = {p: k for k, p in enumerate(probe_ids)}
    offsets = np.array([p.offset_mm for p in probes], dtype=float).reshape(-1, 3)
    T, t = rec.temperature_C, rec.time_s
    if isinstance(rec, LengthRecords):
        k1 = np.array([index[p] for p in ids_per_end[0]], dtype=int)
        k2 = np.array([index[p] for p in ids_per_end[1]], dtype=int)
        X, N, K, I, J = _unique_probings(rec, k1, k2)
        cloud = pc.PointCloud(X, N, K, probes, tuple(f"Q{q + 1}" for q in range(len(X))))
        P1, P2 = offsets[k1], offsets[k2]
        delta = rec.X2_mm - rec.X1_mm
        na = delta / np.linalg.norm(delta, axis=1)[:, None]
        design = fx.Design("length", probe_ids, offsets_given, T=T, t=t, na=na,
                           U1=rec.X1_mm - P1, U2=rec.X2_mm - P2, N1=rec.N1, N2=rec.N2, k1=k1, k2=k2,
                           P1=P1, P2=P2, ref=rec.reference_mm, extent_mm=float(np.max(rec.reference_mm)))
        C = length_covariance(cloud, model.params, I, J)
        n = rec.n
        return Prepared(rec, design, cloud, rec.residual_um.copy(), C, np.zeros((n, 0)), [],
                        np.arange(n), -np.ones(n, dtype=int), ends=(I, J))
    k = np.array([index[p] for p in ids_per_end[0]], dtype=int)
    planar = rec.planar
    dims = 2 if planar else 3
    R0, t0 = kabsch(rec.X_nom_mm, rec.X_mm, planar)
    Y = rec.X_nom_mm @ R0.T + t0
    P = offsets[k]
    c = Y.mean(axis=0)
    N = rec.N if rec.N is not None else np.zeros_like(rec.X_mm)
    design = fx.Design("point", probe_ids, offsets_given, T=T, t=t, Y=Y, U=Y - P, N=rec.N, k=k, P=P,
                       c=c, dims=dims,
                       extent_mm=float(np.max(np.linalg.norm(Y - c, axis=1))) or 1.0)
    cloud = pc.PointCloud(rec.X_mm, N, k, probes, tuple(rec.ids))
    if uses_structured(rec, model, structured):
        from .structured import StructuredCovariance

        C = StructuredCovariance(cloud, model.params, dims)
    else:
        V = pc.V_X(cloud, model.params)
        keep = np.array([3 * i + a for i in range(rec.n) for a in range(dims)])
        C = V[np.ix_(keep, keep)]
    r = ((rec.X_mm - Y)[:, :dims] * 1000.0).reshape(-1)
    A, labels = fx.alignment_columns(design)
    return Prepared(rec, design, cloud, r, C, A, labels, np.repeat(np.arange(rec.n), dims),
                    np.tile(np.arange(dims), rec.n), R0=R0, t0=t0)


# ---------------------------------------------------------------------------------------------
# covariance of length records: C = G V_X G^T in kernel form (Forbes 2025 eqs. 28-29)
# ---------------------------------------------------------------------------------------------

def _sqdist(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    d = np.einsum("ij,ij->i", A, A)[:, None] + np.einsum("ij,ij->i", B, B)[None, :] - 2.0 * A @ B.T
    return np.maximum(d, 0.0)


def length_covariance(cloud: pc.PointCloud, params: pc.Parameters, I: np.ndarray, J: np.ndarray,
                      *, components: bool = False):
    """Covariance (µm²) of the lengths d_a = ||x_J[a] - x_I[a]|| of the unique points of
    ``cloud``: Cov(d_a, d_b) = g_a^T V_X g_b with g_a = -n_a at I[a] and +n_a at J[a].

    Each factor of eq. (28) is a point kernel K(p, q) times a direction term, so
    Cov(d_a, d_b) = sum over the ends s of a and t of b of sign_s sign_t K(s_a, t_b) w_{a,s}.w_{b,t}
    with w = n_a (R, PQ, ET), w = n_a x p (ER, eq. 24) or w = n_a . n_point (P, eq. 26);
    scale/squareness is rank 7 (eq. 11).  Memory and time O(n^2 + m^2), m unique points."""
    X, U, N = cloud.X_mm, cloud.ram_mm, cloud.N
    kp = cloud.probe_index
    d = X[J] - X[I]
    na = d / np.linalg.norm(d, axis=1)[:, None]
    pa = pc.probe_arrays(cloud, params)
    NN = na @ na.T
    out: dict[str, np.ndarray] = {}

    def four(kern, WI=None, WJ=None) -> np.ndarray:
        """sum_{s,t} sign_s sign_t kern(s, t)[a, b] (W_s[a] . W_t[b]) over the ends s of record a
        and t of record b (W None: 1)."""
        total = np.zeros((len(I), len(I)))
        for s, ss, Ws in ((I, -1.0, WI), (J, 1.0, WJ)):
            for t_, st, Wt in ((I, -1.0, WI), (J, 1.0, WJ)):
                term = kern(s, t_)
                if Ws is not None:
                    term = term * (Ws @ Wt.T)
                total += ss * st * term
        return total

    def gather(K: np.ndarray):
        return lambda s, t_: K[np.ix_(s, t_)]

    # R (eq. 8): one probing, one repeatability draw
    out["R"] = params.sigma_R_um**2 * four(lambda s, t_: (s[:, None] == t_[None, :]).astype(float)) * NN
    # PQ (eq. 9)
    s = pa["sigma_PQ_um"]
    out["PQ"] = four(lambda a, b: (kp[a][:, None] == kp[b][None, :]) * np.outer(s[a], s[b])) * NN
    # S (eqs. 11-14): rank 7 at the ram positions
    du = U[J] - U[I]
    nx, ny, nz = na.T
    ux, uy, uz = du.T
    g7 = np.column_stack([nx * ux + ny * uy + nz * uz, nx * ux, ny * uy, nz * uz, nx * uy, nx * uz, ny * uz])
    out["S"] = (g7 * pc.V_S_diag_um_per_mm2(params)) @ g7.T
    D2 = None
    if params.sigma_ET_um > 0 or params.sigma_ER_urad > 0:
        D2 = _sqdist(U, U)
    # ET (eq. 21): independent axes
    if params.sigma_ET_um > 0:
        out["ET"] = params.sigma_ET_um**2 * four(gather(np.exp(-D2 / params.lambda_ET_mm**2))) * NN
    else:
        out["ET"] = np.zeros_like(NN)
    # ER (eq. 25): w = G_k^T n (= p x n; the common sign cancels)
    if params.sigma_ER_urad > 0:
        P = cloud.offsets_mm
        out["ER"] = (params.sigma_ER_urad * pc.MILLI) ** 2 * four(
            gather(np.exp(-D2 / params.lambda_ER_mm**2)), np.cross(na, P[I]), np.cross(na, P[J]))
    else:
        out["ER"] = np.zeros_like(NN)
    # P (eqs. 26-27): o = n_a . n_point, same probe only
    s0, sp, lam = pa["sigma_P0_um"], pa["sigma_P_um"], pa["lambda_P"]
    if np.any(s0 > 0) or np.any(sp > 0):
        same = kp[:, None] == kp[None, :]
        DN2 = _sqdist(N, N)
        with np.errstate(divide="ignore", invalid="ignore"):
            kern = np.where(np.outer(sp, sp) > 0, np.exp(-DN2 / np.outer(lam, lam)), 0.0)
        KP = same * (np.outer(s0, s0) + np.outer(sp, sp) * kern)
        out["P"] = four(gather(KP), np.einsum("ij,ij->i", na, N[I])[:, None],
                        np.einsum("ij,ij->i", na, N[J])[:, None])
    else:
        out["P"] = np.zeros_like(NN)
    if components:
        return out
    total = out["R"]
    for f in ("PQ", "S", "ET", "ER", "P"):
        total = total + out[f]
    return 0.5 * (total + total.T)


def length_covariance_dense(cloud: pc.PointCloud, params: pc.Parameters, I, J) -> np.ndarray:
    """Reference implementation: G V_X G^T with the dense V_X of eq. (28) (tests only)."""
    V = pc.V_X(cloud, params)
    d = cloud.X_mm[J] - cloud.X_mm[I]
    na = d / np.linalg.norm(d, axis=1)[:, None]
    G = np.zeros((len(I), 3 * cloud.m))
    for a in range(len(I)):
        G[a, 3 * I[a]:3 * I[a] + 3] -= na[a]
        G[a, 3 * J[a]:3 * J[a] + 3] += na[a]
    return G @ V @ G.T


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


def _orth(M: np.ndarray, ref_norms: np.ndarray | None = None, tol: float = DEPENDENT):
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


def _out(Q: np.ndarray, M: np.ndarray) -> np.ndarray:
    """M with the span of the orthonormal Q projected out."""
    return M - Q @ (Q.T @ M) if Q.shape[1] else M.copy()


def _cancorr(Qa: np.ndarray, Qb: np.ndarray) -> float:
    """Largest canonical correlation of two orthonormal column sets."""
    if Qa.shape[1] == 0 or Qb.shape[1] == 0:
        return 0.0
    return float(min(1.0, np.linalg.svd(Qa.T @ Qb, compute_uv=False)[0]))


# ---------------------------------------------------------------------------------------------
# the diagnosis
# ---------------------------------------------------------------------------------------------

@dataclass
class Candidate:
    name: str
    cols: fx.Columns | None = None
    kept: list[int] = field(default_factory=list)     # identifiable columns
    reason: str | None = None                         # not identifiable / aliased
    aliased_with: str | None = None
    status: str = "untested"                          # chosen | indicated | tested | aliased | not identifiable
    step: int | None = None
    delta_chi2: float | None = None
    df: int = 0
    logp: float | None = None
    p_adjusted: float | None = None


@dataclass
class Diagnosis:
    prep: Prepared
    alpha: float
    whitener: Whitener
    chi2_before: float
    dof_before: int
    logp_before: float
    mismatch: bool
    candidates: dict[str, Candidate]
    chosen: list[str]
    steps: list[list[dict]]
    X_sel: np.ndarray                 # baseline + chosen columns (n_obs x p)
    sel_labels: list[tuple[str, str]]  # (effect name or "alignment", parameter label)
    beta: np.ndarray
    cov_beta: np.ndarray
    beta0: np.ndarray                 # baseline-only estimates (alignment)
    chi2_after: float
    dof_after: int
    z_before: np.ndarray              # per observation row
    z_after: np.ndarray
    u_obs: np.ndarray                 # sqrt(diag C_e): standard uncertainty of each row's residual
    resid_before: np.ndarray          # r - A theta0
    resid_after: np.ndarray
    groups: list[dict]
    located: list[dict]
    summary: str = ""
    # second edition (docs/recordings.md section 7)
    logp_targeted: float = 0.0        # log of the Bonferroni-adjusted targeted p-value
    gate: str | None = None           # "omnibus", "targeted", "both" or None
    targeted_K: int = 0               # candidates of the targeted test
    logp_after: float = 0.0
    outlier_search: bool = False
    outliers_not_isolated: bool = False
    outliers: list[dict] = field(default_factory=list)
    noise_scale: dict | None = None
    groups_scaled: list[dict] = field(default_factory=list)
    groups_after: list[dict] = field(default_factory=list)   # only when not explained
    with_outliers: dict | None = None
    discrepancy: dict | None = None   # the last candidate, when not explained (xlfuncs/discrepancy.py)
    alpha_name: float = 0.0           # adjusted p a cause must beat to be named (section 7)
    indicated: list[dict] = field(default_factory=list)   # significant at alpha, not at alpha_name

    @property
    def explained(self) -> bool:
        """The remaining chi-square after the refit passes: p_after >= alpha (section 7)."""
        return bool(self.logp_after >= math.log(self.alpha))

    # -- derived ---------------------------------------------------------------------------
    @property
    def rms_before_um(self) -> float:
        return float(np.sqrt(np.mean(self.resid_before**2)))

    @property
    def rms_after_um(self) -> float:
        return float(np.sqrt(np.mean(self.resid_after**2)))

    def effect_rows(self, name: str) -> list[int]:
        return [q for q, (e, _) in enumerate(self.sel_labels) if e == name]

    def to_json(self) -> dict:
        return diagnosis_json(self)


def _group_labels(prep: Prepared) -> dict[str, list[str]]:
    """Labels of every record under each grouping of docs/recordings.md section 3.2."""
    rec, D = prep.rec, prep.design
    out: dict[str, list[str]] = {}
    if rec.group is not None:
        out["group"] = [g or "(none)" for g in rec.group]
    if len(D.probe_ids) > 1:
        if D.kind == "length":
            out["probe"] = [D.probe_ids[a] if a == b else f"{D.probe_ids[a]}-{D.probe_ids[b]}"
                            for a, b in zip(D.k1, D.k2)]
        else:
            out["probe"] = [D.probe_ids[k] for k in D.k]
    if D.kind == "length":
        if D.N1 is not None:
            o = np.einsum("ij,ij->i", D.na, D.N1) * np.einsum("ij,ij->i", D.na, D.N2)
            out["probing"] = ["bidirectional" if v < -0.25 else "unidirectional" if v > 0.25 else "other"
                              for v in o]
        out["direction"] = [direction_label(v) for v in D.na]
    for key, v, unit, scale in (("temperature", D.T, "°C", 1.0), ("time", D.t, "h", 1 / 3600.0)):
        if v is not None and np.ptp(v) > 1e-9:
            out[key] = band_labels(v * scale, unit)
    return {k: v for k, v in out.items() if len(set(v)) > 1}


def direction_label(v: np.ndarray) -> str:
    """'+x', '+x+y', '+x-y+z' ...: the axes with |component| > 0.2, first sign made positive."""
    comps = [(a, np.sign(v[a])) for a in range(3) if abs(v[a]) > 0.2]
    if not comps:
        return "other"
    s0 = comps[0][1]
    return "".join(("+" if s * s0 > 0 else "-") + fx.AXES[a] for a, s in comps)


def band_labels(v: np.ndarray, unit: str) -> list[str]:
    """Three bands (tertiles) of a quantity, labelled by their ranges."""
    edges = np.unique(np.quantile(v, [1 / 3, 2 / 3]))
    idx = np.searchsorted(edges, v, side="right")
    labels = []
    for b in range(len(edges) + 1):
        sel = v[idx == b]
        labels.append(f"{sel.min():.2f}–{sel.max():.2f} {unit}" if sel.size else "")
    return [labels[i] for i in idx]


def _psd_chi2(e: np.ndarray, C: np.ndarray) -> tuple[float, int]:
    lam, V = np.linalg.eigh(0.5 * (C + C.T))
    keep = lam > 1e-10 * max(lam.max(), 1e-300)
    w = (V[:, keep].T @ e) / np.sqrt(lam[keep])
    return float(w @ w), int(keep.sum())


def diagnose(rec: LengthRecords | PointRecords, model: Model, alpha: float = 0.01,
             structured: bool | None = None, alpha_name: float | None = None) -> Diagnosis:
    """The analysis of docs/recordings.md section 3 on validated recordings (``structured``: see
    :func:`prepare`; ``alpha_name``: see :func:`diagnose_prepared`)."""
    alpha_name = check_alphas(alpha, alpha_name)
    prep = prepare(rec, model, structured)
    return diagnose_prepared(prep, alpha, alpha_name)


#: a cause is named when its adjusted p-value is below alpha x NAME_SHARE (docs/recordings.md
#: section 7, "Naming a cause"): a mismatch is raised at alpha, a physical cause -- which sends
#: someone to the machine -- is held to a risk a hundred times smaller
NAME_SHARE = 0.01


def check_alphas(alpha: float, alpha_name: float | None) -> float:
    """Validate alpha and alpha_name (default alpha x NAME_SHARE); return alpha_name."""
    if not (0.0 < alpha < 1.0):
        raise ModelError(f"alpha must be between 0 and 1, got {alpha!r}")
    if alpha_name is None:
        return alpha * NAME_SHARE
    if not (0.0 < alpha_name <= alpha):
        raise ModelError(f"alpha_name must be above 0 and at most alpha ({alpha:g}), got {alpha_name!r}")
    return float(alpha_name)


def is_structured(prep: Prepared) -> bool:
    return not isinstance(prep.C, np.ndarray)


def _structured_whitener(prep: Prepared, names=None):
    """The Gram whitener of :mod:`xlfuncs.structured` on the residual, the alignment and the
    columns of every applicable candidate (or of ``names``), with the group Grams."""
    parts, where = [prep.r_um[:, None], prep.A], {}
    pos = 1 + prep.A.shape[1]
    for eff in fx.EFFECTS:
        if names is not None and eff.name not in names:
            continue
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
        for by, lab in _group_labels(prep).items():
            lab_obs = np.array([lab[a] for a in prep.obs_record], dtype=object)
            for g in dict.fromkeys(lab):
                groups[(by, g)] = np.flatnonzero(lab_obs == g)
    W = prep.C.whitener(B, groups)
    W.where = where
    return W


def diagnose_prepared(prep: Prepared, alpha: float = 0.01, alpha_name: float | None = None) -> Diagnosis:
    """Gates at alpha/2 each; the first effect named at adjusted p < alpha_name (default alpha/100),
    a best one between alpha_name and alpha reported as ``indicated``; further effects at alpha
    (docs/recordings.md section 7)."""
    alpha_name = check_alphas(alpha, alpha_name)
    W = _structured_whitener(prep) if is_structured(prep) else Whitener(prep.C)
    yw = W(prep.r_um)
    Aw = W(prep.A)
    Q0, keptA = _orth(Aw)
    rankA = len(keptA)
    y0 = _out(Q0, yw)
    chi2_before = float(y0 @ y0)
    dof_before = W.rank - rankA
    if dof_before < 1:
        raise ModelError("no degrees of freedom left after the alignment: more records are needed")
    logp_before = chi2_logsf(chi2_before, dof_before)

    # -- candidates: applicability, sensitivity, identifiability against the baseline --------
    cands: dict[str, Candidate] = {}
    white: dict[str, np.ndarray] = {}
    basis: dict[str, np.ndarray] = {}
    for eff in fx.EFFECTS:
        c = Candidate(eff.name)
        cands[eff.name] = c
        try:
            cols = fx.columns(prep.design, eff.name)
        except fx.NotApplicable as e:
            c.status, c.reason = "not identifiable", str(e)
            continue
        c.cols = cols
        big = np.max(np.abs(cols.X), axis=0) > fx.REL_ZERO * cols.full_scale
        if not np.any(big):
            c.status, c.reason = "not identifiable", "no sensitivity: " + _why_zero(prep, eff.name)
            continue
        Xw = W(cols.X)
        raw = np.linalg.norm(Xw, axis=0)
        Z = _out(Q0, Xw)
        Z[:, ~big] = 0.0
        Qc, kept = _orth(Z, raw)
        if not kept:
            c.status = "not identifiable"
            c.reason = ("absorbed by the rigid alignment of the point records" if prep.A.shape[1]
                        else "no sensitivity: " + _why_zero(prep, eff.name))
            continue
        c.kept = kept
        white[eff.name] = Xw
        basis[eff.name] = Qc
    identifiable = [n for n in fx.NAMES if cands[n].status == "untested"]

    # -- exact aliases: the first in the table stands for all of them ------------------------
    for i, a in enumerate(identifiable):
        if cands[a].status != "untested":
            continue
        for b in identifiable[i + 1:]:
            if cands[b].status != "untested":
                continue
            rho = _cancorr(basis[a], basis[b])
            if rho > EXACT_ALIAS:
                cb = cands[b]
                cb.status, cb.aliased_with = "aliased", a
                cb.reason = alias_reason(prep, b, a, rho)

    # -- the targeted gate (docs/recordings.md section 7): every identifiable candidate of the
    # first step, Bonferroni over them; omnibus and targeted share alpha (alpha/2 each) ---------
    first = _effect_rows(prep, W, Q0, Q0, y0, white, cands, identifiable, [], scaled=False)
    if first:
        K1 = len(first)
        logp_targeted = min(0.0, min(r["logp"] for r in first) + math.log(K1))
    else:
        logp_targeted = 0.0
    half = math.log(GATE_SHARE * alpha)
    omnibus, targeted = logp_before < half, logp_targeted < half
    gate = "both" if omnibus and targeted else "omnibus" if omnibus else "targeted" if targeted else None
    mismatch = gate is not None

    outlier_search = mismatch and outliers_searchable(prep, W)
    overflow = False
    noise = None
    kept_answer = None
    groups_scaled: list[dict] = []
    if mismatch:
        srch = _search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=outlier_search)
        overflow = srch.overflow
        if overflow:
            srch = _search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=False)
        fit = _refit(prep, W, keptA, srch)
        if fit[2] < math.log(alpha):
            # not explained: is the rest uniformly larger than the simulation allows, with no
            # structure any candidate or group explains?  The same search with the scale of the
            # covariance estimated (F-tests), then the groups against the scaled covariance
            sc = _search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=outlier_search,
                         scaled=True)
            if sc.overflow:
                sc = _search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=False, scaled=True)
            sfit = _refit(prep, W, keptA, sc)
            beta_s, cov_s, chi2_s, dof_s = sfit[3], sfit[4], sfit[0], sfit[1]
            if dof_s >= 1:
                s2 = chi2_s / dof_s
                groups_scaled = _groups_of(prep, W, sfit[5], beta_s, cov_s, labels_coef(prep, W, keptA, sc),
                                           alpha, scale2=s2, dof_scale=dof_s)
                if s2 > 1.0 and not any(g["flagged"] for g in groups_scaled):
                    noise = {"estimate": math.sqrt(s2), "u": math.sqrt(s2 / (2.0 * dof_s)),
                             "chi2": chi2_s, "dof": dof_s}
                    srch, fit = sc, sfit
        if srch.outliers:
            alt = _search(prep, W, Q0, y0, white, cands, identifiable, alpha, alpha_name, outliers=False,
                          scaled=noise is not None)
            afit = _refit(prep, W, keptA, alt)
            kept_answer = {"effects": list(alt.chosen), "chi2_after": afit[0], "dof_after": afit[1],
                           "p_after": math.exp(afit[2]), "explained": bool(afit[2] >= math.log(alpha))}
    else:
        srch = _Search({n: _copy_candidate(c) for n, c in cands.items()}, [], [], [], [], Q0, y0)
        for name in identifiable:
            srch.cands[name].status = "not tested"
    cands, chosen, steps = srch.cands, srch.chosen, srch.steps

    # -- refit: GLS with the alignment, the chosen effects and the outliers left out ----------
    chi2_after, dof_after, logp_after, beta, cov, X_sel, labels = _refit(prep, W, keptA, srch)
    beta0, cov0, _ = _gls(W, prep.A[:, keptA], prep.r_um)
    resid_before = prep.r_um - prep.A[:, keptA] @ beta0
    resid_after = prep.r_um - X_sel @ beta
    # standard uncertainty of each residual under the baseline (alignment projected out)
    A = prep.A[:, keptA]
    var = prep.C.diagonal() if is_structured(prep) else np.diag(prep.C).copy()
    if A.shape[1]:
        var = var - np.einsum("ij,jk,ik->i", A, cov0, A)
    u_obs = np.sqrt(np.maximum(var, 1e-30))
    diag = Diagnosis(prep=prep, alpha=alpha, whitener=W, chi2_before=chi2_before, dof_before=dof_before,
                     logp_before=logp_before, mismatch=mismatch, candidates=cands, chosen=chosen,
                     steps=steps, X_sel=X_sel, sel_labels=labels, beta=beta, cov_beta=cov, beta0=beta0,
                     chi2_after=chi2_after, dof_after=dof_after, z_before=resid_before / u_obs,
                     z_after=resid_after / u_obs, u_obs=u_obs, resid_before=resid_before,
                     resid_after=resid_after, groups=[], located=[])
    diag.logp_targeted, diag.gate, diag.targeted_K = logp_targeted, gate, len(first)
    diag.logp_after = logp_after
    diag.outlier_search = outlier_search
    diag.outliers_not_isolated = overflow
    diag.outliers = _outlier_report(diag, srch)
    diag.noise_scale = noise
    diag.groups_scaled = groups_scaled
    diag.with_outliers = kept_answer
    diag.alpha_name = alpha_name
    diag.indicated = _indicated_report(prep, W, keptA, srch)
    diag.groups = locate_groups(diag)
    diag.groups_after = (_groups_of(prep, W, X_sel, beta, cov, labels_coef(prep, W, keptA, srch), alpha,
                                    z=diag.z_after) if mismatch and not diag.explained else [])
    diag.located = locate_records(diag)
    if mismatch and not diag.explained:
        from . import discrepancy as disc   # section 7: the discrepancy, last, only when not explained
        diag.discrepancy = disc.fit(prep, W, X_sel, beta, alpha, chi2_after, dof_after, chi2_logsf, _gls,
                                    f_logsf if noise is not None else None)
        if noise is not None and diag.discrepancy and diag.discrepancy["chosen"]:
            diag.noise_scale = None        # a smooth structure, not a uniformly larger noise
    diag.summary = summary_text(diag)
    if diag.discrepancy:
        head = diag.summary.rstrip()
        diag.summary = (head + ("" if head.endswith(".") or not head else ".") + " "
                        + disc.sentence(diag.discrepancy)).strip()
    return diag


GATE_SHARE = 0.5           # each of the two gates judged at alpha/2 (docs/recordings.md section 7)
MAX_OUTLIER_SHARE = 0.03   # isolated outliers: at most this share of the records (and at least 2);
                           # when more look gross, it is a structure and no record is called an outlier
OUTLIER_MAX_OBS = 4000     # the outlier search needs the dense whitener (n_obs^2 numbers)


def outliers_searchable(prep: Prepared, W) -> bool:
    """Single-record outliers are searched with the dense whitener (W as a matrix)."""
    return isinstance(W, Whitener) and W.W.shape[1] <= OUTLIER_MAX_OBS


@dataclass
class _Search:
    cands: dict[str, Candidate]
    chosen: list[str]
    steps: list[list[dict]]
    outliers: list[int]              # record indices, in the order flagged
    outlier_rows: list[dict]         # their statistics when flagged
    Q: np.ndarray
    resid: np.ndarray
    outlier_cols: list[tuple[int, list[int]]] = field(default_factory=list)  # (record, kept rows)
    overflow: bool = False           # more records than MAX_OUTLIER_SHARE looked gross: structure
    indicated: list[str] = field(default_factory=list)   # best effect between alpha_name and alpha


def _copy_candidate(c: Candidate) -> Candidate:
    from dataclasses import replace

    return replace(c, kept=list(c.kept))


def _test_logp(dchi: float, df: int, rest: float, nu: int, scaled: bool) -> float | None:
    """log p of adding df columns that lower chi-square by dchi: chi-square with C known, or the
    F-test with the scale of C estimated from the rest (nu - df degrees of freedom)."""
    if not scaled:
        return chi2_logsf(dchi, df)
    d2 = nu - df
    if d2 < 1:
        return None
    rest_after = max(rest - dchi, 1e-300)
    return f_logsf((dchi / df) / (rest_after / d2), df, d2)


def _effect_rows(prep, W, Q0, Q, resid, white, cands, identifiable, chosen, scaled=False, mutate=False):
    """The candidates of one step: Δχ², df, log p for every contender (``mutate``: mark aliased)."""
    rows = []
    nu = W.rank - Q.shape[1]
    rest = float(resid @ resid)
    for name in identifiable:
        c = cands[name]
        if c.status not in ("untested", "tested"):
            continue
        Xk = white[name][:, c.kept]
        if chosen:
            alias = _alias_with_chosen(Q0, white, cands, chosen, name)
            if alias is not None:
                if mutate:
                    other, rho = alias
                    c.status, c.aliased_with = "aliased", other
                    c.reason = alias_reason(prep, name, other, rho)
                continue
        Z = _out(Q, Xk)
        Qz, kz = _orth(Z, np.linalg.norm(_out(Q0, Xk), axis=0))
        if not kz:
            if mutate:
                c.status, c.aliased_with = "aliased", " + ".join(chosen)
                c.reason = alias_reason(prep, name, " + ".join(chosen), 1.0)
            continue
        dchi = float(np.sum((Qz.T @ resid) ** 2))
        df = len(kz)
        logp = _test_logp(dchi, df, rest, nu, scaled)
        if logp is None:
            continue
        rows.append({"name": name, "df": df, "delta_chi2": dchi, "logp": logp, "kz": kz, "Qz": Qz})
    return rows


def _record_obs(prep: Prepared) -> list[np.ndarray]:
    n = prep.rec.n
    order = np.argsort(prep.obs_record, kind="stable")
    bounds = np.searchsorted(prep.obs_record[order], np.arange(n + 1))
    return [order[bounds[a]:bounds[a + 1]] for a in range(n)]


def _outlier_rows(prep, W, Q, resid, skip, scaled=False):
    """Likelihood-ratio test of a gross error in every single record (a point: its coordinates):
    the drop of chi-square when that record's own mean-shift columns are added (the record left
    out), with C known or (``scaled``) as an F-test.  Bonferroni over the records tested.  A
    column whose whitened remainder after Q is below 1e-3 of its norm is not testable."""
    Wm = W.W
    nu = W.rank - Q.shape[1]
    rest = float(resid @ resid)
    n = prep.rec.n
    d = len(prep.r_um) // n                      # observations per record (1, 2 or 3)
    todo = np.array([a for a in range(n) if a not in skip], dtype=int)
    rows = []
    chunk = max(1, 768 // d)
    for q0 in range(0, len(todo), chunk):
        recs = todo[q0:q0 + chunk]
        cols = (recs[:, None] * d + np.arange(d)[None, :]).reshape(-1)   # obs of record a: d*a + axis
        Wc = Wm[:, cols]
        Z = _out(Q, Wc)
        ok = np.linalg.norm(Z, axis=0) > 1e-3 * np.linalg.norm(Wc, axis=0)
        Z = Z * ok
        b = (Z.T @ resid).reshape(len(recs), d)
        Zr = Z.reshape(Z.shape[0], len(recs), d)
        G = np.einsum("kia,kib->iab", Zr, Zr)
        lam, V = np.linalg.eigh(G)
        keep = lam > 1e-9 * np.maximum(lam.max(axis=1, keepdims=True), 1e-300)
        proj = np.einsum("iab,ia->ib", V, b)
        dchis = np.sum(np.where(keep, proj**2 / np.where(keep, lam, 1.0), 0.0), axis=1)
        dfs = keep.sum(axis=1)
        for t, a in enumerate(recs):
            df = int(dfs[t])
            if df == 0:
                continue
            dchi = float(dchis[t])
            logp = _test_logp(dchi, df, rest, nu, scaled)
            if logp is None:
                continue
            rows.append({"record": int(a), "df": df, "delta_chi2": dchi, "logp": logp, "chunk": (Zr, t),
                         "rows": [int(d * a + j) for j in range(d) if ok.reshape(len(recs), d)[t, j]]})
    K = max(len(rows), 1)
    for r in rows:
        r["log_p_adjusted"] = min(0.0, r["logp"] + math.log(K))
    best = min(rows, key=lambda r: (r["log_p_adjusted"], r["record"])) if rows else None
    if best is not None:        # the orthonormal columns of the best one only
        Zr, t = best["chunk"]
        best["Qz"], _ = _orth(Zr[:, t, :])
    for r in rows:
        r.pop("chunk")
    return rows


def _search(prep, W, Q0, y0, white, cands_in, identifiable, alpha, alpha_name, *, outliers=False,
            scaled=False):
    """Forward selection (docs/recordings.md section 3.3 and section 7): in every step the best
    candidate effect (Bonferroni over the candidates of that step) and, with ``outliers``, the
    record whose gross error would lower chi-square most (Bonferroni over the records); the one
    with the smaller adjusted p-value is taken while that is below alpha -- the first effect only
    below alpha_name: one between alpha_name and alpha is ``indicated`` and the search stops.
    ``scaled``: F-tests with the scale of the covariance estimated from what remains (the
    noise-level answer)."""
    cands = {n: _copy_candidate(c) for n, c in cands_in.items()}
    S = _Search(cands, [], [], [], [], Q0, y0)
    order = {n: i for i, n in enumerate(fx.NAMES)}
    max_out = max(2, math.ceil(MAX_OUTLIER_SHARE * prep.rec.n))
    for step in range(1, MAX_STEPS + 1):
        rows = _effect_rows(prep, W, Q0, S.Q, S.resid, white, cands, identifiable, S.chosen, scaled,
                            mutate=True)
        out_rows = (_outlier_rows(prep, W, S.Q, S.resid, set(S.outliers), scaled)
                    if outliers and not S.overflow else [])
        if not rows and not out_rows:
            break
        best = None
        if rows:
            K = len(rows)
            for row in rows:
                row["log_p_adjusted"] = min(0.0, row["logp"] + math.log(K))
                c = cands[row["name"]]
                c.status, c.step = "tested", step
                c.delta_chi2, c.df, c.logp = row["delta_chi2"], row["df"], row["logp"]
                c.p_adjusted = math.exp(row["log_p_adjusted"])
            best = min(rows, key=lambda r: (r["logp"], -r["delta_chi2"], order[r["name"]]))
            # exact aliases given what is chosen already: the first in the table of section 4
            ties = [r for r in rows if order[r["name"]] < order[best["name"]]
                    and _cancorr(r["Qz"], best["Qz"]) > EXACT_ALIAS]
            if ties:
                best = min(ties, key=lambda r: order[r["name"]])
            S.steps.append([{k: v for k, v in r.items() if k not in ("kz", "Qz")} for r in rows])
        best_out = min(out_rows, key=lambda r: (r["log_p_adjusted"], r["record"])) if out_rows else None
        wants_out = best_out is not None and best_out["log_p_adjusted"] < math.log(alpha) and (
            best is None or best_out["log_p_adjusted"] <= best["log_p_adjusted"])
        if wants_out and len(S.outliers) >= max_out:
            # more gross records than isolated outliers can be: a structure, not outliers
            S.overflow, wants_out = True, False
            break
        if wants_out:
            # outliers before physics: the record is left out of the rest of the search
            S.outliers.append(best_out["record"])
            S.outlier_rows.append({k: v for k, v in best_out.items() if k != "Qz"} | {"step": step})
            best_out["rows"] = [q for q in best_out["rows"]]
            S.outlier_cols.append((best_out["record"], best_out["rows"]))
            S.Q = np.column_stack([S.Q, best_out["Qz"]])
            S.resid = _out(best_out["Qz"], S.resid)
        elif best is not None and best["log_p_adjusted"] < math.log(alpha):
            if S.outliers and not S.chosen and not _still_mismatch(W, S, best, alpha, scaled):
                break     # the outliers explain the mismatch: no gate opens for physics
            c = cands[best["name"]]
            if not S.chosen and best["log_p_adjusted"] >= math.log(alpha_name):
                # the first cause: significant, but not at the level a cause is named at --
                # indicated, not chosen (once one is named the records do differ, and further
                # effects are chosen at alpha as in section 3)
                c.status = "indicated"
                c.kept = [c.kept[j] for j in best["kz"]]
                S.indicated.append(best["name"])
                break
            c.status = "chosen"
            c.kept = [c.kept[j] for j in best["kz"]]
            S.chosen.append(best["name"])
            S.Q = np.column_stack([S.Q, best["Qz"]])
            S.resid = _out(best["Qz"], S.resid)
        else:
            break
        if W.rank - S.Q.shape[1] < 2:
            break
    for name in identifiable:
        if cands[name].status == "untested":
            cands[name].status = "not tested"
    return S


def _still_mismatch(W, S: _Search, best: dict, alpha: float, scaled: bool) -> bool:
    """With the outliers left out, do the records still disagree by the two gates (omnibus on
    what remains, or the best candidate of this step, alpha/2 each)?  (Scaled search: the
    targeted gate only, the omnibus has no meaning when the scale is estimated.)"""
    half = math.log(GATE_SHARE * alpha)
    if best["log_p_adjusted"] < half:
        return True
    nu = W.rank - S.Q.shape[1]
    return (not scaled) and nu > 0 and chi2_logsf(float(S.resid @ S.resid), nu) < half


def _refit(prep, W, keptA, S: _Search):
    """GLS with the alignment, the chosen effects and the outliers' mean-shift columns:
    (chi2, dof, log p, beta, cov, X_sel, labels)."""
    X_parts = [prep.A[:, keptA]]
    labels = [("alignment", prep.A_labels[j]) for j in keptA]
    for name in S.chosen:
        c = S.cands[name]
        X_parts.append(c.cols.X[:, c.kept])
        labels += [(name, c.cols.labels[j]) for j in c.kept]
    n_obs = len(prep.r_um)
    for a, rows in S.outlier_cols:
        E = np.zeros((n_obs, len(rows)))
        E[rows, np.arange(len(rows))] = 1.0
        X_parts.append(E)
        rid = prep.rec.ids[a]
        if prep.design.kind == "length":
            labels.append(("outlier", rid))
        else:
            labels += [("outlier", f"{rid}.{fx.AXES[int(prep.obs_axis[q])]}") for q in rows]
    X_sel = np.column_stack(X_parts) if X_parts else np.zeros((n_obs, 0))
    beta, cov, chi2 = _gls(W, X_sel, prep.r_um)
    dof = W.rank - X_sel.shape[1]
    logp = chi2_logsf(chi2, dof) if dof > 0 else 0.0
    return chi2, dof, logp, beta, cov, X_sel, labels


def labels_coef(prep, W, keptA, S: _Search):
    """X_sel of :func:`_refit` as combinations of the structured whitener's columns (None: dense)."""
    if not is_structured(prep):
        return None
    c = W.B.shape[1]
    cols = [1 + j for j in keptA]
    for name in S.chosen:
        cols += [W.where[name] + j for j in S.cands[name].kept]
    M = np.zeros((c, len(cols)))
    M[cols, np.arange(len(cols))] = 1.0
    return M


def _indicated_report(prep: Prepared, W, keptA, S: _Search) -> list[dict]:
    """``indicated`` of diagnosis.json: the effect the search found significant at alpha but not
    at alpha_name, with the estimate it would have in a refit with it (not applied)."""
    from dataclasses import replace

    out = []
    for name in S.indicated:
        c = S.cands[name]
        _, _, _, beta, cov, _, labels = _refit(prep, W, keptA, replace(S, chosen=S.chosen + [name]))
        out.append({"name": name, **_estimates(prep, c, labels, beta, cov), "unit": fx.BY_NAME[name].unit,
                    "delta_chi2": c.delta_chi2, "p_value": math.exp(c.logp), "p_adjusted": c.p_adjusted,
                    "df": c.df, "step": c.step})
    return out


def _outlier_report(diag: Diagnosis, S: _Search) -> list[dict]:
    """``outliers`` of diagnosis.json: id, residual (after the baseline), z and the adjusted
    p-value of the record's likelihood-ratio test when it was flagged, and the gross error
    estimated by the refit (µm; a point: per coordinate)."""
    prep = diag.prep
    out = []
    obs = _record_obs(prep)
    for a, row in zip(S.outliers, S.outlier_rows):
        rows = [q for q, (e, _) in enumerate(diag.sel_labels) if e == "outlier"
                and diag.sel_labels[q][1].split(".")[0] == prep.rec.ids[a]]
        if prep.design.kind == "point":
            rows = [q for q, (e, l) in enumerate(diag.sel_labels) if e == "outlier" and
                    l.rsplit(".", 1)[0] == prep.rec.ids[a]]
        e = diag.resid_before[obs[a]]
        est = [float(diag.beta[q]) for q in rows]
        unc = [float(math.sqrt(max(diag.cov_beta[q, q], 0.0))) for q in rows]
        item = {"id": prep.rec.ids[a], "residual_um": float(e[0]) if len(e) == 1 else float(np.linalg.norm(e)),
                "z": math.copysign(math.sqrt(row["delta_chi2"]), float(e[0])) if len(e) == 1
                else math.sqrt(row["delta_chi2"]),
                "p_adjusted": math.exp(row["log_p_adjusted"]), "p_value": math.exp(row["logp"]),
                "df": row["df"], "step": row["step"],
                "estimate_um": est[0] if len(est) == 1 and prep.design.kind == "length" else est,
                "u_um": unc[0] if len(unc) == 1 and prep.design.kind == "length" else unc}
        if prep.design.kind == "point":
            item["axes"] = [diag.sel_labels[q][1].rsplit(".", 1)[1] for q in rows]
        out.append(item)
    return out


def _gls(W: Whitener, X: np.ndarray, r: np.ndarray):
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


def _alias_with_chosen(Q0, white, cands, chosen, name):
    """(chosen effect, canonical correlation) when ``name`` is aliased (> 0.98) with one chosen
    effect after projecting out the alignment and the other chosen effects, or with all of them
    together after projecting out the alignment."""
    if not chosen:
        return None
    Xc = white[name][:, cands[name].kept]
    best = (None, 0.0)
    for e in chosen:
        others = [white[o][:, cands[o].kept] for o in chosen if o != e]
        Qo = Q0
        if others:
            Qo, _ = _orth(np.column_stack([Q0, *others]))
        Qa, _ = _orth(_out(Qo, Xc), np.linalg.norm(_out(Q0, Xc), axis=0))
        Qb, _ = _orth(_out(Qo, white[e][:, cands[e].kept]))
        rho = _cancorr(Qa, Qb) if Qa.shape[1] else 1.0
        if rho > best[1]:
            best = (e, rho)
    if len(chosen) > 1:
        Qa, _ = _orth(_out(Q0, Xc))
        Qb, _ = _orth(_out(Q0, np.column_stack([white[o][:, cands[o].kept] for o in chosen])))
        rho = _cancorr(Qa, Qb)
        if rho > ALIAS_CORR and rho > best[1] + 1e-9:
            best = (" + ".join(chosen), rho)
    return best if best[1] > ALIAS_CORR else None


def _why_zero(prep: Prepared, name: str) -> str:
    D = prep.design
    if name.startswith("scale_") and name[-1] in fx.AXES:
        return f"the records do not extend along {name[-1]}"
    if name.startswith("squareness_"):
        return f"no record extends along both {name[-2]} and {name[-1]} (diagonals in that plane)"
    if name == "probe_qualification":
        return ("every length is probed with one probe at both ends, so a probe offset error cancels"
                if D.kind == "length" else "the probes' offsets cancel in these records")
    if name in fx.ANGULAR:
        return (f"the probe offsets are parallel to the rotation axis of {name} or the {name[2]} "
                "carriage does not move")
    if name == "probe_radius":
        return "every length is probed in one direction at both ends (unidirectional), so a radius error cancels"
    return "these records do not respond to it"


def alias_reason(prep: Prepared, name: str, other: str, rho: float) -> str:
    """'aliased with scale_x (canonical correlation 1.000000): one probe offset only; a second
    probe offset would separate them (Forbes 2025 section 3.3)'."""
    D = prep.design
    a, b = fx.BY_NAME.get(name), fx.BY_NAME.get(other.split(" + ")[0])
    why = ""
    hint = a.hint if a is not None else ""
    pair = {name, *other.split(" + ")}
    n_offsets = len({tuple(np.round(p, 6)) for p in (np.vstack([D.P1, D.P2]) if D.kind == "length" else D.P)})
    if pair & set(fx.ANGULAR):
        if n_offsets == 1:
            why = "one probe offset only; "
        hint = fx.BY_NAME["EAX"].hint
    elif "thermal_expansion" in pair:
        why = "the temperatures do not vary enough; "
        hint = fx.BY_NAME["thermal_expansion"].hint
    elif pair & {"scale_drift", "offset_drift"}:
        why = "time order follows length or position; "
        hint = fx.BY_NAME["scale_drift"].hint
    elif "probe_radius" in pair or "probe_qualification" in pair:
        hint = fx.BY_NAME["probe_radius"].hint if "probe_radius" in pair else fx.BY_NAME["probe_qualification"].hint
    elif b is not None and b.hint:
        hint = a.hint if a is not None else b.hint
    return (f"aliased with {other} (canonical correlation {rho:.6f}): {why}these records cannot tell "
            f"them apart; {hint} would separate them")


def locate_records(diag: Diagnosis, top: int = 10) -> list[dict]:
    """Records with the largest |z| (points: Mahalanobis length of the point's residual)."""
    prep = diag.prep
    rec = prep.rec
    if prep.design.kind == "length":
        z = diag.z_before
        order = np.argsort(-np.abs(z), kind="stable")[:top]
        return [{"id": rec.ids[a], "residual_um": float(diag.resid_before[a]), "z": float(z[a])} for a in order]
    dims = prep.design.dims
    e = diag.resid_before.reshape(rec.n, dims)
    zc = diag.z_before.reshape(rec.n, dims)
    # Mahalanobis length with the baseline-adjusted covariance of the point's coordinates
    A = prep.A
    cov0 = _gls(diag.whitener, A, prep.r_um)[1] if A.shape[1] else None
    zm = np.empty(rec.n)
    blocks = prep.C.point_blocks() if is_structured(prep) else None
    for i in range(rec.n):
        sl = slice(dims * i, dims * i + dims)
        B = blocks[i] if blocks is not None else prep.C[sl, sl]
        if cov0 is not None:
            B = B - A[sl] @ cov0 @ A[sl].T
        zm[i] = math.sqrt(_psd_chi2(e[i], B)[0])
    order = np.argsort(-zm, kind="stable")[:top]
    return [{"id": rec.ids[i], "residual_um": float(np.linalg.norm(e[i])), "z": float(zm[i]),
             "residual_xyz_um": [float(v) for v in e[i]], "z_xyz": [float(v) for v in zc[i]]}
            for i in order]


def _groups_of(prep: Prepared, W, X: np.ndarray, beta: np.ndarray, cov: np.ndarray, X_coef, alpha: float,
               *, scale2: float = 1.0, dof_scale: int | None = None, z: np.ndarray | None = None) -> list[dict]:
    """Chi-square of the records of every group (section 3.2 groupings) for the residual
    e = r - X beta of a GLS fit, with the covariance of that residual, C - X cov X'.  With
    ``dof_scale``: judged against the covariance scaled by ``scale2`` (estimated on dof_scale
    degrees of freedom), an F-test; flagged when p < alpha / (number of groups)."""
    labels = _group_labels(prep)
    structured = is_structured(prep)
    e = prep.r_um - X @ beta if X.shape[1] else prep.r_um.copy()
    if structured:
        e_coef = np.zeros(W.B.shape[1])
        e_coef[0] = 1.0
        if X.shape[1]:
            e_coef = e_coef - X_coef @ beta
    else:
        Ce = prep.C - X @ cov @ X.T if X.shape[1] else prep.C
    def chi2_of(by, g, idx):
        if structured:
            return W.group_chi2((by, g), e_coef, cov, X_coef), len(idx)
        return _psd_chi2(e[idx], Ce[np.ix_(idx, idx)])

    def logp_of(chi2, dof):
        if not dof_scale:
            return chi2_logsf(chi2, dof)
        # uniform inflation: neither larger nor smaller than the common scale (two-sided)
        F = chi2 / dof / scale2
        return min(0.0, math.log(2.0) + min(f_logsf(F, dof, dof_scale), f_logcdf(F, dof, dof_scale)))

    extra = None if z is None else (lambda idx: {"rms_z": float(np.sqrt(np.mean(z[idx] ** 2)))})
    return _group_table(prep, labels, chi2_of, logp_of, extra, alpha)


def _group_table(prep: Prepared, labels: dict, chi2_of, logp_of, extra, alpha: float) -> list[dict]:
    """The rows of a group table: for every grouping and group, chi2_of(by, group, observation
    indices) -> (chi2, dof), its log p by logp_of, ``extra(idx)`` fields; flagged when p < alpha /
    (number of groups), sorted by p."""
    rows = []
    for by, lab in labels.items():
        lab_obs = [lab[a] for a in prep.obs_record]
        for g in dict.fromkeys(lab):
            idx = np.array([q for q, v in enumerate(lab_obs) if v == g])
            chi2, dof = chi2_of(by, g, idx)
            if dof == 0:
                continue
            item = {"by": by, "group": g, "records": int(len(set(prep.obs_record[idx]))),
                    "chi2": chi2, "dof": dof, "logp": logp_of(chi2, dof)}
            if extra is not None:
                item.update(extra(idx))
            rows.append(item)
    K = max(len(rows), 1)
    for r in rows:
        r["p_value"] = math.exp(r["logp"])
        r["flagged"] = bool(r["logp"] + math.log(K) < math.log(alpha))
    rows.sort(key=lambda r: r["logp"])
    return rows


def locate_groups(diag: Diagnosis) -> list[dict]:
    """Chi-square of the records of every group (docs/recordings.md section 3.2), with the baseline-adjusted
    covariance; flagged when p < alpha / (number of groups tested)."""
    prep = diag.prep
    labels = _group_labels(prep)
    A = prep.A
    C = prep.C
    structured = is_structured(prep)
    cov0 = np.zeros((0, 0))
    if A.shape[1]:
        cov0 = _gls(diag.whitener, A, prep.r_um)[1]
        if not structured:
            C = C - A @ cov0 @ A.T
    e = diag.resid_before
    if structured:   # e = r - A beta0 and A as combinations of the whitener's columns
        W = diag.whitener
        c = W.B.shape[1]
        p0 = A.shape[1]
        A_coef = np.zeros((c, p0))
        A_coef[1:1 + p0] = np.eye(p0)
        e_coef = np.zeros(c)
        e_coef[0] = 1.0
        if p0:
            e_coef[1:1 + p0] = -_gls(W, A, prep.r_um)[0]
    def chi2_of(by, g, idx):
        if structured:
            return W.group_chi2((by, g), e_coef, cov0, A_coef), len(idx)
        return _psd_chi2(e[idx], C[np.ix_(idx, idx)])

    def extra(idx):
        z = diag.z_before[idx]
        return {"mean_z": float(np.mean(z)), "rms_z": float(np.sqrt(np.mean(z**2)))}

    return _group_table(prep, labels, chi2_of, chi2_logsf, extra, diag.alpha)


# ---------------------------------------------------------------------------------------------
# reporting
# ---------------------------------------------------------------------------------------------

def effect_estimates(diag: Diagnosis, name: str) -> dict:
    """estimate/u of a chosen effect in its unit (vector effects: lists, None where a
    component is not identifiable; probe_qualification also per probe)."""
    return _estimates(diag.prep, diag.candidates[name], diag.sel_labels, diag.beta, diag.cov_beta)


def _estimates(prep: Prepared, c: Candidate, sel_labels, beta, cov_beta) -> dict:
    name = c.name
    rows = [q for q, (e, _) in enumerate(sel_labels) if e == name]
    est = {sel_labels[q][1]: float(beta[q]) for q in rows}
    unc = {sel_labels[q][1]: float(math.sqrt(max(cov_beta[q, q], 0.0))) for q in rows}
    eff = fx.BY_NAME[name]
    if not eff.vector:
        return {"estimate": est[name], "u": unc[name]}
    labels = c.cols.labels
    out = {"estimate": [est.get(l) for l in labels], "u": [unc.get(l) for l in labels]}
    if name == "probe_qualification":
        per = []
        for pid in prep.design.probe_ids[1:]:
            ls = [f"{pid}.d{a}" for a in fx.AXES]
            per.append({"probe": pid, "estimate": [est.get(l) for l in ls], "u": [unc.get(l) for l in ls]})
        out["per_probe"] = per
    return out


def unexplained_rest(diag: Diagnosis, top: int = 5) -> dict | None:
    """Where the chi-square that remains after the refit concentrates (None when explained):
    the groups of section 3.2 by their chi-square after the refit (with the refit's residual
    covariance C - X cov X'), largest first, and the records with the largest |z| after."""
    if not diag.mismatch or diag.explained:
        return None
    groups = [{k: v for k, v in g.items() if k != "logp"} for g in diag.groups_after[:top]]
    z = diag.z_after
    prep = diag.prep
    if prep.design.kind == "length":
        order = np.argsort(-np.abs(z), kind="stable")[:top]
        recs = [{"id": prep.rec.ids[a], "residual_um": float(diag.resid_after[a]), "z": float(z[a])}
                for a in order]
    else:
        dims = prep.design.dims
        zz = np.sqrt(np.sum(z.reshape(prep.rec.n, dims) ** 2, axis=1))
        order = np.argsort(-zz, kind="stable")[:top]
        e = diag.resid_after.reshape(prep.rec.n, dims)
        recs = [{"id": prep.rec.ids[i], "residual_um": float(np.linalg.norm(e[i])), "z": float(zz[i])}
                for i in order]
    return {"chi2_after": diag.chi2_after, "dof_after": diag.dof_after, "groups": groups, "records": recs}


def _finite_or_none(v: float | None):
    if v is None or not math.isfinite(v):
        return None
    return v


def diagnosis_json(diag: Diagnosis) -> dict:
    prep = diag.prep
    out = {
        "records": prep.rec.n, "kind": prep.design.kind, "alpha": diag.alpha,
        "chi2_before": diag.chi2_before, "dof_before": diag.dof_before,
        "p_before": math.exp(diag.logp_before), "mismatch": diag.mismatch,
        "rms_before_um": diag.rms_before_um, "rms_after_um": diag.rms_after_um,
        "chi2_after": diag.chi2_after, "dof_after": diag.dof_after,
        "effects": [], "not_identifiable": [], "located": diag.located,
    }
    for name in diag.chosen:
        c = diag.candidates[name]
        e = {"name": name, **effect_estimates(diag, name), "unit": fx.BY_NAME[name].unit,
             "delta_chi2": c.delta_chi2, "p_value": math.exp(c.logp), "p_adjusted": c.p_adjusted,
             "df": c.df, "step": c.step, "log10_p_value": c.logp / math.log(10)}
        out["effects"].append(e)
    for name in fx.NAMES:
        c = diag.candidates[name]
        if c.status in ("not identifiable", "aliased"):
            item = {"name": name, "reason": c.reason}
            if c.aliased_with:
                item["aliased_with"] = c.aliased_with
            out["not_identifiable"].append(item)
    # extensions (spec: new keys welcome)
    out["p_after"] = math.exp(chi2_logsf(diag.chi2_after, diag.dof_after)) if diag.dof_after > 0 else None
    # second edition (docs/recordings.md section 7)
    out["p_targeted"] = math.exp(diag.logp_targeted) if diag.targeted_K else None
    out["gate"] = diag.gate
    out["explained"] = diag.explained
    out["outliers"] = diag.outliers if (diag.outlier_search or not diag.mismatch) else None
    out["outliers_not_isolated"] = diag.outliers_not_isolated
    out["with_outliers"] = diag.with_outliers
    out["noise_scale"] = diag.noise_scale
    out["unexplained"] = unexplained_rest(diag)
    out["discrepancy"] = diag.discrepancy
    out["alpha_name"] = diag.alpha_name
    out["indicated"] = diag.indicated
    out["log10_p_before"] = diag.logp_before / math.log(10)
    out["covariance_rank"] = diag.whitener.rank
    if is_structured(diag.prep):
        C = diag.prep.C
        out["approximation"] = {
            "method": "structured covariance D + U U^T (Woodbury), GP factors by pivoted-Cholesky "
                      "Nystrom factors", "pivot_tol": C.pivot_tol, "rank": dict(C.ranks),
            "covariance_error_bound_um2": C.eps_C, "chi2_relative_error_bound": C.chi2_bound()}
    out["candidates"] = [{
        "name": n, "status": c.status, "step": c.step, "df": c.df,
        "delta_chi2": c.delta_chi2, "p_value": None if c.logp is None else math.exp(c.logp),
        "p_adjusted": c.p_adjusted, "reason": c.reason} for n, c in diag.candidates.items()]
    out["steps"] = [[{"name": r["name"], "df": r["df"], "delta_chi2": r["delta_chi2"],
                      "p_value": math.exp(r["logp"]), "p_adjusted": math.exp(r["log_p_adjusted"])}
                     for r in sorted(s, key=lambda r: r["logp"])] for s in diag.steps]
    out["groups"] = [{k: v for k, v in g.items() if k != "logp"} for g in diag.groups]
    if prep.design.kind == "point":
        al = {lab: (float(diag.beta[q]), float(math.sqrt(diag.cov_beta[q, q])))
              for q, (e, lab) in enumerate(diag.sel_labels) if e == "alignment"}
        out["alignment"] = {
            "dims": prep.design.dims,
            "initial_rotation": prep.R0.tolist(), "initial_translation_mm": prep.t0.tolist(),
            "refit": {k: {"estimate": v[0], "u": v[1]} for k, v in al.items()},
        }
    out["summary"] = diag.summary
    return _json_safe(out)


def _json_safe(v):
    """Plain JSON: numpy scalars to Python, non-finite numbers to None."""
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if math.isfinite(v) else None
    return v


PLAIN_UNITS = {"um/m": "µm/m", "urad": "µrad", "ppm/K": "ppm/K", "um": "µm", "urad/m": "µrad/m",
               "um/m/h": "µm/m per hour", "um/h": "µm/h"}


def _fmt_pm(est: float, u: float) -> str:
    digits = max(0, min(6, 1 - int(math.floor(math.log10(abs(u)))) if u > 0 else 2))
    return f"{est:.{digits}f} ± {u:.{digits}f}"


def where_seen(diag: Diagnosis, name: str) -> str:
    """Plain words for where the fitted effect concentrates (the smallest share of the records
    carrying 80 % of its standardized signal)."""
    prep = diag.prep
    rows = diag.effect_rows(name)
    f = diag.X_sel[:, rows] @ diag.beta[rows]
    s_obs = (f / diag.u_obs) ** 2
    n = prep.rec.n
    s = np.bincount(prep.obs_record, weights=s_obs, minlength=n)
    total = s.sum()
    if total <= 0:
        return ""
    best = None
    labels = _group_labels(prep)
    pref = ["direction", "probing", "probe", "temperature", "time", "group"]
    for by in sorted(labels, key=lambda b: pref.index(b) if b in pref else len(pref)):
        lab = labels[by]
        shares: dict[str, float] = {}
        counts: dict[str, int] = {}
        for a, g in enumerate(lab):
            shares[g] = shares.get(g, 0.0) + s[a]
            counts[g] = counts.get(g, 0) + 1
        acc, sel = 0.0, []
        for g in sorted(shares, key=lambda g: -shares[g] / counts[g]):
            sel.append(g)
            acc += shares[g]
            if acc >= 0.8 * total:
                break
        frac = sum(counts[g] for g in sel) / n
        rest = max(total - acc, 0.0) / total
        # concentrated: the selected records carry the signal at least 4 times as densely
        dense = rest <= 1e-12 or (acc / total / frac) >= 4.0 * (rest / (1.0 - frac))
        if frac <= 0.75 and dense and (best is None or frac < best[0] - 1e-12):
            best = (frac, by, sel)
    if best is None:
        return "spread over all records"
    _, by, sel = best
    if by == "direction":
        if all(sum(ch in fx.AXES for ch in g) >= 2 for g in sel):
            return "seen in the diagonal lengths (" + ", ".join(sel[:4]) + ("…" if len(sel) > 4 else "") + ")"
        return "seen in the lengths along " + ", ".join(sel[:4])
    if by == "probing":
        return f"seen in the {' and '.join(sel)} lengths"
    if by == "probe":
        return "seen in the records with probe " + ", ".join(sel[:4])
    if by == "temperature":
        return "seen in the records at " + ", ".join(sel)
    if by == "time":
        return "seen in the records at " + ", ".join(sel) + " into the session"
    return "seen in group " + ", ".join(sel[:4])


def summary_text(diag: Diagnosis) -> str:
    """The short plain-language answer printed on the terminal."""
    r = diag.chi2_before / diag.dof_before
    if not diag.mismatch:
        return (f"the records agree with the simulation (chi2/dof {r:.2f}, p = "
                f"{math.exp(diag.logp_before):.2g}); no effect is needed")
    head = f"the records disagree with the simulation (chi2/dof {r:.2f}"
    if diag.gate == "targeted":
        head += f"; the omnibus test alone would pass, the targeted test fires: p = {math.exp(diag.logp_targeted):.2g}"
    head += ")"
    pieces = []
    for o in diag.outliers:
        pieces.append(f"record {o['id']} is a gross outlier (residual {o['residual_um']:.3g} µm, "
                      f"z = {o['z']:.1f}, adjusted p = {o['p_adjusted']:.2g}) and is left out of the effect search")
    if diag.noise_scale:
        ns = diag.noise_scale
        pieces.append(f"the residuals are uniformly larger than the simulation allows, with no structure a "
                      f"candidate or group explains: the declared uncertainties are too small by a factor "
                      f"{_fmt_pm(ns['estimate'], ns['u'])}" + ("" if diag.chosen else "; no physical effect is chosen"))
    for ind in diag.indicated:
        eff = fx.BY_NAME[ind["name"]]
        if eff.vector:
            c = diag.candidates[ind["name"]]
            val = "; ".join(f"{l} {_fmt_pm(e, u)}" for l, e, u in zip(c.cols.labels, ind["estimate"], ind["u"])
                            if e is not None) + f" {PLAIN_UNITS[eff.unit]}"
        else:
            val = f"{_fmt_pm(ind['estimate'], ind['u'])} {PLAIN_UNITS[eff.unit]}"
        pieces.append(f"{eff.plain} of {val} is indicated (adjusted p = {ind['p_adjusted']:.2g}) but not "
                      f"named: a cause is named only at adjusted p < {diag.alpha_name:.2g}, so it is not "
                      f"applied; more records that see it would tell")
    if not diag.chosen and not pieces:
        loc = diag.located[0] if diag.located else None
        tail = f"; the largest is {loc['id']} (z = {loc['z']:.1f})" if loc else ""
        return (head + "; none of the candidate effects explains it significantly: look at the records "
                "listed under 'located'" + tail)
    excess = max(diag.chi2_before - diag.dof_before, 1e-12)
    shares = [max(0.0, min(1.0, diag.candidates[n].delta_chi2 / excess)) for n in diag.chosen]
    shares = [v / max(1.0, sum(shares)) for v in shares]
    parts = []
    for name, share in zip(diag.chosen, shares):
        c = diag.candidates[name]
        eff = fx.BY_NAME[name]
        est = effect_estimates(diag, name)
        if eff.vector:
            comp = [(l, e, u) for l, e, u in zip(c.cols.labels, est["estimate"], est["u"]) if e is not None]
            val = "; ".join(f"{l} {_fmt_pm(e, u)}" for l, e, u in comp) + f" {PLAIN_UNITS[eff.unit]}"
        else:
            val = f"{_fmt_pm(est['estimate'], est['u'])} {PLAIN_UNITS[eff.unit]}"
        seen = where_seen(diag, name)
        parts.append(f"{share * 100:.0f} % of the excess is explained by {eff.plain} of {val}"
                     + (f", {seen}" if seen else ""))
    after = diag.chi2_after / max(diag.dof_after, 1)
    text = head + "; " + "; ".join(pieces + (["; then ".join(parts)] if parts else []))
    if diag.chosen or diag.outliers:
        what = ("it" if len(diag.chosen) + len(diag.outliers) == 1 else "them")
        text += f"; after {f'leaving {what} out' if not diag.chosen else f'adding {what}'} chi2/dof is {after:.2f}"
    if not diag.explained and not diag.noise_scale:
        rest = unexplained_rest(diag)
        where = ""
        if rest and rest["groups"] and rest["groups"][0]["flagged"]:
            g = rest["groups"][0]
            where = f"; the rest concentrates in {g['by']} {g['group']} (chi2 {g['chi2']:.1f} on {g['dof']} dof)"
        elif rest and rest["records"]:
            where = f"; no group stands out, the largest is {rest['records'][0]['id']} (z = {rest['records'][0]['z']:.1f})"
        text += (f". This is not the whole story: what remains still fails (p_after = "
                 f"{math.exp(diag.logp_after):.2g}){where}")
    if diag.with_outliers is not None and diag.with_outliers["effects"] != diag.chosen:
        kept = diag.with_outliers["effects"]
        text += (". With the outliers kept the search would choose " + (", ".join(kept) if kept else "nothing"))
    groups: dict[tuple[str, str], list[str]] = {}
    for c in diag.candidates.values():
        if c.status == "aliased" and c.aliased_with in diag.chosen:
            groups.setdefault((c.aliased_with, c.reason.rsplit("; ", 1)[-1]), []).append(c.name)
    for (other, hint), names in list(groups.items())[:3]:
        who = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
        text += f". {who} cannot be told apart from {other} with these records: {hint}"
    return text


def effect_covariance(prep: Prepared, name: str, W: Whitener | None = None):
    """GLS covariance of the parameters of candidate ``name`` fitted alone with the baseline:
    ``(cov, labels)`` over its identifiable columns (the standard uncertainty a planted effect is
    measured against; used to size effects in the simulator and the benchmark)."""
    if W is None:
        W = _structured_whitener(prep, [name]) if is_structured(prep) else Whitener(prep.C)
    cols = fx.columns(prep.design, name)
    Q0, keptA = _orth(W(prep.A))
    Xw = W(cols.X)
    big = np.max(np.abs(cols.X), axis=0) > fx.REL_ZERO * cols.full_scale
    Z = _out(Q0, Xw)
    Z[:, ~big] = 0.0
    _, kept = _orth(Z, np.linalg.norm(Xw, axis=0))
    if not kept:
        raise fx.NotApplicable("not identifiable")
    X = np.column_stack([prep.A[:, keptA], cols.X[:, kept]])
    _, cov, _ = _gls(W, X, prep.r_um)
    p0 = len(keptA)
    return cov[p0:, p0:], [cols.labels[j] for j in kept]
