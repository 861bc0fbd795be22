"""The probability distributions of cmmwb, in one module (numpy and the standard library only; no
scipy): the normal distribution (JCGM 106:2012 decisions, GUM coverage factors), Student's t (GUM
G.3, G.6), and the chi-square and F tails in logarithms (the locator's tests, docs/diagnose.md
sections 2-3 and 6), so that p-values far below 1e-308 still rank.

* :func:`norm_pdf`, :func:`norm_cdf` (via erfc: accurate in both tails), :func:`norm_ppf`
  (Acklam's start, Newton steps on Phi: full double precision);
* :func:`t_cdf`, :func:`t_quantile`: Student's t by the regularized incomplete beta function and its
  inverse (bisection);
* :func:`chi2_logsf`, :func:`chi2_sf`, :func:`f_logcdf`, :func:`f_logsf`, :func:`betainc`: the
  regularized incomplete gamma (series and continued fraction) and beta (continued fraction)
  functions.

The decisions and statements (``conformity``, ``global_risk``, ``dof``, ``statement``) and the
locator (``locator.diagnose``, ``search``, ``report``) take them from here; the GUM modules import
nothing of the locator (``tests/layout/test_layout.py``).
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ModelError

# ---------------------------------------------------------------------------------------------
# the normal distribution
# ---------------------------------------------------------------------------------------------

def norm_pdf(x):
    """phi(x), the standard normal density: of a number by ``math.exp`` (a float), of an array by
    ``numpy.exp``."""
    if isinstance(x, (int, float)):
        return math.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)
    return np.exp(-0.5 * np.asarray(x) ** 2) / math.sqrt(2.0 * math.pi)


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


# ---------------------------------------------------------------------------------------------
# Student's t
# ---------------------------------------------------------------------------------------------

def t_cdf(t: float, nu: float) -> float:
    """Pr(T <= t) for Student's t with ν degrees of freedom (GUM G.3)."""
    if not nu > 0:
        raise ModelError(f"degrees of freedom must be positive, got {nu!r}")
    if math.isinf(nu):
        return 0.5 * math.erfc(-t / math.sqrt(2.0))
    tail = 0.5 * betainc(nu / 2.0, 0.5, nu / (nu + t * t))
    return 1.0 - tail if t > 0 else tail


def t_quantile(p: float, nu: float) -> float:
    """The t with Pr(T <= t) = p (0 < p < 1)."""
    if not 0.0 < p < 1.0:
        raise ModelError(f"a probability must lie strictly between 0 and 1, got {p!r}")
    if p < 0.5:
        return -t_quantile(1.0 - p, nu)
    if p == 0.5:
        return 0.0
    lo, hi = 0.0, 1.0
    while t_cdf(hi, nu) < p:
        hi *= 2.0
        if hi > 1e12:
            break
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if t_cdf(mid, nu) < p:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-15 * hi:
            break
    return 0.5 * (lo + hi)


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


def betainc(a: float, b: float, x: float) -> float:
    """I_x(a, b), the regularized incomplete beta function (behind Student's t and the F tails)."""
    return math.exp(_log_betainc(a, b, x))


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
