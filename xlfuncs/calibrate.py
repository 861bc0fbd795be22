"""The user's own machine: the hyper-parameters of the six influence factors (Forbes 2025,
Tables 1 and 3) estimated from its verification recordings by restricted maximum likelihood
(the likelihood and its maximizer: :mod:`xlfuncs.reml`), with the identifiability of each.

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

What the fit gives (residuals, profiles, the MPE check, GLS of the effects):
:mod:`xlfuncs.calibration_checks`.

numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import pointcloud as pc
from .errors import ModelError
from .model.hyperparameters import GP, HYPER, HYPERPARAMETERS
from .reml import (
    NAMES,
    PARTNER,
    UNIT,
    ZERO_SHARE,
    RecordSet,
    bounds,
    maximize,
    observed_information,
    reml_terms,
    values_from_log,
)

#: a hyper-parameter is identified when u(log value) from the observed information is below this
U_LOG_MAX = 0.5
#: a parameter with an expected information below this (per unit log) has no sensitivity
NO_SENSITIVITY = 1e-6
#: drop of the REML log-likelihood that bounds a standard deviation estimated at zero: the upper
#: one-sided 95 % limit for a parameter on the boundary (Self & Liang 1987: the likelihood-ratio
#: statistic is 1/2 chi2_0 + 1/2 chi2_1, its 95 % point chi2_1(0.90) = 2.706, half of it)
UPPER_DROP = 1.353
#: two local maxima of the REML likelihood are distinct when some log hyper-parameter differs by
#: more than this between them (a factor e^0.1 ~ 1.1)
PEAK_SEPARATION = 0.1
#: a start, or a profile point, that reaches this much more log-likelihood than the fit is higher
#: (the fit's own convergence is within 1e-6)
PEAK_GAIN = 0.01
#: the other starts of the fit: every estimated length scale at these multiples of its estimate,
#: the others at their estimates (a short correlation with a small sigma and a long one with a
#: larger sigma are the classic pair of peaks of a Gaussian process likelihood)
OTHER_STARTS = (0.25, 4.0)

#: what measurement identifies each hyper-parameter (reported with a non-identifiable one): its record's
ADVICE = {h.name: h.advice for h in HYPERPARAMETERS}


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
class Peak:
    """One local maximum of the REML likelihood found by the fit: the estimated hyper-parameters
    there, its log-likelihood and the start that led to it."""

    values: dict[str, float]
    loglik: float
    found_by: str

    def to_json(self) -> dict:
        return {"values": dict(self.values), "loglik": self.loglik, "found_by": self.found_by}


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
    #: the distinct local maxima found (the fit's first), with the free set of ``free``
    peaks: list[Peak] = field(default_factory=list)
    fixed: tuple[str, ...] = ()
    u_log_max: float = U_LOG_MAX
    #: whether the fit was started again from other length scales (step 5 of :func:`calibrate`)
    peaks_searched: bool = True

    @property
    def multimodal(self) -> str | None:
        """The sentence that says the likelihood has several peaks and what separates them, or None."""
        return peaks_text(self.peaks) if len(self.peaks) > 1 else None

    def to_json(self) -> dict:
        return {
            "loglik": self.loglik, "loglik_start": self.loglik_start, "reml_chi2": self.chi2, "reml_dof": self.dof,
            "iterations": self.iterations,
            "peaks": [p.to_json() for p in self.peaks],
            "multimodal": self.multimodal,
            "peaks_searched": self.peaks_searched,
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
    # the kernels over the ram positions (ET, ER; P's is over the normals)
    lam = next((lm for _s, lm, f in GP if f == HYPER[name].factor and f in ("ET", "ER")), None)
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
    factor = HYPER[name].factor
    if factor == "PQ" and len(ids) < 2:
        return ("one probe: its qualification error is common to every probing and "
                + ("cancels in every length" if kinds == {"length"} else "is absorbed by the alignment"))
    if factor == "ER" and all(np.allclose(p, 0.0) for p in probes):
        return "every probe offset is zero: a rotation of the ram moves no stylus tip"
    if factor == "P":
        return "no normals in the records, or every point probed along one direction per probe"
    if factor == "W":
        return ("no record away from 20 °C (temperature_C, or the task's T): the artefact's expansion does not "
                "act" if name == "u_alpha_ppm_per_K" else "the artefact's alpha is zero: its temperature does not act")
    far = _beyond_travel(name, sets, values) if values else None
    return far or "the records carry no information on it after the fixed effects"


def _why_weak(name: str, sets: list[RecordSet], corr_row: np.ndarray | None, free: list[str],
              values: dict[str, float]) -> str:
    parts = []
    far = _beyond_travel(name, sets, values)
    if far:
        parts.append(far)
    factor = HYPER[name].factor
    if factor == "ER":
        offs = {p.offset_mm for s in sets for p in s.op.cloud.probes}
        if len(offs) == 1:
            parts.append("one probe offset: a rotation moves every tip like a translation of the ram")
    if factor == "S":
        parts.append("one machine shows one draw of each scale/squareness parameter")
    if factor == "W":
        temps = {float(t) for s in sets for t in (s.op.cloud.temperature_C if s.op.cloud.temperature_C is not None
                                                   else [s.op.cloud.workpiece.T_degC])}
        if len(temps) <= 1:
            parts.append("every record at one temperature: the artefact's expansion is a scale error, one with "
                         "the machine's scale (sigma_S)")
        parts.append("one artefact shows one draw of its alpha error and one thermometer one draw of its error: "
                     "the 'thermal_expansion' effect estimates the alpha draw (records at several temperatures)")
    if corr_row is not None:
        j = int(np.argmax(np.abs(corr_row)))
        if abs(corr_row[j]) > 0.7:
            parts.append(f"correlated with {free[j]} (rho = {corr_row[j]:+.2f})")
    return "; ".join(parts) or "the likelihood is flat in it"


def calibrate(sets: list[RecordSet], start: pc.Parameters, *, fixed: tuple[str, ...] = (),
              u_log_max: float = U_LOG_MAX, warm: dict[str, float] | None = None, found_by: str = "",
              known: list[Peak] | None = None, other_starts: bool | None = None) -> Calibration:
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
       held at its start too and the rest refitted.
    5. The likelihood of Gaussian-process hyper-parameters can have more than one peak (a short
       correlation with a small sigma, a long one with a larger sigma): once the free set is
       settled, the fit is started again with every estimated length scale at
       :data:`OTHER_STARTS` times its estimate; a start that climbs higher (by :data:`PEAK_GAIN`)
       moves the fit there.  The distinct local maxima found are ``peaks`` (the fit's first),
       and :attr:`Calibration.multimodal` says what separates them.

    ``warm``: values the fit of the free parameters starts from instead of ``start`` (a point a
    likelihood profile found higher, :func:`xlfuncs.calibration_checks.profiles_at_maximum`;
    ``found_by`` says so), ``known``: peaks found before, kept in ``peaks``; ``other_starts``
    False skips step 5, None (default) runs it when every record set has the dense covariance
    (on the structured one each start is a large fit of its own: ``peaks_searched`` says so)."""
    if not sets:
        raise ModelError("no records to calibrate from")
    if other_starts is None:
        other_starts = not any(getattr(s, "structured", False) for s in sets)
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

    # -- 3./4./5. the fit ----------------------------------------------------------------------
    iterations = 0
    if warm:
        for n in free:
            if warm.get(n, 0.0) > 0:
                sv[n] = float(warm[n])
    values = dict(sv)
    cov = np.zeros((0, 0))
    peaks: list[Peak] = []
    origin = found_by or ("the task's values" if not warm else "the values given")
    tried: list[str] | None = None
    while free:
        box = bounds(sets, sv, free)
        phi, t, it = maximize(sets, sv, free, box)
        iterations += it
        values = values_from_log(sv, free, phi)
        zero = [n for n, x, lo in zip(free, phi, box.lo) if HYPER[n].role != "lambda" and x <= lo + 1e-6]
        if not zero and other_starts and tried != free:
            # 5. the other starts, once per free set
            tried = list(free)
            peaks = [Peak({n: values[n] for n in free}, t.loglik, origin)]
            found = _other_starts(sets, values, free, box, peaks, origin)
            iterations += found[1]
            best = peaks[0]
            if best.loglik > t.loglik + PEAK_GAIN:
                origin = best.found_by
                for n in free:
                    sv[n] = best.values[n]
                continue          # the fit from the higher peak (zero, information, holds as before)
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
    peaks = _distinct([p for p in (known or []) + peaks if set(p.values) == set(free)],
                      first=Peak({n: values[n] for n in free}, tf.loglik, origin))
    for n, e in est.items():
        if e.status == "zero":
            e.upper = upper_limit(sets, fitted, list(free), n, e.start, tf.loglik,
                                  {lm: est[lm].start for lm, s_ in PARTNER.items() if s_ == n})
            e.reason += f"; upper 95 % limit {e.upper:.3g} {e.unit} (REML profile)"
    return Calibration(est, params, start, list(free), cov if free else np.zeros((0, 0)), tf.loglik,
                       loglik_start, tf.chi2, tf.dof, iterations, sets, peaks if free else [], tuple(fixed),
                       u_log_max, bool(other_starts))


def _other_starts(sets: list[RecordSet], values: dict[str, float], free: list[str], box,
                  peaks: list[Peak], origin: str) -> tuple[list[Peak], int]:
    """Step 5 of :func:`calibrate`: Fisher scoring from every estimated length scale at
    :data:`OTHER_STARTS` times its estimate (the others at theirs); the distinct maxima reached
    are added to ``peaks``.  Returns (peaks, iterations)."""
    its = 0
    for lm in [n for n in free if n.startswith("lambda")]:
        for f in OTHER_STARTS:
            s0 = dict(values)
            s0[lm] = values[lm] * f
            phi, t, it = maximize(sets, s0, free, box, max_iter=60)
            its += it
            peaks.append(Peak(dict(zip(free, np.exp(phi).tolist())), t.loglik,
                              f"a start at {lm} = {s0[lm]:.4g} {UNIT[lm]} ({f:g} x its value at the peak "
                              f"reached from {origin})"))
    peaks[:] = _distinct(peaks)
    return peaks, its


def _distinct(peaks: list[Peak], first: Peak | None = None) -> list[Peak]:
    """The peaks, highest first (``first``, the fit, before all), without repeats: a peak within
    PEAK_SEPARATION in every log hyper-parameter of one found before it (in the order given) is
    that one, and the first start that reached it names it."""
    def far(p: Peak, q: Peak) -> bool:
        return max(abs(math.log(p.values[n]) - math.log(q.values[n])) for n in p.values) > PEAK_SEPARATION

    kept: list[Peak] = []
    for p in peaks:                  # the first start that reached a peak stands for it
        if (first is None or far(p, first)) and all(far(p, q) for q in kept):
            kept.append(p)
    kept.sort(key=lambda p: -p.loglik)
    return ([first] if first is not None else []) + kept


def _separating(a: Peak, b: Peak) -> list[str]:
    """The hyper-parameters in which two peaks differ by more than PEAK_SEPARATION in log, the
    largest difference first."""
    gap = {n: abs(math.log(a.values[n]) - math.log(b.values[n])) for n in a.values}
    return [n for n in sorted(gap, key=lambda n: -gap[n]) if gap[n] > PEAK_SEPARATION]


def peaks_text(peaks: list[Peak]) -> str:
    """What a lab reads when the REML likelihood has several peaks: which one the fit reports,
    the others with their log-likelihood below it, the hyper-parameters that separate them
    and how strongly the records prefer the fit (likelihood ratio; 2 x the difference against
    chi2_1(0.95) = 3.84)."""
    top = peaks[0]
    parts = [f"The REML likelihood has {len(peaks)} peaks; the fit is the highest (log-likelihood "
             f"{top.loglik:.3f}, found from {top.found_by})."]
    for p in peaks[1:]:
        d = top.loglik - p.loglik
        sep = _separating(top, p)[:3]
        what = ", ".join(f"{n} {top.values[n]:.3g} vs {p.values[n]:.3g} {UNIT[n]}" for n in sep)
        firm = ("the records rule it out" if 2 * d > 3.84 else
                "the records do not rule it out (2 x the difference is below 3.84, chi2_1 at 95 %)")
        parts.append(f"Another peak {d:.3f} lower (likelihood ratio {math.exp(d):.3g}, found from {p.found_by}) "
                     f"differs in {what}: {firm}.")
    if len(peaks) > 1:
        sep = _separating(top, peaks[1])
        if sep:
            parts.append("What would separate them: " + "; ".join(ADVICE[n] for n in sep[:2]) + ".")
    return " ".join(parts)


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
