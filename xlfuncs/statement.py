"""Rounded result statements (GUM, JCGM 100:2008, 7.2.6 and 7.2.2 / 7.2.4).

The expanded uncertainty U is quoted to two significant digits (7.2.6: "it usually suffices to
quote u_c(y) and U to at most two significant digits"), the value to the same decimal place, and
the statement names the coverage factor and the coverage probability (7.2.2, 7.2.4) that k
gives with the effective degrees of freedom (GUM G.1.3, G.3.2: 2Φ(k) - 1, or Student's t for a
finite ν_eff; :func:`xlfuncs.dof.coverage_probability`), in percent to two decimals:
``d = 100.0123 mm, U = 3.4 µm (k = 2, coverage probability ≈ 95.45 %)``; k = 3 gives 99.73 %.

Rounding is to the nearest, halves away from zero, on the decimal representation of the number
(``repr``), so that 0.125 rounds to 0.13 as a person would do it.  ``mode="up"`` rounds U up
instead (GUM 7.2.6: "it may sometimes be appropriate to round uncertainties up").  Full precision
stays in the computing cells; this is for the text a person reads.
"""

from __future__ import annotations

import math
from decimal import ROUND_CEILING, ROUND_HALF_UP, Decimal

from .dof import coverage_probability
from .errors import ModelError


def decimals_for(U: float, digits: int = 2) -> int:
    """The number of decimal places that shows ``U`` with ``digits`` significant digits
    (negative: tens, hundreds ...).  3.44 -> 1, 0.0712 -> 3, 12.6 -> 0, 134 -> -1."""
    U = float(U)
    if not (math.isfinite(U) and U > 0):
        raise ModelError(f"an uncertainty to round must be a positive number, got {U!r}")
    exp = Decimal(repr(U)).adjusted()      # the power of ten of the leading digit
    return digits - 1 - exp


def round_to(x: float, decimals: int, mode: str = "nearest") -> float:
    """``x`` rounded to ``decimals`` places (negative: to tens ...), halves away from zero."""
    q = Decimal(1).scaleb(-decimals)
    rounding = ROUND_CEILING if mode == "up" else ROUND_HALF_UP
    return float(Decimal(repr(float(x))).quantize(q, rounding=rounding))


def round_uncertainty(U: float, digits: int = 2, mode: str = "nearest") -> tuple[float, int]:
    """(U rounded to ``digits`` significant digits, its number of decimals).  Rounding can carry
    into a new digit (9.96 -> 10): the decimals are then those of the rounded U."""
    dec = decimals_for(U, digits)
    r = round_to(U, dec, mode)
    if decimals_for(r, digits) != dec:     # 9.96 -> 10.0: two significant digits of 10 are "10"
        dec = decimals_for(r, digits)
        r = round_to(r, dec, mode)
    return r, dec


def fmt(x: float, decimals: int) -> str:
    """``x`` shown with ``decimals`` places (none when ``decimals`` <= 0)."""
    return f"{round_to(x, decimals) + 0.0:.{max(decimals, 0)}f}"     # + 0.0: no "-0.000"


def coverage_text(k: float, nu: float = math.inf) -> str:
    """"k = 2, coverage probability ≈ 95.45 %": the probability of k with ν_eff (GUM G.1.3,
    G.3.2) in percent to two decimals; a k that is not a whole number (a t-distribution's, GUM
    G.6.4) with two decimals: "k = 2.28"."""
    ks = f"{round(k):d}" if abs(k - round(k)) < 1e-9 else f"{k:.2f}"
    return f"k = {ks}, coverage probability ≈ {percent(coverage_probability(k, nu))} %"


def percent(p: float) -> str:
    """A probability in percent with two decimals, halves away from zero (0.9545 -> "95.45")."""
    return fmt(100.0 * p, 2)


def statement(symbol: str, value: float, value_unit: str, U: float, U_unit: str, k: float, *,
              nu: float = math.inf, unit_ratio: float = 1000.0, digits: int = 2, mode: str = "nearest") -> str:
    """The result statement: ``symbol = value value_unit, U = U U_unit (k = .., coverage
    probability ≈ .. %)``.  ``unit_ratio`` = U_unit per value_unit (1000 for µm per mm, 1 when
    both are the same); the value is rounded to the decimal place of the rounded U; ``nu`` the
    effective degrees of freedom of U (∞: type B only)."""
    U_r, dec_U = round_uncertainty(U, digits, mode)
    dec_value = dec_U + round(math.log10(unit_ratio)) if unit_ratio > 0 else dec_U
    # a dimensionless quantity (unit ""): no space before the comma
    vu, Uu = (f" {value_unit}" if value_unit else ""), (f" {U_unit}" if U_unit else "")
    return f"{symbol} = {fmt(value, dec_value)}{vu}, U = {fmt(U_r, dec_U)}{Uu} ({coverage_text(k, nu)})"
