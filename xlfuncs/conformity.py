"""Conformity decisions with measurement uncertainty (JCGM 106:2012, ISO 14253-1:2017).

The measurand's state of knowledge after measurement is taken as normal, N(y, u²), with y the
measured value and u its standard uncertainty (JCGM 106:2012, 7.2-7.3).  A tolerance interval
[T_L, T_U] (one limit may be absent: a one-sided interval) specifies the conforming values.

* :func:`probability_of_conformance`: p_c = Φ((T_U - y)/u) - Φ((T_L - y)/u)
  (JCGM 106:2012, 7.3.2 eq. (9)-(10) one-sided, 7.4 eq. (12) two-sided).
* :func:`acceptance_limits`: the acceptance interval [A_L, A_U] of a decision rule: guard band
  w = r·U inside the tolerance interval (guarded acceptance, JCGM 106:2012, 8.3.2), outside it
  (guarded rejection, 8.3.3), none (simple acceptance, 8.2), or, for a stated largest probability
  of false acceptance α (specific risk, 8.3.2 and 9.3), the w at which an item on the acceptance
  limit has p_c = 1 - α exactly: w = z·u with z = Φ⁻¹(1 - α) for a one-sided interval, the root
  of eq. (12) for a two-sided one (:func:`specific_risk_guard_band_um`, Newton steps that the
  Decision sheet repeats cell by cell).
* :func:`decide`: the outcome for one characteristic: ``conforms``, ``does not conform`` or
  ``cannot be decided``, and the zone the measured value falls in.
* :func:`acceptance_limits_for_p_c`: the exact acceptance limits for a required p_c (one- and
  two-sided), :func:`specific_consumer_risk` = 1 - p_c (JCGM 106:2012, 9.3).
* :func:`global_risks`, :func:`guard_band_for_global_risk`: global consumer's and producer's risks
  of a production process with a prior PDF (:func:`normal_prior`, :func:`gamma_prior`) inspected
  by a measuring system N(η, u_m²), and the guard band for a stated global consumer's risk
  (JCGM 106:2012, 9.5; these take any one unit, not mm/µm).

Units: values and limits in mm, uncertainties in µm (the project's convention); the functions
convert with :data:`UM_PER_MM`.  numpy and the standard library only; no spreadsheet knowledge.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .errors import ModelError

UM_PER_MM = 1000.0

#: the decision rules (``DecisionRule.kind``)
RULES = ("simple", "iso14253", "guarded_acceptance", "guarded_rejection", "specific_risk")
RULE_TEXT = {
    "simple": "simple acceptance (JCGM 106:2012, 8.2; ILAC-G8 shared risk): accepted when the "
              "measured value lies in the tolerance interval",
    "iso14253": "ISO 14253-1:2017 default rule: conformance proven when the measured value lies in the "
                "tolerance interval reduced by U on each side, non-conformance proven when it lies "
                "outside the interval enlarged by U; between them the result cannot be decided",
    "guarded_acceptance": "guarded acceptance (JCGM 106:2012, 8.3.2): acceptance interval = tolerance "
                          "interval reduced by the guard band w = r·U",
    "guarded_rejection": "guarded rejection (JCGM 106:2012, 8.3.3): acceptance interval = tolerance "
                         "interval enlarged by the guard band w = r·U",
    "specific_risk": "specific risk (JCGM 106:2012, 9.3): accepted when the probability of conformance "
                     "p_c is at least 1 - max_pfa (the largest probability of false acceptance)",
}

CONFORMS = "conforms"
DOES_NOT_CONFORM = "does not conform"
UNDECIDED = "cannot be decided"


def norm_cdf(z):
    """Φ(z), the standard normal distribution function (via erfc: accurate in both tails)."""
    z = np.asarray(z, float)
    out = 0.5 * np.vectorize(math.erfc, otypes=[float])(-z / math.sqrt(2.0))
    return float(out) if out.ndim == 0 else out


def norm_ppf(p: float) -> float:
    """Φ⁻¹(p) for 0 < p < 1: Acklam's rational start, refined by Newton steps on Φ (full double
    precision; numpy-only, no scipy)."""
    p = float(p)
    if not 0.0 < p < 1.0:
        raise ModelError(f"a probability must lie strictly between 0 and 1, got {p!r}")
    a = (-3.969683028665376e+01, 2.209460984245205e+02, -2.759285104469687e+02,
         1.383577518672690e+02, -3.066479806614716e+01, 2.506628277459239e+00)
    b = (-5.447609879822406e+01, 1.615858368580409e+02, -1.556989798598866e+02,
         6.680131188771972e+01, -1.328068155288572e+01)
    c = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e+00,
         -2.549732539343734e+00, 4.374664141464968e+00, 2.938163982698783e+00)
    d = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00, 3.754408661907416e+00)
    lo = 0.02425
    if p < lo:
        q = math.sqrt(-2 * math.log(p))
        x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) / \
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1)
    elif p > 1 - lo:
        q = math.sqrt(-2 * math.log1p(-p))
        x = -(((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) / \
            ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1)
    else:
        q = p - 0.5
        r = q * q
        x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q / \
            (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1)
    for _ in range(3):          # Newton on Φ(x) - p; in the upper tail on the complement
        pdf = math.exp(-0.5 * x * x) / math.sqrt(2 * math.pi)
        if pdf == 0.0:
            break
        if p > 0.5:
            err = (1.0 - p) - 0.5 * math.erfc(x / math.sqrt(2.0))
            x -= err / pdf
        else:
            err = 0.5 * math.erfc(-x / math.sqrt(2.0)) - p
            x -= err / pdf
    return x


@dataclass(frozen=True)
class Tolerance:
    """A tolerance interval [lsl_mm, usl_mm] (JCGM 106:2012, 3.3.5); ``None`` = no such limit
    (a one-sided interval).  :meth:`symmetric` builds nominal ± tol."""

    lsl_mm: float | None = None
    usl_mm: float | None = None

    def __post_init__(self):
        if self.lsl_mm is None and self.usl_mm is None:
            raise ModelError("a tolerance needs a lower or an upper specification limit (lsl_mm, usl_mm)")
        for name in ("lsl_mm", "usl_mm"):
            v = getattr(self, name)
            if v is not None and not math.isfinite(float(v)):
                raise ModelError(f"{name} = {v!r} is not a finite number")
        if self.lsl_mm is not None and self.usl_mm is not None and not self.lsl_mm < self.usl_mm:
            raise ModelError(f"the lower specification limit lsl_mm = {self.lsl_mm} must be below the "
                             f"upper usl_mm = {self.usl_mm}")

    @classmethod
    def symmetric(cls, nominal_mm: float, tol_mm: float) -> "Tolerance":
        if not (math.isfinite(tol_mm) and tol_mm > 0):
            raise ModelError(f"tol_mm = {tol_mm!r} must be a positive number (the interval is nominal ± tol_mm)")
        return cls(nominal_mm - tol_mm, nominal_mm + tol_mm)

    @property
    def two_sided(self) -> bool:
        return self.lsl_mm is not None and self.usl_mm is not None

    @property
    def mid_mm(self) -> float | None:
        if self.lsl_mm is None or self.usl_mm is None:
            return None
        return 0.5 * (self.lsl_mm + self.usl_mm)


@dataclass(frozen=True)
class DecisionRule:
    """How a measured value is turned into a decision.

    ``kind``: one of :data:`RULES`; ``r``: guard band factor, w = r·U (guarded rules);
    ``max_pfa``: the largest probability of false acceptance of the specific-risk rule."""

    kind: str = "iso14253"
    r: float = 1.0
    max_pfa: float = 0.05

    def __post_init__(self):
        if self.kind not in RULES:
            raise ModelError(f"unknown decision rule {self.kind!r}; choose one of {', '.join(RULES)}")
        if not (math.isfinite(self.r) and self.r >= 0):
            raise ModelError(f"r = {self.r!r} must be a number >= 0 (guard band w = r·U)")
        if not (math.isfinite(self.max_pfa) and 0 < self.max_pfa < 0.5):
            raise ModelError(f"max_pfa = {self.max_pfa!r} must lie strictly between 0 and 0.5")

    @property
    def text(self) -> str:
        extra = ""
        if self.kind in ("guarded_acceptance", "guarded_rejection"):
            extra = f", r = {self.r:g}"
        elif self.kind == "specific_risk":
            extra = f", max_pfa = {self.max_pfa:g}"
        return RULE_TEXT[self.kind] + extra


@dataclass(frozen=True)
class Decision:
    """The outcome for one characteristic; lengths in mm, uncertainties in µm."""

    value_mm: float
    u_um: float
    U_um: float
    k: float
    tolerance: Tolerance
    rule: DecisionRule
    w_um: float                      #: guard band (> 0 inside the tolerance interval, < 0 outside)
    acceptance_mm: tuple[float | None, float | None]   #: [A_L, A_U]
    rejection_mm: tuple[float | None, float | None]    #: beyond these: does not conform (iso14253)
    p_c: float                       #: probability of conformance
    outcome: str                     #: conforms / does not conform / cannot be decided
    zone: str

    def as_dict(self) -> dict:
        return {"value_mm": self.value_mm, "u_um": self.u_um, "U_um": self.U_um, "k": self.k,
                "lsl_mm": self.tolerance.lsl_mm, "usl_mm": self.tolerance.usl_mm,
                "rule": self.rule.kind, "r": self.rule.r, "max_pfa": self.rule.max_pfa,
                "w_um": self.w_um, "acceptance_limits_mm": list(self.acceptance_mm),
                "acceptance_interval_empty": empty(self.acceptance_mm),
                "p_c": self.p_c, "outcome": self.outcome, "zone": self.zone}


def probability_of_conformance(value_mm, u_um, tolerance: Tolerance):
    """p_c = Pr(T_L <= Y <= T_U | y) for Y ~ N(y, u²) (JCGM 106:2012, 7.3 and 7.4).

    ``value_mm`` and ``u_um`` may be arrays (broadcast)."""
    y = np.asarray(value_mm, float)
    u_mm = np.asarray(u_um, float) / UM_PER_MM
    if np.any(~(u_mm > 0)):
        raise ModelError("the standard uncertainty u must be positive to compute a probability of conformance")
    p = np.ones(np.broadcast(y, u_mm).shape)
    if tolerance.usl_mm is not None:
        p = norm_cdf((tolerance.usl_mm - y) / u_mm)
    if tolerance.lsl_mm is not None:
        p = p - norm_cdf((tolerance.lsl_mm - y) / u_mm)
    p = np.asarray(p, float)
    return float(p) if p.ndim == 0 else p


def guard_band_um(rule: DecisionRule, U_um: float, k: float) -> float:
    """The guard band w (µm), positive when the acceptance interval lies inside the tolerance
    interval: r·U (guarded acceptance), -r·U (guarded rejection), 0 (simple acceptance),
    U (ISO 14253-1 conformance zone), z·u with z = Φ⁻¹(1 - max_pfa) (specific risk: exact for a
    one-sided interval; :func:`decide` takes the exact two-sided one from
    :func:`specific_risk_guard_band_um`)."""
    if rule.kind == "simple":
        return 0.0
    if rule.kind == "iso14253":
        return float(U_um)
    if rule.kind == "guarded_acceptance":
        return rule.r * float(U_um)
    if rule.kind == "guarded_rejection":
        return -rule.r * float(U_um)
    return norm_ppf(1.0 - rule.max_pfa) * float(U_um) / float(k)


#: Newton steps of :func:`specific_risk_iterates` (the Decision sheet has one column per step)
NEWTON_STEPS = 5


def specific_risk_iterates(h: float, max_pfa: float, steps: int = NEWTON_STEPS) -> list[float]:
    """Newton's iteration for the exact specific-risk acceptance limit of a two-sided interval.

    With h = (T_U - T_L)/(2u) and the acceptance limits at the midpoint ± d·u, an item on the limit
    has p_c = Φ(h - d) + Φ(h + d) - 1 (JCGM 106:2012, 7.4 eq. (12)); the limit is the root of
    G(s) = Φ(h - √s) + Φ(h + √s) - 2 + α, s = d² (α = max_pfa).  In s the root is simple even where
    the acceptance interval shrinks to the midpoint (G'(0) = -h φ(h) ≠ 0; in d it would be a
    double root), so Newton converges quadratically from the one-sided start s₀ = max(0, h - z)²,
    z = Φ⁻¹(1 - α): an overshoot below 0 is cut to 0, from where G is convex and the steps rise
    monotonically to the root.  G'(s) = (φ(h + d) - φ(h - d))/(2d), -h φ(h) at s = 0.  Returns
    [s₀, s₁, ..., s_steps].  Five steps reach the root to the conditioning of the problem (about
    1e-7 in d at the very edge where the interval vanishes, 1e-12 and better elsewhere; measured
    against the bisection of :func:`acceptance_limits_for_p_c` for 1 - α = 0.5001 ... 0.999999)."""
    z = norm_ppf(1.0 - max_pfa)
    s = max(0.0, h - z) ** 2
    out = [s]
    for _ in range(steps):
        d = math.sqrt(s)
        g = float(norm_cdf(h - d)) + float(norm_cdf(h + d)) - 2.0 + max_pfa
        dg = -h * _pdf(h) if s == 0.0 else (_pdf(h + d) - _pdf(h - d)) / (2.0 * d)
        s = max(0.0, s - g / dg)
        out.append(s)
    return out


def _pdf(x: float) -> float:
    return math.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)


def specific_risk_guard_band_um(tolerance: Tolerance, u_um: float, max_pfa: float) -> float:
    """The guard band w (µm) of the specific-risk rule: an item on the acceptance limit has
    p_c = 1 - max_pfa (JCGM 106:2012, 8.3.2 and 9.3).  One-sided: w = z·u, z = Φ⁻¹(1 - max_pfa)
    (7.3 Table 1).  Two-sided: w = (h - d)·u with d = √s from :func:`specific_risk_iterates`;
    when even the midpoint has p_c < 1 - max_pfa nothing can be accepted and w is half the
    tolerance (1 + 1e-9), which crosses the limits (:func:`empty`), as
    :func:`acceptance_limits_for_p_c` does."""
    u = float(u_um)
    if not tolerance.two_sided:
        return norm_ppf(1.0 - max_pfa) * u
    assert tolerance.lsl_mm is not None and tolerance.usl_mm is not None
    half_um = (tolerance.usl_mm - tolerance.lsl_mm) * UM_PER_MM / 2.0
    h = half_um / u
    if float(norm_cdf(h)) - float(norm_cdf(-h)) < 1.0 - max_pfa:
        return half_um * (1.0 + 1e-9)
    return (h - math.sqrt(specific_risk_iterates(h, max_pfa)[-1])) * u


def acceptance_limits(tolerance: Tolerance, w_um: float) -> tuple[float | None, float | None]:
    """[A_L, A_U] = [T_L + w, T_U - w] (JCGM 106:2012, 8.3.1); a missing limit stays None.

    A guard band of half the tolerance or more gives A_L >= A_U: an empty acceptance interval, in
    which no measured value lies (the uncertainty is too large for the tolerance, JCGM 106:2012,
    8.3.2); every value is then rejected (``does not conform``) or, by the ISO 14253-1 rule, at best
    undecided."""
    w = w_um / UM_PER_MM
    lo = None if tolerance.lsl_mm is None else tolerance.lsl_mm + w
    hi = None if tolerance.usl_mm is None else tolerance.usl_mm - w
    return lo, hi


def empty(limits: tuple[float | None, float | None]) -> bool:
    """True when an acceptance interval [A_L, A_U] holds no value (A_L > A_U)."""
    lo, hi = limits
    return lo is not None and hi is not None and lo > hi


def _inside(y: float, lo: float | None, hi: float | None) -> bool:
    return (lo is None or y >= lo) and (hi is None or y <= hi)


def decide(value_mm: float, u_um: float, tolerance: Tolerance, rule: DecisionRule, k: float = 2.0) -> Decision:
    """The decision for one characteristic measured as ``value_mm`` with standard uncertainty
    ``u_um`` and expanded uncertainty U = k·u.

    Binary rules (simple, guarded acceptance/rejection, specific risk) accept (``conforms``,
    acceptance zone) or reject (``does not conform``, rejection zone).  The ISO 14253-1 rule has
    three outcomes: conformance zone, non-conformance zone, and the uncertainty range between
    them (``cannot be decided``)."""
    y = float(value_mm)
    u = float(u_um)
    if not (math.isfinite(y) and math.isfinite(u) and u > 0 and math.isfinite(k) and k > 0):
        raise ModelError(f"a decision needs a finite value and u > 0, k > 0 (value {y!r} mm, u {u!r} µm, k {k!r})")
    U = k * u
    p_c = probability_of_conformance(y, u, tolerance)
    w = (specific_risk_guard_band_um(tolerance, u, rule.max_pfa) if rule.kind == "specific_risk"
         else guard_band_um(rule, U, k))
    acc = acceptance_limits(tolerance, w)
    rej: tuple[float | None, float | None] = (None, None)
    if rule.kind == "iso14253":
        rej = acceptance_limits(tolerance, -U)
        if _inside(y, *acc):
            outcome, zone = CONFORMS, "conformance zone"
        elif not _inside(y, *rej):
            outcome, zone = DOES_NOT_CONFORM, "non-conformance zone"
        else:
            outcome, zone = UNDECIDED, "uncertainty range"
    elif rule.kind == "specific_risk":
        ok = p_c >= 1.0 - rule.max_pfa
        outcome, zone = (CONFORMS, "acceptance zone") if ok else (DOES_NOT_CONFORM, "rejection zone")
    else:
        ok = _inside(y, *acc)
        outcome, zone = (CONFORMS, "acceptance zone") if ok else (DOES_NOT_CONFORM, "rejection zone")
    return Decision(value_mm=y, u_um=u, U_um=U, k=float(k), tolerance=tolerance, rule=rule, w_um=w,
                    acceptance_mm=acc, rejection_mm=rej, p_c=p_c, outcome=outcome, zone=zone)


def measurement_capability_index(tolerance: Tolerance, u_um: float) -> float:
    """C_m = (T_U - T_L) / (4 u) (JCGM 106:2012, 7.6 eq. (15)); two-sided intervals only."""
    if tolerance.lsl_mm is None or tolerance.usl_mm is None:      # not two-sided
        raise ModelError("the measurement capability index needs a two-sided tolerance interval")
    return (tolerance.usl_mm - tolerance.lsl_mm) * UM_PER_MM / (4.0 * float(u_um))


# -- specific risk and acceptance limits from a required probability of conformance -------------

def specific_consumer_risk(value_mm, u_um, tolerance: Tolerance):
    """R_C* = 1 - p_c, the probability that an item accepted with measured value y does not
    conform (JCGM 106:2012, 9.3: the specific consumer's risk of an accepted item)."""
    return 1.0 - probability_of_conformance(value_mm, u_um, tolerance)


def acceptance_limits_for_p_c(tolerance: Tolerance, u_um: float, p_min: float) -> tuple[float | None, float | None]:
    """The acceptance limits [A_L, A_U] (mm) at which an accepted item has exactly p_c = p_min.

    One-sided interval: A_U = T_U - z·u, A_L = T_L + z·u with z = Φ⁻¹(p_min) (JCGM 106:2012, 7.3
    Table 1, 8.3.2).  Two-sided interval: the far limit adds to 1 - p_c, so the exact limit is the
    root of Φ((T_U - A)/u) - Φ((T_L - A)/u) = p_min (JCGM 106:2012, 7.4 eq. (12)) on the side of
    each limit, found by bisection (p_c falls monotonically from the midpoint outwards; p_min < 1/2
    puts the limits outside the tolerance interval, guarded rejection).
    When even the midpoint has p_c < p_min no value can be accepted: the limits are returned
    crossed (A_L > A_U), which :func:`empty` reports."""
    u_mm = float(u_um) / UM_PER_MM
    if not (math.isfinite(u_mm) and u_mm > 0):
        raise ModelError(f"u = {u_um!r} µm must be a positive number")
    if not 0.0 < p_min < 1.0:
        raise ModelError(f"p_min = {p_min!r} must lie strictly between 0 and 1")
    z = norm_ppf(p_min)
    if not tolerance.two_sided:
        return acceptance_limits(tolerance, z * float(u_um))
    mid, usl, lsl = tolerance.mid_mm, tolerance.usl_mm, tolerance.lsl_mm
    assert mid is not None and usl is not None and lsl is not None       # two-sided
    if probability_of_conformance(mid, u_um, tolerance) < p_min:
        return acceptance_limits(tolerance, 0.5 * (usl - lsl) * UM_PER_MM * (1 + 1e-9))
    lo, hi = mid, usl + 40 * u_mm   # p_c(lo) >= p_min > p_c(hi) ≈ 0: bisect on the upper side
    for _ in range(200):
        m = 0.5 * (lo + hi)
        if probability_of_conformance(m, u_um, tolerance) >= p_min:
            lo = m
        else:
            hi = m
        if hi - lo <= 4e-16 * max(1.0, abs(hi)):
            break
    a_u = lo
    return 2.0 * mid - a_u, a_u              # symmetric: p_c(mid - d) = p_c(mid + d)


# -- global risks with a prior PDF of the production process (JCGM 106:2012, 9.5) ----------------

@dataclass(frozen=True)
class Prior:
    """The prior PDF g₀(η) of the property η of items from a production process (JCGM 106:2012,
    9.5): ``pdf`` (vectorised callable) on the support [lo, hi] (finite bounds that hold
    all but a negligible part of the probability).  Any one unit (that of the tolerance limits and
    of u_m)."""

    pdf: Callable[[np.ndarray], np.ndarray]
    lo: float
    hi: float
    text: str = ""


def normal_prior(mean: float, sd: float) -> Prior:
    """g₀ = N(y₀, u₀²) (JCGM 106:2012, 9.5, normal process PDF), cut at ± 40 u₀ (the
    mass beyond is below 1e-300)."""
    if not (math.isfinite(mean) and math.isfinite(sd) and sd > 0):
        raise ModelError(f"a normal prior needs a finite mean and sd > 0 (got {mean!r}, {sd!r})")
    c = 1.0 / (sd * math.sqrt(2 * math.pi))
    return Prior(lambda x: c * np.exp(-0.5 * ((np.asarray(x, float) - mean) / sd) ** 2),
                 mean - 40 * sd, mean + 40 * sd, f"N({mean:g}, {sd:g}²)")


def gamma_prior(shape: float, rate: float) -> Prior:
    """g₀(η) = β^α η^(α-1) e^(-βη) / Γ(α) on η >= 0 (shape α, rate β): a quantity bounded below
    by zero, such as the radial error motion of a bearing (JCGM 106:2012, 9.5.4).  Cut above at
    the mean + 60 standard deviations."""
    if not (math.isfinite(shape) and math.isfinite(rate) and shape >= 1 and rate > 0):
        raise ModelError(f"a gamma prior needs shape >= 1 and rate > 0 (got {shape!r}, {rate!r})")
    log_c = shape * math.log(rate) - math.lgamma(shape)

    def pdf(x):
        x = np.asarray(x, float)
        with np.errstate(divide="ignore"):
            out = np.exp(log_c + (shape - 1) * np.log(np.where(x > 0, x, 1.0)) - rate * x)
        return np.where(x > 0, out, 0.0 if shape > 1 else math.exp(log_c))

    return Prior(pdf, 0.0, shape / rate + 60 * math.sqrt(shape) / rate, f"Gamma(α = {shape:g}, β = {rate:g})")


_GL_X, _GL_W = np.polynomial.legendre.leggauss(20)


def _integrate(f, a: float, b: float, step: float) -> float:
    """∫_a^b f by composite 20-point Gauss-Legendre on panels no wider than ``step``."""
    if not b > a:
        return 0.0
    n = max(1, min(20000, int(math.ceil((b - a) / step))))
    edges = np.linspace(a, b, n + 1)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[:-1] + edges[1:])
    x = (mid[:, None] + half[:, None] * _GL_X[None, :]).ravel()
    return float(np.sum(f(x).reshape(n, -1) * _GL_W[None, :] * half[:, None]))


def _p_accept(eta, u_m: float, acceptance):
    """Pr(η_m ∈ A | η) for η_m ~ N(η, u_m²) (JCGM 106:2012, 9.5: the measuring system's PDF)."""
    lo, hi = acceptance
    p = norm_cdf((hi - np.asarray(eta, float)) / u_m) if hi is not None else np.ones(np.shape(eta))
    if lo is not None:
        p = p - norm_cdf((lo - np.asarray(eta, float)) / u_m)
    return np.asarray(p, float)


def _pieces(prior: Prior, tolerance_limits, acceptance, u_m: float):
    """The support of the prior cut at the tolerance limits and at A ± 12 u_m around each
    acceptance limit: [(a, b, conforming?, near an acceptance limit?)].  Outside those windows
    Pr(η_m ∈ A | η) is 0 or 1 to within Φ(-12) ≈ 2e-33, so the integrand is as smooth as the prior."""
    t_lo, t_hi = tolerance_limits
    win = [(a - 12 * u_m, a + 12 * u_m) for a in acceptance if a is not None]
    pts = [t for t in (t_lo, t_hi) if t is not None] + [x for w in win for x in w]
    cuts = sorted({prior.lo, prior.hi, *(t for t in pts if prior.lo < t < prior.hi)})
    out = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        m = 0.5 * (a + b)
        ok = (t_lo is None or m >= t_lo) and (t_hi is None or m <= t_hi)
        near = any(lo <= m <= hi for lo, hi in win)
        out.append((a, b, ok, near))
    return out


@dataclass(frozen=True)
class GlobalRisks:
    """Global risks of a conformity assessment of items of one production process."""

    consumer: float            #: R_C: an item chosen at random is accepted and does not conform
    producer: float            #: R_P: an item chosen at random is rejected and conforms
    nonconforming: float       #: the prior probability that an item does not conform (no inspection)


def global_risks(prior: Prior, u_m: float, tolerance_limits, acceptance) -> GlobalRisks:
    """R_C and R_P (JCGM 106:2012, 9.5):

        R_C = ∫_{η ∉ C} g₀(η) ∫_{η_m ∈ A} h(η_m | η) dη_m dη,
        R_P = ∫_{η ∈ C} g₀(η) ∫_{η_m ∉ A} h(η_m | η) dη_m dη,

    with h(η_m | η) = N(η, u_m²) the measuring system's PDF, C = [T_L, T_U] the tolerance
    interval and A = [A_L, A_U] the acceptance interval (``None`` = no such limit; any one unit).
    The inner integrals are normal distribution functions; the outer one is composite Gauss-Legendre
    quadrature split at the tolerance limits, with panels no wider than u_m/8 within 12 u_m of an
    acceptance limit and no wider than 1/640 of the prior's support elsewhere."""
    if not (math.isfinite(u_m) and u_m > 0):
        raise ModelError(f"u_m = {u_m!r} must be a positive number")
    coarse = (prior.hi - prior.lo) / 640.0
    r_c = r_p = bad = 0.0
    for a, b, ok, near in _pieces(prior, tolerance_limits, acceptance, u_m):
        step = min(coarse, u_m / 8.0) if near else coarse
        if ok:
            r_p += _integrate(lambda x: prior.pdf(x) * (1.0 - _p_accept(x, u_m, acceptance)), a, b, step)
        else:
            r_c += _integrate(lambda x: prior.pdf(x) * _p_accept(x, u_m, acceptance), a, b, step)
            bad += _integrate(prior.pdf, a, b, step)
    return GlobalRisks(consumer=r_c, producer=r_p, nonconforming=bad)


def guard_band_for_global_risk(prior: Prior, u_m: float, tolerance_limits, max_consumer_risk: float) -> float:
    """The guard band w >= 0 (acceptance limits A_L = T_L + w, A_U = T_U - w) at which the global
    consumer's risk R_C equals ``max_consumer_risk`` (JCGM 106:2012, 9.5.4: an acceptance limit
    chosen so that R_C does not exceed a stated value).  R_C falls as w grows; bisection to
    1e-13 of the tolerance scale.  0 when simple acceptance already meets the target."""
    t_lo, t_hi = tolerance_limits
    if not 0.0 < max_consumer_risk < 1.0:
        raise ModelError(f"max_consumer_risk = {max_consumer_risk!r} must lie strictly between 0 and 1")

    def r_c(w):
        acc = (None if t_lo is None else t_lo + w, None if t_hi is None else t_hi - w)
        return global_risks(prior, u_m, tolerance_limits, acc).consumer

    if r_c(0.0) <= max_consumer_risk:
        return 0.0
    width = (t_hi - t_lo) / 2.0 if (t_lo is not None and t_hi is not None) else prior.hi - prior.lo
    lo, hi = 0.0, width
    if r_c(hi) > max_consumer_risk:
        raise ModelError("no guard band inside the tolerance interval reaches the stated consumer's risk")
    scale = max(abs(v) for v in (t_lo, t_hi, width) if v is not None)
    while hi - lo > 1e-13 * scale:
        m = 0.5 * (lo + hi)
        if r_c(m) > max_consumer_risk:
            lo = m
        else:
            hi = m
    return 0.5 * (lo + hi)


# -- global risks of a normal process in closed quadrature (what the Decision sheet computes) -------

#: Gauss-Legendre points per panel of :func:`global_risks_normal` (the Decision sheet's node table)
GL_POINTS = 48
#: the standardised integration variable runs over [-GL_RANGE, GL_RANGE] (φ beyond: below 1e-31)
GL_RANGE = 12.0
GL_NODES, GL_WEIGHTS = (tuple(float(v) for v in a) for a in np.polynomial.legendre.leggauss(GL_POINTS))


def risk_panels(mean_mm: float, sd_um: float, u_um: float, tolerance: Tolerance,
                acceptance_mm: tuple[float | None, float | None]) -> dict:
    """The panels of :func:`global_risks_normal`: which variable is integrated and, per risk
    piece, the intervals [a, b] (clamped to ±GL_RANGE) and the integrand's kind.

    A missing limit (one-sided tolerance) stands in at mean ∓ 1000·(σ₀ + u), where every normal
    probability beyond it is 0 in double precision."""
    far = 1000.0 * (sd_um + u_um) / UM_PER_MM
    t_l = tolerance.lsl_mm if tolerance.lsl_mm is not None else mean_mm - far
    t_u = tolerance.usl_mm if tolerance.usl_mm is not None else mean_mm + far
    a_l = acceptance_mm[0] if acceptance_mm[0] is not None else mean_mm - far
    a_u = acceptance_mm[1] if acceptance_mm[1] is not None else mean_mm + far
    return {"T_L": t_l, "T_U": t_u, "A_L": a_l, "A_U": a_u, "over_error": u_um <= sd_um}


def _clamp(a: float, b: float) -> tuple[float, float]:
    a = min(max(a, -GL_RANGE), GL_RANGE)
    b = min(max(b, -GL_RANGE), GL_RANGE)
    return a, max(a, b)


def _gl(f, a: float, b: float) -> float:
    """Σ w_i f(m + h x_i) h on [a, b] (clamped), the sum one SUMPRODUCT of the sheet forms."""
    a, b = _clamp(a, b)
    h = (b - a) / 2.0
    x = (a + b) / 2.0 + h * np.asarray(GL_NODES)
    return float(np.sum(np.asarray(GL_WEIGHTS) * f(x)) * h)


def _phi(x):
    return np.exp(-0.5 * np.asarray(x) ** 2) / math.sqrt(2.0 * math.pi)


def global_risks_normal(mean_mm: float, sd_um: float, u_um: float, tolerance: Tolerance,
                        acceptance_mm: tuple[float | None, float | None]) -> GlobalRisks:
    """Global consumer's and producer's risks (JCGM 106:2012, 9.5) of a normal process
    η ~ N(μ, σ₀²) measured with a normal error e ~ N(0, u²) and accepted when η_m = η + e lies in
    [A_L, A_U], by fixed Gauss-Legendre panels that the Decision sheet repeats with SUMPRODUCT.

    The integral runs over the standardised variable with the smaller standard deviation, so that
    the other one's distribution function, the integrand's second factor, varies no faster than the
    normal density: over v = e/u when u <= σ₀, over x = (η - μ)/σ₀ otherwise.  Each risk is the sum
    of its own small pieces, written with the tail (Φ or Q = 1 - Φ) in which they are small, so
    that no difference of numbers near 1 loses the digits of a small risk:

    * over v: R_C = P(η > T_U, η_m ∈ A) + P(η < T_L, η_m ∈ A),
      R_P = P(η ∈ C, η_m > A_U) + P(η ∈ C, η_m < A_L), each an integral of φ(v) times a difference
      of prior tails at A - u v, T, split where the integrand's form changes (v = (A - T)/u);
    * over x: R_C = ∫_{x ∉ C} φ(x) Pr(η_m ∈ A | η) dx, R_P = ∫_{x ∈ C} φ(x) Pr(η_m ∉ A | η) dx.

    An empty acceptance interval accepts nothing: R_C = 0, R_P = Pr(η ∈ C).  Lengths in mm, σ₀
    and u in µm.  Checked against :func:`global_risks` (adaptive quadrature) in the tests."""
    if not (math.isfinite(sd_um) and sd_um > 0 and math.isfinite(u_um) and u_um > 0):
        raise ModelError(f"a normal process needs sd > 0 and u > 0 (got {sd_um!r} µm, {u_um!r} µm)")
    p = risk_panels(mean_mm, sd_um, u_um, tolerance, acceptance_mm)
    t_l, t_u, a_l, a_u = p["T_L"], p["T_U"], p["A_L"], p["A_U"]
    s0, u = sd_um / UM_PER_MM, u_um / UM_PER_MM
    x_l, x_u = (t_l - mean_mm) / s0, (t_u - mean_mm) / s0
    nonconforming = float(norm_cdf(x_l)) + float(norm_cdf(-x_u))
    if a_l > a_u:
        return GlobalRisks(consumer=0.0, producer=1.0 - nonconforming, nonconforming=nonconforming)
    if p["over_error"]:
        def P0(t):    # prior distribution function Φ((t - μ)/σ₀)
            return norm_cdf((np.asarray(t) - mean_mm) / s0)

        def Q0(t):    # its upper tail
            return norm_cdf((mean_mm - np.asarray(t)) / s0)

        v1, v2, v3, v4 = (a_l - t_l) / u, (a_u - t_u) / u, (a_u - t_l) / u, (a_l - t_u) / u
        V = GL_RANGE
        r_c = (_gl(lambda v: _phi(v) * (Q0(a_l - u * v) - Q0(a_u - u * v)), -V, v4)
               + _gl(lambda v: _phi(v) * (Q0(t_u) - Q0(a_u - u * v)), v4, v2)
               + _gl(lambda v: _phi(v) * (P0(t_l) - P0(a_l - u * v)), v1, v3)
               + _gl(lambda v: _phi(v) * (P0(a_u - u * v) - P0(a_l - u * v)), v3, V))
        r_p = (_gl(lambda v: _phi(v) * (Q0(a_u - u * v) - Q0(t_u)), v2, v3)
               + _gl(lambda v: _phi(v) * (Q0(t_l) - Q0(t_u)), v3, V)
               + _gl(lambda v: _phi(v) * (P0(t_u) - P0(t_l)), -V, v4)
               + _gl(lambda v: _phi(v) * (P0(a_l - u * v) - P0(t_l)), v4, v1))
    else:
        def eta(x):
            return mean_mm + s0 * np.asarray(x)

        V = GL_RANGE
        r_c = (_gl(lambda x: _phi(x) * (norm_cdf((eta(x) - a_l) / u) - norm_cdf((eta(x) - a_u) / u)), -V, x_l)
               + _gl(lambda x: _phi(x) * (norm_cdf((a_u - eta(x)) / u) - norm_cdf((a_l - eta(x)) / u)), x_u, V))
        r_p = _gl(lambda x: _phi(x) * (norm_cdf((a_l - eta(x)) / u) + norm_cdf((eta(x) - a_u) / u)), x_l, x_u)
    return GlobalRisks(consumer=r_c, producer=r_p, nonconforming=nonconforming)
