"""Degrees of freedom: Welch–Satterthwaite and the t-distribution's coverage factor
(GUM, JCGM 100:2008, G.4 and G.6; numpy and the standard library only).

* :func:`nu_eff`: ν_eff = u_c⁴ / Σ (c_i u_i)⁴ / ν_i (GUM G.4.1, eq. (G.2b)); ν_i = inf for inputs
  known exactly enough (type B inputs, GUM G.4.3) contribute nothing to the sum.
* :func:`t_cdf`, :func:`t_quantile`: Student's t (:mod:`xlfuncs.distributions`, re-exported).
* :func:`coverage_factor`: k_p = t_p(ν_eff) with ν_eff truncated to the next lower integer
  (GUM G.6.4), p = 0.9545 by default (k = 2 for ν = ∞, GUM G.1.3, G.6.6).
* :func:`coverage_probability`: the other way, the coverage probability of a coverage factor k:
  2Φ(k) - 1 for ν_eff = ∞ (GUM G.1.3: k = 2 gives 95.45 %, k = 3 99.73 %), 2 t_cdf(k, ⌊ν_eff⌋) - 1
  for a finite ν_eff (GUM G.3.2, G.6.4).
"""

from __future__ import annotations

import math

from .distributions import norm_ppf, t_cdf, t_quantile  # noqa: F401  (t_cdf re-exported)
from .errors import ModelError

P_K2 = 0.9545          #: the coverage probability of k = 2 for a normal distribution (GUM G.1.3)


def nu_eff(u_contributions, nus) -> float:
    """Welch–Satterthwaite (GUM G.4.1, eq. (G.2b)): ``u_contributions`` = |c_i| u(x_i) (any unit),
    ``nus`` their degrees of freedom (``math.inf`` for type B)."""
    us = [abs(float(u)) for u in u_contributions]
    ns = [float(n) for n in nus]
    if len(us) != len(ns) or not us:
        raise ModelError("nu_eff needs one degrees-of-freedom value per uncertainty contribution")
    for n in ns:
        if not n > 0:
            raise ModelError(f"degrees of freedom must be positive, got {n!r}")
    uc2 = sum(u * u for u in us)
    den = sum(u ** 4 / n for u, n in zip(us, ns) if math.isfinite(n))
    if den == 0.0:
        return math.inf
    return uc2 * uc2 / den


def coverage_factor(nu: float, p: float = P_K2) -> float:
    """k_p = t_p(ν) of the two-sided interval of probability ``p`` (GUM G.3.4), ν truncated to
    the next lower integer (GUM G.6.4); ν = inf gives the normal value (2.000 for p = 0.9545)."""
    if math.isinf(nu):
        return norm_ppf(0.5 + p / 2.0)
    n = math.floor(nu)
    if n < 1:
        raise ModelError(f"an effective degrees of freedom below 1 ({nu!r}) gives no coverage factor")
    return t_quantile(0.5 + p / 2.0, n)


def coverage_probability(k: float, nu: float = math.inf) -> float:
    """The coverage probability p of the interval y ± k·u (GUM G.1.3, G.3.2): 2Φ(k) - 1 for
    ν = ∞ (normal), else 2·F_t(k; ⌊ν⌋) - 1 with ν truncated to the next lower integer as for the
    coverage factor (GUM G.6.4), so that ``coverage_probability(coverage_factor(nu), nu)`` is
    0.9545."""
    k = float(k)
    if not (math.isfinite(k) and k > 0):
        raise ModelError(f"a coverage factor must be a positive number, got {k!r}")
    if math.isinf(nu):
        return math.erf(k / math.sqrt(2.0))
    n = math.floor(nu)
    if n < 1:
        raise ModelError(f"an effective degrees of freedom below 1 ({nu!r}) gives no coverage probability")
    return 2.0 * t_cdf(k, n) - 1.0


#: b of u = b·E_L,MPE that names a distribution: 1/√3 (rectangular, GUM 4.3.7) and 1/√6
#: (triangular, GUM 4.3.9), matched to ``B_TOLERANCE`` so that the printed 0.577 and 0.408 count
B_RECTANGULAR = 1.0 / math.sqrt(3.0)
B_TRIANGULAR = 1.0 / math.sqrt(6.0)
B_TOLERANCE = 5e-4
#: the distribution of an input whose b names none of the above (b = 1/2, 1/3, ...: the task's
#: own coverage convention, taken as the standard deviation of a normal distribution)
B_OTHER = "normal (b given)"


def distribution_of_b(b: float) -> str:
    """The distribution that u = b·E_L,MPE implies for an MPE-derived (type B) input
    (Wojtyła/Płowucha 2023 eq. (5); GUM 4.3.7, 4.3.9): b = 1/√3 (0.577) "rectangular", b = 1/√6
    (0.408) "triangular", any other b "normal (b given)" (docs/errata.md)."""
    b = float(b)
    if abs(b - B_RECTANGULAR) <= B_TOLERANCE:
        return "rectangular"
    if abs(b - B_TRIANGULAR) <= B_TOLERANCE:
        return "triangular"
    return B_OTHER
