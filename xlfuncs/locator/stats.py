"""Tails of the chi-square and F distributions in logarithms, numpy/math only, so that p-values far
below 1e-308 still rank (the likelihood-ratio tests of docs/diagnose.md sections 2-3 and the
F-tests of the noise level, section 6): the regularized incomplete gamma function (series and
continued fraction) and the regularized incomplete beta function (continued fraction)."""

from __future__ import annotations

import math

from ..errors import ModelError

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
    """I_x(a, b), the regularized incomplete beta function (also behind Student's t in
    :mod:`xlfuncs.dof`)."""
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
