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
* :func:`decide`: for one characteristic, two separate things (ISO 14253-1:2017, ILAC-G8:09/2019):
  the outcome of the decision rule (``accepted`` or ``rejected`` under the named rule, and the
  rule's zone: acceptance or rejection zone; the ISO 14253-1 rule: ``conforms``, ``does not
  conform`` or ``cannot be decided``), and the conformity statement the value and its U prove
  whatever the rule (``conformity proven`` in [T_L + U, T_U - U], ``non-conformity proven``
  outside [T_L - U, T_U + U], else ``neither proven``: the uncertainty range).  A value outside
  its tolerance interval can be *accepted* by guarded rejection, never said to conform; one
  inside it can be *rejected*, never said not to conform.
* :func:`acceptance_limits_for_p_c`: the exact acceptance limits for a required p_c (one- and
  two-sided), :func:`specific_consumer_risk` = 1 - p_c (JCGM 106:2012, 9.3).
* the global risks of a production process (JCGM 106:2012, 9.5) are in :mod:`xlfuncs.global_risk`.

Units: values and limits in mm, uncertainties in µm (the project's convention); the functions
convert with :data:`UM_PER_MM`.  numpy and the standard library only; no spreadsheet knowledge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .distributions import norm_cdf, norm_pdf, norm_ppf  # noqa: F401  (re-exported)
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
#: the outcome of a binary rule (simple, guarded acceptance/rejection, specific risk)
ACCEPTED = "accepted"
REJECTED = "rejected"
#: the ISO 14253-1 conformity statement, whatever the rule: what the value and U prove
CONFORMITY_PROVEN = "conformity proven"
NONCONFORMITY_PROVEN = "non-conformity proven"
NEITHER_PROVEN = "neither proven"
#: the zones of ISO 14253-1:2017 (5.2, 5.3): by conformity statement
CONFORMITY_ZONES = {CONFORMITY_PROVEN: "conformance zone", NONCONFORMITY_PROVEN: "non-conformance zone",
                    NEITHER_PROVEN: "uncertainty range"}
#: the rule's outcome in two words, by the ``outcome`` of each rule
RULE_OUTCOME = {CONFORMS: ACCEPTED, DOES_NOT_CONFORM: REJECTED, UNDECIDED: UNDECIDED, ACCEPTED: ACCEPTED,
                REJECTED: REJECTED}
#: a rule's short name, for "accepted (guarded rejection)"
RULE_NAME = {"simple": "simple acceptance", "iso14253": "ISO 14253-1", "guarded_acceptance": "guarded acceptance",
             "guarded_rejection": "guarded rejection", "specific_risk": "specific risk"}


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


#: the smallest max_pfa of the specific-risk rule: p_c >= 1 - max_pfa is still decidable in double
#: precision (and in the Decision sheet's NORMSINV); 1e-17 would make 1 - max_pfa exactly 1
MIN_PFA = 1e-9


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
        if not (math.isfinite(self.max_pfa) and MIN_PFA <= self.max_pfa < 0.5):
            raise ModelError(f"max_pfa = {self.max_pfa!r} must lie between {MIN_PFA:g} and 0.5 (0.5 excluded; "
                             f"below {MIN_PFA:g}, 1 - max_pfa is 1 to the precision of the decision)")

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
    #: the non-conformance limits [T_L - U, T_U + U]: beyond them non-conformity is proven
    #: (ISO 14253-1:2017, 5.3), whatever the rule
    rejection_mm: tuple[float | None, float | None]
    p_c: float                       #: probability of conformance
    #: the rule's outcome: conforms / does not conform / cannot be decided (ISO 14253-1 rule),
    #: accepted / rejected (the binary rules)
    outcome: str
    zone: str                        #: the rule's zone of the value
    #: the conformance limits [T_L + U, T_U - U]: inside them conformity is proven (5.2)
    conformance_mm: tuple[float | None, float | None] = (None, None)
    conformity: str = NEITHER_PROVEN   #: conformity proven / non-conformity proven / neither proven

    @property
    def rule_outcome(self) -> str:
        """accepted / rejected / cannot be decided (the ISO 14253-1 rule's uncertainty range)."""
        return RULE_OUTCOME[self.outcome]

    @property
    def conformity_zone(self) -> str:
        return CONFORMITY_ZONES[self.conformity]

    def as_dict(self) -> dict:
        return {"value_mm": self.value_mm, "u_um": self.u_um, "U_um": self.U_um, "k": self.k,
                "lsl_mm": self.tolerance.lsl_mm, "usl_mm": self.tolerance.usl_mm,
                "rule": self.rule.kind, "r": self.rule.r, "max_pfa": self.rule.max_pfa,
                "w_um": self.w_um, "acceptance_limits_mm": list(self.acceptance_mm),
                "acceptance_interval_empty": empty(self.acceptance_mm),
                "p_c": self.p_c, "outcome": self.outcome, "zone": self.zone,
                "rule_outcome": self.rule_outcome, "rule_name": RULE_NAME[self.rule.kind],
                "conformity": self.conformity, "conformity_zone": self.conformity_zone,
                "conformance_limits_mm": list(self.conformance_mm),
                "non_conformance_limits_mm": list(self.rejection_mm)}


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
        dg = -h * norm_pdf(h) if s == 0.0 else (norm_pdf(h + d) - norm_pdf(h - d)) / (2.0 * d)
        s = max(0.0, s - g / dg)
        out.append(s)
    return out


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

    Binary rules (simple, guarded acceptance/rejection, specific risk) accept (``accepted``,
    acceptance zone) or reject (``rejected``, rejection zone).  The ISO 14253-1 rule has three
    outcomes: conformance zone (``conforms``), non-conformance zone (``does not conform``), and
    the uncertainty range between them (``cannot be decided``).  Whatever the rule, the
    conformity statement says what the value and U prove (ISO 14253-1:2017, 5.2, 5.3):
    ``conformity proven`` in [T_L + U, T_U - U], ``non-conformity proven`` outside
    [T_L - U, T_U + U], else ``neither proven``."""
    y = float(value_mm)
    u = float(u_um)
    if not (math.isfinite(y) and math.isfinite(u) and u > 0 and math.isfinite(k) and k > 0):
        raise ModelError(f"a decision needs a finite value and u > 0, k > 0 (value {y!r} mm, u {u!r} µm, k {k!r})")
    U = k * u
    p_c = probability_of_conformance(y, u, tolerance)
    w = (specific_risk_guard_band_um(tolerance, u, rule.max_pfa) if rule.kind == "specific_risk"
         else guard_band_um(rule, U, k))
    acc = acceptance_limits(tolerance, w)
    conf = acceptance_limits(tolerance, U)
    rej = acceptance_limits(tolerance, -U)
    if _inside(y, *conf) and not empty(conf):
        conformity = CONFORMITY_PROVEN
    elif not _inside(y, *rej):
        conformity = NONCONFORMITY_PROVEN
    else:
        conformity = NEITHER_PROVEN
    if rule.kind == "iso14253":
        outcome, zone = {CONFORMITY_PROVEN: (CONFORMS, "conformance zone"),
                         NONCONFORMITY_PROVEN: (DOES_NOT_CONFORM, "non-conformance zone"),
                         NEITHER_PROVEN: (UNDECIDED, "uncertainty range")}[conformity]
    else:
        ok = p_c >= 1.0 - rule.max_pfa if rule.kind == "specific_risk" else _inside(y, *acc)
        outcome, zone = (ACCEPTED, "acceptance zone") if ok else (REJECTED, "rejection zone")
    return Decision(value_mm=y, u_um=u, U_um=U, k=float(k), tolerance=tolerance, rule=rule, w_um=w,
                    acceptance_mm=acc, rejection_mm=rej, p_c=p_c, outcome=outcome, zone=zone,
                    conformance_mm=conf, conformity=conformity)


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
