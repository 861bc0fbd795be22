"""Global consumer's and producer's risks of a production process (JCGM 106:2012, 9.5).

The items of a process have a prior PDF g₀(η) of the property η; each is measured by a system
with N(η, u_m²) and accepted when the measured value falls in the acceptance interval A:

* :func:`global_risks`: R_C (accepted and not conforming) and R_P (rejected and conforming) by
  adaptive quadrature, for any prior (:func:`normal_prior`, :func:`gamma_prior`); these take any
  one unit, not mm/µm;
* :func:`guard_band_for_global_risk`: the guard band w for a stated global consumer's risk;
* :func:`global_risks_normal`, :func:`risk_panels`: the same risks of a normal process by fixed
  Gauss-Legendre panels, the sums the Decision sheet repeats with SUMPRODUCT (values in mm,
  uncertainties in µm).

The specific (one item) decision is :mod:`xlfuncs.conformity`.  numpy and the standard library
only; no spreadsheet knowledge.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .conformity import UM_PER_MM, Tolerance
from .distributions import norm_cdf, norm_pdf
from .errors import ModelError

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
        r_c = (_gl(lambda v: norm_pdf(v) * (Q0(a_l - u * v) - Q0(a_u - u * v)), -V, v4)
               + _gl(lambda v: norm_pdf(v) * (Q0(t_u) - Q0(a_u - u * v)), v4, v2)
               + _gl(lambda v: norm_pdf(v) * (P0(t_l) - P0(a_l - u * v)), v1, v3)
               + _gl(lambda v: norm_pdf(v) * (P0(a_u - u * v) - P0(a_l - u * v)), v3, V))
        r_p = (_gl(lambda v: norm_pdf(v) * (Q0(a_u - u * v) - Q0(t_u)), v2, v3)
               + _gl(lambda v: norm_pdf(v) * (Q0(t_l) - Q0(t_u)), v3, V)
               + _gl(lambda v: norm_pdf(v) * (P0(t_u) - P0(t_l)), -V, v4)
               + _gl(lambda v: norm_pdf(v) * (P0(a_l - u * v) - P0(t_l)), v4, v1))
    else:
        def eta(x):
            return mean_mm + s0 * np.asarray(x)

        V = GL_RANGE
        r_c = (_gl(lambda x: norm_pdf(x) * (norm_cdf((eta(x) - a_l) / u) - norm_cdf((eta(x) - a_u) / u)), -V, x_l)
               + _gl(lambda x: norm_pdf(x) * (norm_cdf((a_u - eta(x)) / u) - norm_cdf((a_l - eta(x)) / u)), x_u, V))
        r_p = _gl(lambda x: norm_pdf(x) * (norm_cdf((a_l - eta(x)) / u) + norm_cdf((eta(x) - a_u) / u)), x_l, x_u)
    return GlobalRisks(consumer=r_c, producer=r_p, nonconforming=nonconforming)
