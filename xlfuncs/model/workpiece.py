"""The workpiece's temperature, the factor W (docs/workpiece.md): the part expands about the point
where it is held, and a CMM measures it at its own temperature T, not at the reference temperature
of 20 °C (ISO 1) at which lengths are defined.

A uniform expansion of the part by the strain eps is a scale of its coordinates about the fixture
point x0: x_i -> x_i + eps (x_i - x0).  The CMM corrects to 20 °C with the expansion coefficient
alpha_c (usually the part's nominal alpha; 0 when it does not correct), so the error left is

    e_i = [alpha_true (T_true - 20) - alpha_c (T - 20)] (x_i - x0)
        ~ [(alpha - alpha_c)(T - 20) + (T - 20) d_alpha + alpha d_T] (x_i - x0),

with alpha, T the estimates and d_alpha, d_T their errors.  Its covariance is

    V_W = u^2(eps) (X - x0)(X - x0)^T,    u^2(eps) = (T - 20)^2 u^2(alpha) + alpha^2 u^2(T)
          + alpha^2 dT^2 / 12 + b^2,    b = (alpha - alpha_c)(T - 20),

rank one (a length L gets u_W = L u(eps) exactly).  ``dT`` is a temperature difference across the
part, taken as a rectangular spread of the part's mean temperature (half-width dT/2); ``b`` the
expansion the CMM leaves uncorrected, a known systematic error carried in quadrature (the RSSu
convention of Phillips, Eberhardt & Parry 1997; see docs/workpiece.md and docs/errata.md), zero
when the CMM corrects with the part's own alpha.

With temperatures per point (records of a calibration at several temperatures, ``t_i``), the
columns of V_W = K K^T per point are (x_i - x0) [(t_i - 20) u(alpha), alpha sqrt(u^2(T) + dT^2/12),
(alpha - alpha_c)(t_i - 20)] x 10^-3 (ppm x mm = 10^-3 µm): :func:`workpiece_columns`.

Units: alpha in 10^-6/K (``ppm/K``), temperatures in °C, differences in K, x0 in mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError

#: the reference temperature of lengths (ISO 1:2022), °C
REFERENCE_C = 20.0
#: ppm x mm = 10^-3 µm
MILLI = 1e-3

#: expansion coefficients (10^-6/K) of materials a task may name instead of alpha: Swyt 1994 (J. Res.
#: NIST 99, 31), section 1: "aluminum, steel, and silicon ... 23.1 ppm/°C, 11.5 ppm/°C, and 2.6 ppm/°C"
MATERIALS = {"aluminium": 23.1, "aluminum": 23.1, "steel": 11.5, "silicon": 2.6}

#: plausible part temperatures of a CMM measurement (°C): outside, the unit is probably wrong (K, °F)
PLAUSIBLE_T_C = (0.0, 50.0)


@dataclass(frozen=True)
class Workpiece:
    """The part's thermal state (docs/workpiece.md): its expansion coefficient ``alpha_ppm_per_K``,
    mean temperature ``T_degC``, whether the CMM corrects to 20 °C (``corrected``) and with which
    coefficient (``alpha_corr_ppm_per_K``; None: the part's alpha), the point it expands about
    (``fixture_mm``), a temperature difference across it (``dT_K``), and whether the factor W is on
    (``enabled``: a task keeps its inputs with W switched off).  The standard uncertainties u(alpha),
    u(T) are hyper-parameters (``Parameters.u_alpha_ppm_per_K``, ``u_T_K``)."""

    alpha_ppm_per_K: float
    T_degC: float = REFERENCE_C
    corrected: bool = True
    alpha_corr_ppm_per_K: float | None = None
    fixture_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dT_K: float = 0.0
    enabled: bool = True
    material: str | None = None

    def __post_init__(self) -> None:
        for name in ("alpha_ppm_per_K", "T_degC", "dT_K"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ModelError(f"{name} must be a finite number, got {v!r}")
        if self.alpha_corr_ppm_per_K is not None and not math.isfinite(self.alpha_corr_ppm_per_K):
            raise ModelError(f"alpha_corr_ppm_per_K must be a finite number, got {self.alpha_corr_ppm_per_K!r}")
        if self.dT_K < 0:
            raise ModelError(f"dT_K (the temperature difference across the part) must not be negative, "
                             f"got {self.dT_K!r}")
        x0 = tuple(float(c) for c in self.fixture_mm)
        if len(x0) != 3 or not all(math.isfinite(c) for c in x0):
            raise ModelError(f"fixture_mm must be three finite coordinates (mm), got {list(self.fixture_mm)}")
        object.__setattr__(self, "fixture_mm", x0)

    @property
    def alpha_c(self) -> float:
        """The coefficient the CMM corrects with (0 when it does not correct)."""
        if not self.corrected:
            return 0.0
        return self.alpha_ppm_per_K if self.alpha_corr_ppm_per_K is None else self.alpha_corr_ppm_per_K

    def bias_ppm(self, T_degC: float | None = None) -> float:
        """b = (alpha - alpha_c)(T - 20), the expansion left uncorrected (10^-6)."""
        T = self.T_degC if T_degC is None else T_degC
        return (self.alpha_ppm_per_K - self.alpha_c) * (T - REFERENCE_C)

    def terms_ppm(self, u_alpha_ppm_per_K: float, u_T_K: float) -> dict[str, float]:
        """The terms of u(eps) at the part's temperature (10^-6), each a standard uncertainty:
        ``alpha`` (T - 20) u(alpha), ``T`` alpha u(T), ``dT`` alpha dT/sqrt(12), ``uncorrected`` |b|."""
        if not self.enabled:
            return {"alpha": 0.0, "T": 0.0, "dT": 0.0, "uncorrected": 0.0}
        a = self.alpha_ppm_per_K
        return {"alpha": abs(self.T_degC - REFERENCE_C) * u_alpha_ppm_per_K, "T": abs(a) * u_T_K,
                "dT": abs(a) * self.dT_K / math.sqrt(12.0), "uncorrected": abs(self.bias_ppm())}

    def u_eps_ppm(self, u_alpha_ppm_per_K: float, u_T_K: float) -> float:
        """u(eps) of the module docstring (10^-6): a length L gets u_W = L u(eps)."""
        t = self.terms_ppm(u_alpha_ppm_per_K, u_T_K)
        return math.sqrt(t["alpha"] ** 2 + t["T"] ** 2 + t["dT"] ** 2 + t["uncorrected"] ** 2)

    def coefficients_ppm(self, u_alpha_ppm_per_K: float, u_T_K: float, T_points_C=None, m: int = 1) -> np.ndarray:
        """Per point the three coefficients of the columns of V_W (m x 3, 10^-6): (t_i - 20) u(alpha),
        alpha sqrt(u^2(T) + dT^2/12), (alpha - alpha_c)(t_i - 20); ``T_points_C`` the points'
        temperatures (None: the part's T for all ``m`` points)."""
        t = np.full(m, self.T_degC) if T_points_C is None else np.asarray(T_points_C, dtype=float)
        if not self.enabled:
            return np.zeros((t.size, 3))
        dt = t - REFERENCE_C
        a = self.alpha_ppm_per_K
        return np.column_stack([dt * u_alpha_ppm_per_K,
                                np.full(t.size, a * math.sqrt(u_T_K**2 + self.dT_K**2 / 12.0)),
                                (a - self.alpha_c) * dt])


def workpiece_from_readings(readings_C, **kw) -> Workpiece:
    """A workpiece whose T is the mean of thermometer readings on the part and whose temperature
    difference across it (unless given) is their range (docs/workpiece.md)."""
    r = [float(x) for x in readings_C]
    if not r or not all(math.isfinite(x) for x in r):
        raise ModelError("the temperature readings must be finite numbers (°C)")
    kw.setdefault("dT_K", max(r) - min(r))
    return Workpiece(T_degC=math.fsum(r) / len(r), **kw)


#: the part's state as named input cells of a workbook (``workpiece_<key>``, docs/workpiece.md), in
#: the order of the Inputs sheet: on/off and the correction as 1/0, the fixture point per coordinate
STATE_CELLS = ("enabled", "alpha_ppm_per_K", "T_degC", "dT_K", "corrected", "alpha_corr_ppm_per_K",
               "fixture_x_mm", "fixture_y_mm", "fixture_z_mm")
#: the prefix of the workbook names of the [workpiece] inputs
PREFIX = "workpiece_"


def state_cells(wp: Workpiece) -> dict[str, float]:
    """The values of :data:`STATE_CELLS` (numbers: 1/0 for the switches; alpha_c when the CMM corrects
    with the part's own alpha)."""
    x, y, z = wp.fixture_mm
    ac = wp.alpha_ppm_per_K if wp.alpha_corr_ppm_per_K is None else wp.alpha_corr_ppm_per_K
    return {"enabled": 1.0 if wp.enabled else 0.0, "alpha_ppm_per_K": wp.alpha_ppm_per_K, "T_degC": wp.T_degC,
            "dT_K": wp.dT_K, "corrected": 1.0 if wp.corrected else 0.0, "alpha_corr_ppm_per_K": ac,
            "fixture_x_mm": x, "fixture_y_mm": y, "fixture_z_mm": z}


def from_cells(values: dict[str, float]) -> Workpiece | None:
    """The workpiece of :data:`STATE_CELLS` values (keys with or without :data:`PREFIX`); None when
    ``alpha_ppm_per_K`` is not among them (a workbook without the factor W)."""
    v = {k[len(PREFIX):] if k.startswith(PREFIX) else k: x for k, x in values.items()}
    if "alpha_ppm_per_K" not in v:
        return None
    missing = [k for k in STATE_CELLS if k not in v]
    if missing:
        raise ModelError("the workpiece inputs lack " + ", ".join(PREFIX + k for k in missing))
    for k in ("enabled", "corrected"):
        if v[k] not in (0.0, 1.0):
            raise ModelError(f"{PREFIX}{k} must be 1 (yes) or 0 (no), got {v[k]!r}")
    return Workpiece(alpha_ppm_per_K=v["alpha_ppm_per_K"], T_degC=v["T_degC"], corrected=bool(v["corrected"]),
                     alpha_corr_ppm_per_K=v["alpha_corr_ppm_per_K"],
                     fixture_mm=(v["fixture_x_mm"], v["fixture_y_mm"], v["fixture_z_mm"]), dT_K=v["dT_K"],
                     enabled=bool(v["enabled"]))
