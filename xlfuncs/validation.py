"""Does the model hold on this machine?  The check of task-specific uncertainties against
calibrated workpieces (ISO/TS 15530-4:2008, the test of an uncertainty evaluating software by
measuring calibrated workpieces; docs/validate.md): ``cmmwb validate``.

Every row is one measured characteristic of a calibrated workpiece: the measured value y (the
mean of its repeats), the calibrated value y_cal with the certificate's U_cal and k_cal, and the
model's U and k for that characteristic (the task's result record).  Per row

    E_n = |y - y_cal| / sqrt(U^2 + U_cal^2)                 (the ISO/TS 15530-4 criterion E_n <= 1;
                                                              the E_n number of ISO 13528)

and, with u = U/k, u_cal = U_cal/k_cal, the coverage the model claims for that row,
p = P(|N(0, u^2 + u_cal^2)| <= sqrt(U^2 + U_cal^2)) = erf(E / sqrt(2)) with
E = sqrt(U^2 + U_cal^2)/sqrt(u^2 + u_cal^2) (k = k_cal = 2: 95.45 %).

**The count.**  K rows of n have E_n <= 1.  Were the rows independent, K would be binomial with
the rows' mean claimed coverage (a conservative stand-in for the exact Poisson-binomial: same
mean, larger spread); on one machine they are not (one scale error moves every long length), so
where the rows' correlation under the model is known (length rows with their probed points,
:func:`joint_correlation`) the null distribution of K is drawn: deviations N(0, D R D) with D the
rows' u_c and R their correlation, :data:`DRAWS` draws from a fixed seed.  The one-sided p-value
P(K' <= K) says whether too few rows lie within their U.

**The structure.**  Length rows with their probed points (the columns of docs/recordings.md 1a)
are the mismatch locator's length records (reference = calibrated value, measured = the mean of
the rows at the same probings): its record covariance under the task's model plus u_cal^2 on the
diagonal (calibrations taken independent), its two gates (omnibus and targeted) and, where they
fire, the effect it names, the outliers, the noise scale.  Rows without probed points: chi-square
of z = (y - y_cal)/u_c over all rows, per workpiece and per run, and the slope of the deviations
against the calibrated value (a scale error), Bonferroni over these tests.

**The verdict** (:data:`RULE`): the model holds when the count is consistent with the claimed
coverage (p >= alpha/2) and no structure is found (p >= alpha/2): at most alpha of correct models
are called wrong (union bound).  Otherwise the cause: the effect the locator names, the noise
scale, outliers, a scale slope, a group, or the count alone; and the next step.

numpy only (the locator for the structure).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import pointcloud as pc
from .distributions import chi2_logsf
from .errors import ModelError
from .locator import diagnose as dg
from .locator import effects as fx
from .locator.model import Model, length_covariance, prepare, resolve_probes
from .locator.recordings import LengthRecords

#: the significance level of the verdict: alpha/2 for the count, alpha/2 for the structure
ALPHA = 0.01
#: draws of the correlated null distribution of the count (fixed seed)
DRAWS = 10000
SEED = 20150
#: the worst rows listed
WORST = 5

RULE = ("ISO/TS 15530-4 (validation by measuring calibrated workpieces): E_n = |y - y_cal| / sqrt(U^2 + U_cal^2) "
        "per row; the model holds when the share of rows with E_n <= 1 is consistent with the coverage the model "
        "claims (one-sided test, p >= alpha/2) and the deviations show no structure the model does not carry "
        "(the mismatch locator's gates on rows with their probed points, chi-square, group and scale-slope tests "
        "on the others, Bonferroni; p >= alpha/2): a correct model is called wrong at most alpha of the time")
VERDICT_WORDS = {True: "the model holds", False: "the model does not hold"}


class ResultsError(ModelError):
    """Bad validation results: ``line`` (1-based line of the file) and ``column`` say where."""

    def __init__(self, message: str, line: int | None = None, column: str | None = None):
        super().__init__(message)
        self.message, self.line, self.column = message, line, column

    @property
    def where(self) -> str | None:
        parts = ([f"line {self.line}"] if self.line is not None else []) \
            + ([f"column {self.column!r}"] if self.column is not None else [])
        return ", ".join(parts) or None

    def __str__(self) -> str:
        return f"{self.where}: {self.message}" if self.where else self.message


@dataclass(frozen=True)
class Rows:
    """The validation rows, one per measured characteristic of a calibrated workpiece and run.

    Values in the characteristic's ``unit``; ``U``, ``U_cal`` and ``s`` in its ``U_unit``;
    ``scale`` = U_unit per value unit (1000: µm per mm)."""

    label: tuple[str, ...]
    workpiece: tuple[str, ...]
    run: tuple[str, ...]
    y: np.ndarray          # measured value: the mean of the repeats
    n: np.ndarray          # repeats
    s: np.ndarray          # standard deviation of the repeats (U unit; nan with one)
    y_cal: np.ndarray      # calibrated value (certificate)
    U_cal: np.ndarray      # certificate's expanded uncertainty
    k_cal: np.ndarray      # and its coverage factor
    U: np.ndarray          # the model's expanded uncertainty (the task's record)
    k: np.ndarray          # and its coverage factor
    scale: np.ndarray
    unit: tuple[str, ...]
    U_unit: tuple[str, ...]
    lines: tuple[int, ...] = ()

    def __post_init__(self):
        n = len(self.label)
        for name in ("y", "n", "s", "y_cal", "U_cal", "k_cal", "U", "k", "scale"):
            if np.shape(getattr(self, name)) != (n,):
                raise ModelError(f"validation rows: {name} has {np.size(getattr(self, name))} entries, not {n}")
        if n == 0:
            raise ModelError("no validation rows")
        for name, lo in (("U_cal", 0.0), ("k_cal", 0.0), ("U", 0.0), ("k", 0.0)):
            v = getattr(self, name)
            bad = np.flatnonzero(~np.isfinite(v) | (v < lo) | ((v == lo) & (name != "U_cal")))
            if bad.size:
                i = int(bad[0])
                raise ResultsError(f"{name} must be {'>= 0' if name == 'U_cal' else '> 0'}, got {v[i]!r}",
                                   self.lines[i] if self.lines else None, name)

    @property
    def size(self) -> int:
        return len(self.label)

    @property
    def deviation(self) -> np.ndarray:
        """y - y_cal in the U unit."""
        return (self.y - self.y_cal) * self.scale

    @property
    def U_c(self) -> np.ndarray:
        """sqrt(U^2 + U_cal^2), the limit of |y - y_cal| (U unit)."""
        return np.hypot(self.U, self.U_cal)

    @property
    def u_c(self) -> np.ndarray:
        """sqrt(u^2 + u_cal^2), the standard uncertainty of y - y_cal under the model."""
        return np.hypot(self.U / self.k, self.U_cal / self.k_cal)

    @property
    def E_n(self) -> np.ndarray:
        return np.abs(self.deviation) / self.U_c

    @property
    def claimed(self) -> np.ndarray:
        """The coverage the model claims for each row: P(|y - y_cal| <= U_c) under the model
        (normal deviations with standard uncertainty u_c)."""
        return np.array([math.erf(e / math.sqrt(2.0)) for e in self.U_c / self.u_c])


@dataclass(frozen=True)
class Geometry:
    """The probed points of length rows (docs/recordings.md 1a): ``rows`` the indices of the rows
    that have them, and their ends, normals, probe offsets and ids (None where not given)."""

    rows: np.ndarray
    X1_mm: np.ndarray
    X2_mm: np.ndarray
    N1: np.ndarray | None = None
    N2: np.ndarray | None = None
    P1_mm: np.ndarray | None = None
    P2_mm: np.ndarray | None = None
    probe1: tuple[str, ...] | None = None
    probe2: tuple[str, ...] | None = None


# ---------------------------------------------------------------------------------------------
# the count of rows within E_n <= 1
# ---------------------------------------------------------------------------------------------

def binomial_cdf(k: int, n: int, p: float) -> float:
    """P(X <= k), X ~ Bin(n, p), summed in logarithms."""
    if k < 0:
        return 0.0
    if k >= n:
        return 1.0
    if p <= 0.0:
        return 1.0
    if p >= 1.0:
        return 0.0
    lp, lq = math.log(p), math.log1p(-p)
    terms = [math.lgamma(n + 1) - math.lgamma(j + 1) - math.lgamma(n - j + 1) + j * lp + (n - j) * lq
             for j in range(k + 1)]
    m = max(terms)
    return min(1.0, math.exp(m) * math.fsum(math.exp(t - m) for t in terms))


def count_null(corr: np.ndarray, u_c: np.ndarray, U_c: np.ndarray, draws: int = DRAWS,
               seed: int = SEED) -> np.ndarray:
    """The number of rows within their U_c in ``draws`` draws of deviations N(0, D R D), D = u_c,
    R = ``corr`` (the rows' correlation under the model): the null distribution of the count.
    R^(1/2) is the symmetric square root (eigenvalues below 1e-12 of the largest dropped), the
    draws come from a fixed seed: the counts do not depend on the CPU but for a deviation exactly
    on its limit."""
    w, V = np.linalg.eigh(0.5 * (corr + corr.T))
    keep = w > 1e-12 * w[-1]
    # the symmetric square root R^(1/2) = V W^(1/2) V^T, unique, not V W^(1/2): eigenvectors of a
    # degenerate eigenvalue are any basis of their space, chosen by the BLAS kernel (as in
    # xlfuncs.locator.simulate)
    S = (V[:, keep] * np.sqrt(w[keep])) @ V[:, keep].T
    rng = np.random.default_rng(seed)
    counts = np.empty(draws, dtype=int)
    limit = (U_c / u_c)[:, None]
    for start in range(0, draws, 2000):
        z = rng.standard_normal((S.shape[1], min(2000, draws - start)))
        counts[start:start + z.shape[1]] = np.sum(np.abs(S @ z) <= limit, axis=0)
    return counts


@dataclass
class Count:
    within: int
    n: int
    claimed: float               # mean claimed coverage of the rows
    p_low_binomial: float        # P(K' <= K), K' ~ Bin(n, claimed)
    p_high_binomial: float       # P(K' >= K)
    p_low_correlated: float | None = None     # from the draws (rows' correlation known)
    p_high_correlated: float | None = None
    expected_correlated: float | None = None  # mean count of the draws / n
    basis: str = "independent rows (binomial with the rows' mean claimed coverage)"

    @property
    def p_low(self) -> float:
        return self.p_low_binomial if self.p_low_correlated is None else self.p_low_correlated

    @property
    def p_high(self) -> float:
        return self.p_high_binomial if self.p_high_correlated is None else self.p_high_correlated

    def words(self, alpha: float) -> str:
        share = 100.0 * self.within / self.n
        s = (f"{self.within} of {self.n} rows ({share:.1f} %) have E_n <= 1; the model claims "
             f"{100 * self.claimed:.2f} % for each. With {self.basis}, {self.within} or fewer happen with "
             f"probability {self.p_low:.3g}: ")
        if self.p_low < alpha / 2:
            s += (f"fewer than the claimed coverage allows (below alpha/2 = {alpha / 2:g}): the model's U is too small "
                  "for these rows")
        else:
            s += "consistent with the coverage claimed"
            if self.p_high < alpha / 2:
                s += (f"; but {self.within} or more happen with probability {self.p_high:.3g} only: more rows lie "
                      "within their U than the coverage claims -- the model's U is larger than these deviations need "
                      "(conservative)")
        return s + "."

    def to_json(self) -> dict:
        return {"within": self.within, "rows": self.n, "share": self.within / self.n, "claimed": self.claimed,
                "p_low_binomial": self.p_low_binomial, "p_high_binomial": self.p_high_binomial,
                "p_low_correlated": self.p_low_correlated, "p_high_correlated": self.p_high_correlated,
                "expected_share_correlated": self.expected_correlated, "basis": self.basis,
                "p_low": self.p_low, "p_high": self.p_high}


def count_test(rows: Rows, corr: np.ndarray | None = None, draws: int = DRAWS, seed: int = SEED) -> Count:
    """The count of rows with E_n <= 1 against the coverage the model claims (module docstring)."""
    within = int(np.sum(rows.E_n <= 1.0))
    n = rows.size
    p = float(np.mean(rows.claimed))
    c = Count(within, n, p, binomial_cdf(within, n, p), 1.0 - binomial_cdf(within - 1, n, p))
    if corr is not None and np.any(np.abs(corr - np.eye(n)) > 0):
        null = count_null(corr, rows.u_c, rows.U_c, draws, seed)
        c.p_low_correlated = float((1 + np.sum(null <= within)) / (draws + 1))
        c.p_high_correlated = float((1 + np.sum(null >= within)) / (draws + 1))
        c.expected_correlated = float(np.mean(null) / n)
        c.basis = (f"the rows' correlation under the model ({draws} draws of the count; the runs of a "
                   "characteristic without probed points fully correlated, different ones independent)")
    return c


# ---------------------------------------------------------------------------------------------
# length rows with their probed points: the covariance and the locator
# ---------------------------------------------------------------------------------------------

def _records(rows: Rows, geo: Geometry, idx: np.ndarray, measured: np.ndarray, ids: list[str]) -> LengthRecords:
    """Length records (docs/recordings.md 1a) of the geometry entries ``idx``."""
    r = geo.rows[idx]

    def pick(a):
        return None if a is None else np.asarray(a)[idx]

    def pick_t(a):
        return None if a is None else tuple(a[i] for i in idx)

    return LengthRecords(kind="length", ids=tuple(ids), lines=tuple(rows.lines[i] if rows.lines else 0 for i in r),
                         X1_mm=geo.X1_mm[idx], X2_mm=geo.X2_mm[idx], reference_mm=rows.y_cal[r],
                         measured_mm=measured, N1=pick(geo.N1), N2=pick(geo.N2), P1_mm=pick(geo.P1_mm),
                         P2_mm=pick(geo.P2_mm), probe1=pick_t(geo.probe1), probe2=pick_t(geo.probe2))


def _probings(rec: LengthRecords, model: Model, keys: list[str]):
    """The point cloud of the records' probings, one per (key, coordinates, normal, probe): ends of
    records with different ``keys`` (runs) are different probings even at the same place."""
    ids_per_end, probe_ids, probes, _ = resolve_probes(rec, model)
    index = {p: k for k, p in enumerate(probe_ids)}
    where: dict[tuple, int] = {}
    X, N, K, ends = [], [], [], []
    for e, (Xe, Ne) in enumerate(((rec.X1_mm, rec.N1), (rec.X2_mm, rec.N2))):
        col = []
        for a in range(rec.n):
            normal = (0.0, 0.0, 0.0) if Ne is None else tuple(float(v) + 0.0 for v in Ne[a])
            key = (keys[a], tuple(float(v) + 0.0 for v in Xe[a]), normal, index[ids_per_end[e][a]])
            if key not in where:
                where[key] = len(X)
                X.append(Xe[a])
                N.append(normal)
                K.append(key[3])
            col.append(where[key])
        ends.append(np.array(col))
    cloud = pc.PointCloud(np.array(X, dtype=float), np.array(N, dtype=float), np.array(K), probes,
                          tuple(f"Q{q + 1}" for q in range(len(X))))
    return cloud, ends[0], ends[1]


def _length_cov(rec: LengthRecords, model: Model, keys: list[str], repeats: np.ndarray) -> np.ndarray:
    """Covariance (µm²) of the records' measured lengths under the task's model, the
    repeatability part of records that are means of ``repeats`` measurements scaled by
    1/sqrt(N_a N_b) (exact when records sharing a probing are means of equally many repeats)."""
    cloud, I, J = _probings(rec, model, keys)
    comps = length_covariance(cloud, model.params, I, J, components=True)
    C = sum(comps.values())
    f = 1.0 / np.sqrt(np.asarray(repeats, dtype=float))
    C = C - comps["R"] + comps["R"] * np.outer(f, f)
    return 0.5 * (C + C.T)


def joint_correlation(rows: Rows, geo: Geometry | None, model: Model | None) -> np.ndarray | None:
    """The correlation of the rows' deviations y - y_cal under the model: length rows with their
    probed points by the task's record covariance (each run its own probings; the repeatability of
    means of repeats reduced), plus u_cal^2 (independent calibrations); the other rows of one
    characteristic of a workpiece in several runs fully correlated (one machine, one calibration:
    the model's systematic part dominates; taking them fully correlated is the cautious side),
    rows of different characteristics independent.  None when every row is independent."""
    R = np.eye(rows.size)
    plain = np.setdiff1d(np.arange(rows.size), geo.rows if geo is not None and model is not None else [])
    for members in _same_characteristic(rows, plain):
        R[np.ix_(members, members)] = 1.0
    if geo is not None and model is not None and geo.rows.size:
        r = geo.rows
        rec = _records(rows, geo, np.arange(len(r)), rows.y[r], [f"row{i}" for i in r])
        C = _length_cov(rec, model, [rows.run[i] for i in r], rows.n[r])
        C = C + np.diag((rows.U_cal[r] / rows.k_cal[r]) ** 2)
        s = np.sqrt(np.diag(C))
        R[np.ix_(r, r)] = C / np.outer(s, s)
    return None if np.array_equal(R, np.eye(rows.size)) else R


def _same_characteristic(rows: Rows, idx: np.ndarray) -> list[list[int]]:
    """The rows ``idx`` grouped by characteristic and workpiece (its runs), in first-row order."""
    groups: dict[tuple[str, str], list[int]] = {}
    for i in idx:
        groups.setdefault((rows.label[i], rows.workpiece[i]), []).append(int(i))
    return list(groups.values())


def merged_records(rows: Rows, geo: Geometry) -> tuple[LengthRecords, list[list[int]]]:
    """The length records the locator reads: rows at the same probings (repeats, runs of a
    workpiece not moved) of the same characteristic and workpiece are one record, their mean
    weighted by the repeats; returns the records and the rows of each."""
    groups: dict[tuple, list[int]] = {}
    for g, i in enumerate(geo.rows):
        key = (rows.label[i], rows.workpiece[i], tuple(geo.X1_mm[g]), tuple(geo.X2_mm[g]),
               None if geo.N1 is None else (tuple(geo.N1[g]), tuple(geo.N2[g])),
               None if geo.probe1 is None else (geo.probe1[g], geo.probe2[g]))
        groups.setdefault(key, []).append(g)
    idx = np.array([gs[0] for gs in groups.values()])
    meas = np.array([np.average(rows.y[geo.rows[gs]], weights=rows.n[geo.rows[gs]]) for gs in groups.values()])
    ids = [f"{rows.workpiece[geo.rows[gs[0]]]}/{rows.label[geo.rows[gs[0]]]}" for gs in groups.values()]
    seen: dict[str, int] = {}
    for a, name in enumerate(ids):
        seen[name] = seen.get(name, 0) + 1
        if seen[name] > 1:
            ids[a] = f"{name} ({seen[name]})"
    return _records(rows, geo, idx, meas, ids), [[int(geo.rows[g]) for g in gs] for gs in groups.values()]


def locate(rows: Rows, geo: Geometry, model: Model, alpha: float) -> tuple[dg.Diagnosis, list[list[int]]]:
    """The mismatch locator on the length rows (merged at equal probings): the task's record
    covariance of the means, plus u_cal^2; its gates at alpha/2 (each alpha/4)."""
    rec, members = merged_records(rows, geo)
    if rec.n < 2:
        raise ModelError("the locator needs two length rows with their probed points at least")
    prep = prepare(rec, model, False)
    total = np.array([float(np.sum(rows.n[m])) for m in members])
    C = _length_cov(rec, model, ["all"] * rec.n, total)
    ucal2 = np.array([(rows.U_cal[m[0]] / rows.k_cal[m[0]]) ** 2 for m in members])
    prep = replace(prep, C=C + np.diag(ucal2))
    return dg.diagnose_prepared(prep, alpha / 2), members


# ---------------------------------------------------------------------------------------------
# rows without probed points: chi-square, groups, the scale slope
# ---------------------------------------------------------------------------------------------

def _chi2_p(chi2: float, dof: int) -> float:
    return math.exp(chi2_logsf(chi2, dof))


def plain_tests(rows: Rows, idx: np.ndarray) -> list[dict]:
    """The tests of the rows ``idx`` (without probed points).  The runs of one characteristic share
    the machine's systematic errors and the calibration, so each characteristic of a workpiece
    enters once, as the mean deviation of its runs with the u_c of one measurement (the cautious
    side); characteristics are taken independent.  Chi-square of z = mean deviation / u_c over all,
    per workpiece (when there are several), and the slope of the deviation against the calibrated
    value of the characteristics in mm (weighted least squares with an intercept; the slope in µm/m
    is a scale error the model does not carry)."""
    if idx.size == 0:
        return []
    groups = _same_characteristic(rows, idx)
    first = np.array([g[0] for g in groups])
    dev = np.array([np.average(rows.deviation[g], weights=rows.n[g]) for g in groups])
    u_c = rows.u_c[first]
    z = dev / u_c
    out = [{"test": "chi-square of the characteristics without probed points", "chi2": float(z @ z),
            "dof": int(z.size), "p": _chi2_p(float(z @ z), int(z.size)), "rows": idx.tolist()}]
    names = list(dict.fromkeys(rows.workpiece[i] for i in first))
    if len(names) > 1:
        for name in names:
            sel = np.array([k for k, i in enumerate(first) if rows.workpiece[i] == name])
            c = float(z[sel] @ z[sel])
            out.append({"test": f"chi-square of workpiece {name}", "chi2": c, "dof": int(sel.size),
                        "p": _chi2_p(c, int(sel.size)), "rows": [i for k in sel for i in groups[k]]})
    mm = np.array([k for k, i in enumerate(first) if rows.unit[i] == "mm"])
    if mm.size >= 3 and np.ptp(rows.y_cal[first[mm]]) > 0:
        w = 1.0 / u_c[mm]
        yc = rows.y_cal[first[mm]]
        x = yc - np.average(yc, weights=w**2)
        A = np.column_stack([np.ones(mm.size), x]) * w[:, None]
        cov = np.linalg.inv(A.T @ A)
        b = cov @ (A.T @ (dev[mm] * w))
        zb = b[1] / math.sqrt(cov[1, 1])
        out.append({"test": "slope of the deviation against the calibrated value (scale)",
                    "slope_um_per_m": float(b[1] * 1000.0), "u_um_per_m": float(math.sqrt(cov[1, 1]) * 1000.0),
                    "chi2": float(zb * zb), "dof": 1, "p": _chi2_p(float(zb * zb), 1),
                    "rows": [i for k in mm for i in groups[k]]})
    return out


# ---------------------------------------------------------------------------------------------
# the verdict
# ---------------------------------------------------------------------------------------------

@dataclass
class Validation:
    rows: Rows
    alpha: float
    count: Count
    p_structure: float
    structure_basis: str
    holds: bool
    causes: list[dict]
    next_step: str
    worst: list[int]
    tests: list[dict] = field(default_factory=list)
    diagnosis: dg.Diagnosis | None = None
    members: list[list[int]] = field(default_factory=list)
    corr_known: bool = False

    @property
    def verdict(self) -> str:
        return VERDICT_WORDS[self.holds]

    def to_json(self) -> dict:
        r = self.rows
        dev, Uc, En, claimed = r.deviation, r.U_c, r.E_n, r.claimed
        rows = [{"label": r.label[i], "workpiece": r.workpiece[i], "run": r.run[i], "line": r.lines[i] if r.lines else None,
                 "unit": r.unit[i], "U_unit": r.U_unit[i], "measured": float(r.y[i]), "repeats": int(r.n[i]),
                 "s": None if not math.isfinite(r.s[i]) else float(r.s[i]), "calibrated": float(r.y_cal[i]),
                 "U_cal": float(r.U_cal[i]), "k_cal": float(r.k_cal[i]), "U": float(r.U[i]), "k": float(r.k[i]),
                 "deviation": float(dev[i]), "U_c": float(Uc[i]), "u_c": float(r.u_c[i]), "E_n": float(En[i]),
                 "within": bool(En[i] <= 1.0), "claimed_coverage": float(claimed[i])} for i in range(r.size)]
        d = self.diagnosis
        return {"rows": rows, "alpha": self.alpha, "count": self.count.to_json(),
                "count_words": self.count.words(self.alpha),
                "p_count": self.count.p_low, "p_structure": self.p_structure, "structure_basis": self.structure_basis,
                "tests": [{k: v for k, v in t.items()} for t in self.tests],
                "locator": None if d is None else {
                    "records": int(d.prep.rec.n), "rows_of_records": self.members,
                    "chi2": d.chi2_before, "dof": d.dof_before, "p_omnibus": math.exp(d.logp_before),
                    "p_targeted": math.exp(d.logp_targeted), "mismatch": bool(d.mismatch), "gate": d.gate,
                    "effects": [dict(name=e, **_estimate(d, e)) for e in d.chosen], "indicated": d.indicated,
                    "outliers": d.outliers, "noise_scale": d.noise_scale,
                    "groups": [{k: g[k] for k in ("by", "group", "records", "chi2", "dof", "p_value", "flagged")}
                               for g in d.groups if g.get("flagged")],
                    "located": d.located[:WORST], "summary": d.summary},
                "worst": [rows[i] for i in self.worst],
                "verdict": {"holds": self.holds, "verdict": self.verdict, "rule": RULE, "alpha": self.alpha,
                            "causes": self.causes, "cause": self.causes[0]["text"] if self.causes else None,
                            "next_step": self.next_step},
                "correlation_known": self.corr_known}


def _estimate(d: dg.Diagnosis, name: str) -> dict:
    from .locator.report import effect_estimates

    e = effect_estimates(d, name)
    return {"estimate": e["estimate"], "u": e["u"], "unit": fx.BY_NAME[name].unit}


def _fmt(v) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(f"{x:.3g}" for x in v if x is not None) + "]"
    return f"{v:.3g}"


NEXT = {
    "effect": ("the task does not model it: compensate it on the machine, or let cmmwb calibrate name it on the "
               "verification recordings and feed it back (--effects auto, --feedback compensate or factor); then "
               "validate again on workpieces not used in that fit"),
    "noise": ("the model's U is too small for this machine, evenly: estimate the hyper-parameters from this machine's "
              "verification recordings (cmmwb calibrate) and build the tasks from the fitted task; then validate again"),
    "outlier": ("a gross deviation on a few rows: re-measure them and check the workpiece and its certificate before "
                "judging the model"),
    "scale": ("the deviations grow with the size: a scale error the model does not carry (temperature, the machine's "
              "scale compensation): check the compensation and the temperature, or calibrate with --effects scale"),
    "group": ("one workpiece or run deviates: check its setup (fixturing, temperature, probe qualification) and its "
              "certificate"),
    "count": ("too many rows lie beyond E_n = 1 with no structure found: the model's U is too small; calibrate the "
              "hyper-parameters on this machine's recordings (cmmwb calibrate)"),
}


def validate(rows: Rows, geo: Geometry | None = None, model: Model | None = None, alpha: float = ALPHA,
             draws: int = DRAWS, seed: int = SEED) -> Validation:
    """The validation of docs/validate.md: E_n per row, the count against the claimed coverage,
    the structure (the locator on length rows with probed points, plain tests on the others) and
    the verdict under :data:`RULE` with its cause and next step."""
    if not (0.0 < alpha < 1.0):
        raise ModelError(f"alpha must be between 0 and 1, got {alpha!r}")
    use_geo = geo is not None and model is not None and geo.rows.size >= 2
    corr = joint_correlation(rows, geo if use_geo else None, model)
    count = count_test(rows, corr, draws, seed)
    diag, members = None, []
    parts: list[tuple[str, float]] = []
    if use_geo:
        diag, members = locate(rows, geo, model, alpha)
        p_loc = min(1.0, 2.0 * min(math.exp(diag.logp_before), math.exp(diag.logp_targeted)))
        parts.append((f"the mismatch locator on {diag.prep.rec.n} length records (its two gates)", p_loc))
    plain_idx = np.setdiff1d(np.arange(rows.size), geo.rows if use_geo else np.array([], dtype=int))
    tests = plain_tests(rows, plain_idx)
    if tests:
        p_plain = min(1.0, len(tests) * min(t["p"] for t in tests))
        parts.append((f"{len(tests)} test{'s' if len(tests) > 1 else ''} of the rows without probed points "
                      "(Bonferroni)", p_plain))
    p_struct = min(1.0, len(parts) * min(p for _, p in parts)) if parts else 1.0
    basis = "; ".join(f"{w}: p = {p:.3g}" for w, p in parts) + (" (Bonferroni over the parts)" if len(parts) > 1 else "")
    holds = count.p_low >= alpha / 2 and p_struct >= alpha / 2
    causes = [] if holds else _causes(rows, count, diag, members, tests, alpha)
    next_step = ("none: the model's U is borne out by these workpieces (keep the validation with the task; "
                 "repeat it when the machine, the strategy or the environment changes)") if holds \
        else NEXT[causes[0]["kind"]] if causes else NEXT["count"]
    worst = [int(i) for i in np.argsort(-rows.E_n, kind="stable")[:WORST]]
    return Validation(rows, alpha, count, p_struct, basis, holds, causes, next_step, worst, tests, diag, members,
                      corr is not None)


def _causes(rows: Rows, count: Count, diag: dg.Diagnosis | None, members, tests: list[dict],
            alpha: float) -> list[dict]:
    """What the evidence names, the strongest first: effects the locator names (then indicated
    ones), outliers, the noise scale, a scale slope or a group of the plain tests, the count."""
    out = []
    if diag is not None:
        for name in diag.chosen:
            e = _estimate(diag, name)
            out.append({"kind": "effect", "name": name, **e,
                        "text": f"the locator names {name} = {_fmt(e.get('estimate'))} ± {_fmt(e.get('u'))} "
                                f"{e.get('unit', '')} in the length rows (an effect the task's model does not carry)"})
        for ind in diag.indicated:
            out.append({"kind": "effect", "name": ind["name"], "indicated": True,
                        "text": f"the locator indicates {ind['name']} = {_fmt(ind['estimate'])} ± {_fmt(ind['u'])} "
                                f"{ind['unit']} (significant at alpha, not strong enough to name)"})
        for o in diag.outliers:
            rid = o["id"]
            a = diag.prep.rec.ids.index(rid)
            lines = [rows.lines[i] for i in members[a]] if rows.lines else []
            out.append({"kind": "outlier", "record": rid, "rows": members[a], "residual_um": o.get("residual_um"),
                        "text": f"row {rid} (line {', '.join(map(str, lines))}) deviates grossly: "
                                f"{o.get('residual_um', float('nan')):.3g} µm"})
        if diag.noise_scale:
            s = diag.noise_scale
            out.append({"kind": "noise", "scale": s["estimate"], "u": s["u"],
                        "text": f"the length rows deviate {s['estimate']:.3g} ± {s['u']:.2g} times more than the "
                                "model's covariance allows, evenly (no structure a candidate explains)"})
    for t in sorted(tests, key=lambda t: ("slope_um_per_m" not in t, t["p"])):   # a scale slope first
        if t["p"] * len(tests) >= alpha / 2 or t["test"].startswith("chi-square of the characteristics"):
            continue
        if "slope_um_per_m" in t:
            out.append({"kind": "scale", "slope_um_per_m": t["slope_um_per_m"], "u_um_per_m": t["u_um_per_m"],
                        "text": f"the deviations grow with the calibrated value: {t['slope_um_per_m']:.3g} ± "
                                f"{t['u_um_per_m']:.2g} µm/m (a scale error the model does not carry)"})
        else:
            out.append({"kind": "group", "test": t["test"],
                        "text": f"{t['test'][len('chi-square of '):]} deviates: chi2 {t['chi2']:.3g} on {t['dof']} rows "
                                f"(p {t['p']:.2g})"})
    if count.p_low < alpha / 2:
        out.append({"kind": "count", "text": count.words(alpha)})
    if not out:
        plain = next((t for t in tests if t["test"].startswith("chi-square of the characteristics")), None)
        if plain is not None:
            out.append({"kind": "count",
                        "text": f"the characteristics without probed points deviate more than their U allows: chi2 "
                                f"{plain['chi2']:.3g} on {plain['dof']} (p {plain['p']:.2g})"})
        elif diag is not None:
            out.append({"kind": "count", "text": "the locator's gates fire (" + (diag.gate or "") + ") but name no cause"})
    return out


def summary(v: Validation) -> str:
    """The verdict in words: the count, the structure, the cause and the next step."""
    parts = [f"Verdict: {v.verdict} ({len(v.rows.label)} rows; rule: ISO/TS 15530-4 E_n with the count and "
             f"structure tests at alpha = {v.alpha:g}).", v.count.words(v.alpha),
             f"Structure: p = {v.p_structure:.3g} ({v.structure_basis})."]
    if not v.holds:
        parts.append("Cause: " + (v.causes[0]["text"] if v.causes else "not named") + ".")
        parts.append("Next step: " + v.next_step + ".")
    return " ".join(parts)
